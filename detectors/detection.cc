#include "detectors/detection.h"

namespace linecal {

const char* DetectReasonName(DetectReason reason) {
  switch (reason) {
    case DetectReason::kNone:
      return "";
    case DetectReason::kBadImage:
      return "bad_image";
    case DetectReason::kLowContrast:
      return "low_contrast";
    case DetectReason::kNoCandidates:
      return "no_candidates";
    case DetectReason::kTooFewFeatures:
      return "too_few_features";
    case DetectReason::kAmbiguous:
      return "ambiguous";
    case DetectReason::kVerificationFailed:
      return "verification_failed";
    case DetectReason::kWrongBoard:
      return "wrong_board";
    case DetectReason::kPartial:
      return "partial";
  }
  return "unknown";
}

DetectReason CheckDetectorInput(const ImageView8& image, const Board& board, BoardType type,
                                bool options_valid) {
  if (board.type() != type) return DetectReason::kWrongBoard;
  if (image.Validate() != ImageViewError::kOk || image.width < kMinDetectImageSide ||
      image.height < kMinDetectImageSide || !options_valid) {
    return DetectReason::kBadImage;
  }
  return DetectReason::kNone;
}

}  // namespace linecal

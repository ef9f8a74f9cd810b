#include "detectors/apriltag/apriltag_detector.h"

namespace linecal {

Detection DetectApriltag(const ImageView8& image, const Board& board,
                         const ApriltagOptions& options) {
  Detection detection;
  if (board.type() != BoardType::kApriltag) {
    detection.reason = DetectReason::kWrongBoard;
    return detection;
  }
  if (image.Validate() != ImageViewError::kOk || !options.Validate().empty()) {
    detection.reason = DetectReason::kBadImage;
    return detection;
  }
  const MarkerScan scan =
      ScanMarkers(image, Tag36h11Family(board.params().apriltag_border_bits), options.markers);
  return VerifyMarkerBoard(scan, board, options.markers);
}

}  // namespace linecal

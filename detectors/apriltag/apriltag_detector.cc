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
  // Four corner features per tag: once every tag of the board is read, stop eroding.
  const int board_tags = static_cast<int>(board.features().size()) / 4;
  const MarkerFamily family = Tag36h11Family(board.params().apriltag_border_bits);
  return DetectMarkerBoard(image, board, family, options.markers, nullptr, board_tags);
}

}  // namespace linecal

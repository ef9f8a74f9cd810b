#include "detectors/aruco/aruco_detector.h"

namespace linecal {

Detection DetectAruco(const ImageView8& image, const Board& board, const ArucoOptions& options) {
  Detection detection;
  if (board.type() != BoardType::kAruco && board.type() != BoardType::kRoundHole) {
    detection.reason = DetectReason::kWrongBoard;
    return detection;
  }
  if (image.Validate() != ImageViewError::kOk || !options.Validate().empty()) {
    detection.reason = DetectReason::kBadImage;
    return detection;
  }
  const MarkerScan scan = ScanMarkers(image, Aruco4x4_50Family(), options.markers);
  return VerifyMarkerBoard(scan, board, options.markers);
}

}  // namespace linecal

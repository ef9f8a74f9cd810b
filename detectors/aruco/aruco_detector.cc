#include "detectors/aruco/aruco_detector.h"

#include <algorithm>
#include <optional>

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
  const MarkerFamily family = Aruco4x4_50Family();
  // The other board with these four markers, at the same scale: what this board must be told from.
  BoardParams sibling_params = board.params();
  sibling_params.type =
      board.type() == BoardType::kAruco ? BoardType::kRoundHole : BoardType::kAruco;
  const std::optional<Board> sibling = Board::Create(sibling_params);
  // Once the board's markers are read, the scan's later passes have nothing to find.
  const int board_markers = static_cast<int>(
      std::count_if(board.features().begin(), board.features().end(),
                    [](const BoardFeature& f) { return f.kind == FeatureKind::kMarkerCorner; }) /
      4);
  return DetectMarkerBoard(image, board, family, options.markers, sibling ? &*sibling : nullptr,
                           board_markers);
}

}  // namespace linecal

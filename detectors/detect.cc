#include "detectors/detect.h"

#include <algorithm>
#include <cstdint>

#include "detectors/apriltag/apriltag_detector.h"
#include "detectors/aruco/aruco_detector.h"
#include "detectors/charuco/charuco_detector.h"
#include "detectors/checker/checker_detector.h"
#include "detectors/chessboard/chessboard_detector.h"
#include "detectors/circle/circle_detector.h"
#include "detectors/circle/circle_grid_detector.h"
#include "detectors/square_grid/square_grid_detector.h"
#include "detectors/vertical/vertical_detector.h"

namespace linecal {

std::optional<Detection> DetectBoard(const ImageView8& image, const Board& board) {
  switch (board.type()) {
    case BoardType::kChecker:
      return DetectChecker(image, board);
    case BoardType::kCircle:
      return DetectCircleBoard(image, board);
    case BoardType::kCircleGrid:
      return DetectCircleGrid(image, board);
    case BoardType::kChessboard:
      return DetectChessboard(image, board);
    case BoardType::kVertical:
      return DetectVertical(image, board);
    case BoardType::kAruco:
    case BoardType::kRoundHole:
      return DetectAruco(image, board);
    case BoardType::kApriltag:
      return DetectApriltag(image, board);
    case BoardType::kSquareGrid:
      return DetectSquareGrid(image, board);
    case BoardType::kCharuco:
      return DetectCharuco(image, board);
  }
  return std::nullopt;
}

Image8 RangeTo8Bit(const ImageView16& image) {
  if (image.Validate() != ImageViewError::kOk) return Image8();
  std::uint16_t lo = 65535;
  std::uint16_t hi = 0;
  for (int y = 0; y < image.height; ++y) {
    const std::uint16_t* row = image.Row(y);
    const auto [mn, mx] = std::minmax_element(row, row + image.width);
    lo = std::min(lo, *mn);
    hi = std::max(hi, *mx);
  }
  Image8 image8(image.width, image.height, 0);
  if (hi == lo) return image8;
  // Fixed point: 255 * (v - lo) / (hi - lo), rounded; the product fits in 32 bits.
  const std::uint32_t range = hi - lo;
  for (int y = 0; y < image.height; ++y) {
    const std::uint16_t* row = image.Row(y);
    for (int x = 0; x < image.width; ++x) {
      image8.at(x, y) = static_cast<std::uint8_t>((255u * (row[x] - lo) + range / 2) / range);
    }
  }
  return image8;
}

std::optional<Detection> DetectBoard(const ImageView16& image, const Board& board) {
  if (image.Validate() != ImageViewError::kOk) return DetectBoard(ImageView8{}, board);
  const Image8 image8 = RangeTo8Bit(image);
  return DetectBoard(image8.view(), board);
}

}  // namespace linecal

// The dispatcher: the right detector per board type, and 16-bit input by its own range.
#include "detectors/detect.h"

#include <gtest/gtest.h>

#include "detectors/checker/checker_detector.h"
#include "tests/detectors/board_scene.h"

namespace linecal {
namespace {

TEST(DetectBoardTest, RangeTo8BitStretchesTheImagesOwnRange) {
  Image16 image(4, 1);
  image.pixels = {1000, 1500, 2000, 1250};
  const Image8 out = RangeTo8Bit(image.view());
  ASSERT_EQ(out.width, 4);
  EXPECT_EQ(out.pixels[0], 0);
  EXPECT_EQ(out.pixels[1], 128);  // 127.5 rounds up
  EXPECT_EQ(out.pixels[2], 255);
  EXPECT_EQ(out.pixels[3], 64);  // 63.75
  EXPECT_EQ(RangeTo8Bit(Image16(3, 3, 777).view()).pixels, std::vector<std::uint8_t>(9, 0));
  EXPECT_EQ(RangeTo8Bit(ImageView16{}).width, 0);
}

TEST(DetectBoardTest, CheckerIn8And16BitsGivesTheCheckerDetectorsResult) {
  test_scene::BoardView view;
  view.params.type = BoardType::kChecker;
  view.distance_m = 0.8;
  CameraRenderOptions options;
  options.blur_sigma_px = 0.7;
  const Board board = *Board::Create(view.params);
  const CameraFrame frame8 = test_scene::RenderView(view, options, 3);
  const std::optional<Detection> d8 = DetectBoard(frame8.image8.view(), board);
  ASSERT_TRUE(d8.has_value());
  const Detection direct = DetectChecker(frame8.image8.view(), board);
  ASSERT_TRUE(d8->found);
  ASSERT_EQ(d8->features.size(), direct.features.size());
  for (std::size_t i = 0; i < direct.features.size(); ++i) {
    EXPECT_EQ(d8->features[i].uv_px, direct.features[i].uv_px);
  }
  // A 16-bit camera using a quarter of its range: stretched, the board is found.
  options.bit_depth = 16;
  options.illumination = 0.25;
  const CameraFrame frame16 = test_scene::RenderView(view, options, 3);
  const std::optional<Detection> d16 = DetectBoard(frame16.image16.view(), board);
  ASSERT_TRUE(d16.has_value());
  EXPECT_TRUE(d16->found) << DetectReasonName(d16->reason);
  EXPECT_EQ(d16->features.size(), 54u);
  // Invalid 16-bit views reach the detector as invalid 8-bit views.
  const std::optional<Detection> bad = DetectBoard(ImageView16{}, board);
  ASSERT_TRUE(bad.has_value());
  EXPECT_EQ(bad->reason, DetectReason::kBadImage);
}

// docs/acceptance.md's bad input, for every board: a reason, never a crash or a board. Views that
// no detector may read (empty, over kMaxImageSide, short or misaligned stride) are refused
// before a pixel is touched: the 20000 x 20000 view points at one byte.
TEST(DetectBoardTest, BadInputGivesAReasonForEveryBoard) {
  const std::uint8_t one_byte = 0;
  const std::uint16_t one_word = 0;
  const Image8 black(640, 480, 0);
  const Image8 white(640, 480, 255);
  const Image8 noise = test_scene::UniformNoiseImage(640, 480);
  const Image16 noise16 = [&] {
    Image16 n(640, 480);
    for (std::size_t i = 0; i < n.pixels.size(); ++i)
      n.pixels[i] = static_cast<std::uint16_t>(noise.pixels[i] * 257);
    return n;
  }();
  for (BoardType type : kAllBoardTypes) {
    BoardParams params;
    params.type = type;
    const Board board = *Board::Create(params);
    SCOPED_TRACE(board.name());
    const auto reason = [&](const auto& view) {
      const std::optional<Detection> d = DetectBoard(view, board);
      EXPECT_TRUE(d.has_value());
      if (!d) return DetectReason::kNone;
      EXPECT_FALSE(d->found);
      EXPECT_TRUE(d->features.empty());
      return d->reason;
    };
    EXPECT_EQ(reason(ImageView8{}), DetectReason::kBadImage) << "empty";
    EXPECT_EQ(reason(ImageView8{&one_byte, 1, 1, 1}), DetectReason::kBadImage) << "1x1";
    EXPECT_EQ(reason(ImageView8{&one_byte, 20000, 20000, 20000}), DetectReason::kBadImage)
        << "20000x20000";
    EXPECT_EQ(reason(ImageView8{black.pixels.data(), 640, 480, 320}), DetectReason::kBadImage)
        << "short stride";
    EXPECT_EQ(reason(ImageView16{&one_word, 20000, 20000, 40000}), DetectReason::kBadImage)
        << "16-bit 20000x20000";
    EXPECT_EQ(reason(ImageView16{&one_word, 2, 2, 3}), DetectReason::kBadImage)
        << "16-bit odd stride";
    // Nothing printed: no contrast, or no candidates of the board's kind.
    for (const Image8* flat : {&black, &white}) {
      const DetectReason r = reason(flat->view());
      EXPECT_TRUE(r == DetectReason::kLowContrast || r == DetectReason::kNoCandidates)
          << DetectReasonName(r);
    }
    EXPECT_NE(reason(noise.view()), DetectReason::kNone) << "noise";
    EXPECT_NE(reason(noise16.view()), DetectReason::kNone) << "16-bit noise";
  }
}

}  // namespace
}  // namespace linecal

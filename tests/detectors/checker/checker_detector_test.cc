// The checker detector on golden renders (station/sim/camera_render.h, exact ground truth):
// ids and sub-pixel errors over a grid of poses with noise, blur and lighting, nothing on
// board-free images or other boards, and the bad-input reasons.
#include "detectors/checker/checker_detector.h"

#include <gtest/gtest.h>
#include <time.h>

#include <cstdio>
#include <vector>

#include "tests/detectors/board_scene.h"
#include "tests/detectors/circle/circle_scene.h"

namespace linecal {
namespace {

using test_scene::BoardView;
using test_scene::CleanRender;
using test_scene::ExpectComplete;
using test_scene::FeatureRmsPx;
using test_scene::kCleanRmsBarPx;
using test_scene::kNoisyRmsBarPx;
using test_scene::NoisyRender;
using test_scene::RenderView;

BoardParams Checker(int cols, int rows, double square_m) {
  BoardParams p;
  p.type = BoardType::kChecker;
  p.cols = cols;
  p.rows = rows;
  p.square_m = square_m;
  return p;
}

TEST(CheckerDetectorTest, FrontalBoardHasExactIdsAndSubPixelCorners) {
  BoardView view;
  view.params = Checker(9, 6, 0.025);
  view.distance_m = 0.8;  // squares of about 31 px
  const CameraFrame frame = RenderView(view, CleanRender(), 1);
  const Board board = *Board::Create(view.params);
  const Detection d = DetectChecker(frame.image8.view(), board);
  ExpectComplete(d, board);
  int matched = 0, unknown = 0;
  const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
  EXPECT_EQ(matched, 54);
  EXPECT_EQ(unknown, 0);
  EXPECT_LT(rms, kCleanRmsBarPx);
  // Corner 0 is the top-left one: left of and above corner 53 in a frontal view.
  EXPECT_LT(d.features[0].uv_px.x(), d.features[53].uv_px.x());
  EXPECT_LT(d.features[0].uv_px.y(), d.features[53].uv_px.y());
}

TEST(CheckerDetectorTest, PoseGridWithNoiseBlurAndLighting) {
  const BoardParams params = Checker(9, 6, 0.025);
  const Board board = *Board::Create(params);
  int views = 0, detected = 0;
  double sum_sq_clean = 0.0, sum_sq_noisy = 0.0;
  int n_clean = 0, n_noisy = 0;
  std::uint64_t seed = 10;
  // 12 views (roll, yaw, pitch at the extremes of docs/acceptance.md, two sizes), each rendered
  // clean and noisy (sigma 4, blur 1.0, a 3:1 lighting gradient, gamma 1.4).
  int index = 0;
  for (double roll : {-30.0, 30.0}) {
    for (double yaw : {-50.0, 0.0, 50.0}) {
      for (double pitch : {-40.0, 40.0}) {
        const double distance = (index++ % 2 == 0) ? 0.6 : 1.4;  // squares of ~42 and ~18 px
        for (bool noisy : {false, true}) {
          BoardView view;
          view.params = params;
          view.distance_m = distance;
          view.roll_deg = roll;
          view.yaw_deg = yaw;
          view.pitch_deg = pitch;
          CameraRenderOptions options = noisy ? NoisyRender() : CleanRender();
          if (noisy) {
            options.illumination_gradient_ratio = 3.0;
            options.illumination_gradient_direction_deg = roll * 3.0;
            options.gamma = 1.4;
          }
          const CameraFrame frame = RenderView(view, options, ++seed);
          const Detection d = DetectChecker(frame.image8.view(), board);
          ++views;
          if (!d.found) {
            ADD_FAILURE() << "roll " << roll << " yaw " << yaw << " pitch " << pitch << " distance "
                          << distance << " noisy " << noisy << ": " << DetectReasonName(d.reason);
            continue;
          }
          ++detected;
          int matched = 0, unknown = 0;
          const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
          EXPECT_EQ(matched, 54);
          EXPECT_EQ(unknown, 0);
          (noisy ? sum_sq_noisy : sum_sq_clean) += rms * rms * matched;
          (noisy ? n_noisy : n_clean) += matched;
        }
      }
    }
  }
  const double rms_clean = std::sqrt(sum_sq_clean / std::max(n_clean, 1));
  const double rms_noisy = std::sqrt(sum_sq_noisy / std::max(n_noisy, 1));
  std::printf("checker pose grid: %d / %d detected, RMS clean %.4f px, noisy %.4f px\n", detected,
              views, rms_clean, rms_noisy);
  EXPECT_EQ(detected, views);
  EXPECT_LT(rms_clean, kCleanRmsBarPx);
  EXPECT_LT(rms_noisy, kNoisyRmsBarPx);
}

TEST(CheckerDetectorTest, SmallestSquaresOfTwelvePixels) {
  BoardView view;
  view.params = Checker(9, 6, 0.025);
  view.distance_m = 1000.0 * 0.025 / 12.0;  // f = 1000 px: 12 px squares
  view.yaw_deg = 20.0;
  const CameraFrame frame = RenderView(view, NoisyRender(), 3);
  const Board board = *Board::Create(view.params);
  const Detection d = DetectChecker(frame.image8.view(), board);
  ExpectComplete(d, board);
  int matched = 0, unknown = 0;
  EXPECT_LT(FeatureRmsPx(d, frame, &matched, &unknown), kNoisyRmsBarPx);
  EXPECT_EQ(unknown, 0);
}

TEST(CheckerDetectorTest, SymmetricBoardIsReportedUpright) {
  // 8 x 6: cols + rows even, the board looks the same turned by 180 degrees. Rolled by
  // 170 degrees the detector reports it as if rolled by -10 (docs: as upright as possible).
  BoardView view;
  view.params = Checker(8, 6, 0.025);
  view.distance_m = 0.8;
  view.roll_deg = 170.0;
  const CameraFrame frame = RenderView(view, CleanRender(), 4);
  const Board board = *Board::Create(view.params);
  const Detection d = DetectChecker(frame.image8.view(), board);
  ExpectComplete(d, board);
  EXPECT_LT(d.features[0].uv_px.x(), d.features[7].uv_px.x());
  // The true corner 0 is at the bottom right: the reported corner 0 is the true corner 47.
  for (const RenderedFeature& t : frame.features) {
    if (t.feature_id == 47) {
      EXPECT_LT((d.features[0].uv_px - t.uv_px).norm(), 0.1);
    }
  }
}

TEST(CheckerDetectorTest, NothingOnOtherBoardsOrEmptyScenes) {
  const Board board = *Board::Create(Checker(9, 6, 0.025));
  // Another checker size, a larger one, the wide chessboard, the vertical board, the
  // circle board, and a scene with no board (the floor only).
  std::vector<BoardView> views;
  BoardView v;
  v.params = Checker(7, 5, 0.03);
  v.distance_m = 0.8;
  views.push_back(v);
  v.params = Checker(11, 8, 0.02);
  views.push_back(v);
  for (BoardType type : {BoardType::kChessboard, BoardType::kVertical, BoardType::kCircle,
                         BoardType::kAruco, BoardType::kApriltag}) {
    v.params = BoardParams();
    v.params.type = type;
    v.distance_m = 3.0;
    views.push_back(v);
  }
  v.params = Checker(9, 6, 0.025);
  v.distance_m = 0.8;
  v.yaw_deg = 180.0;  // the board's unprinted back
  views.push_back(v);
  std::uint64_t seed = 100;
  for (const BoardView& view : views) {
    CameraRenderOptions options = NoisyRender();
    options.clutter = true;
    const CameraFrame frame = RenderView(view, options, ++seed);
    const Detection d = DetectChecker(frame.image8.view(), board);
    EXPECT_FALSE(d.found) << BoardTypeName(view.params.type) << " " << view.params.cols;
    EXPECT_TRUE(d.features.empty());
    EXPECT_NE(d.reason, DetectReason::kNone);
  }
}

TEST(CheckerDetectorTest, BadInputGivesAReason) {
  const Board board = *Board::Create(Checker(9, 6, 0.025));
  EXPECT_EQ(DetectChecker(ImageView8{}, board).reason, DetectReason::kBadImage);
  const Image8 one(1, 1, 128);
  EXPECT_EQ(DetectChecker(one.view(), board).reason, DetectReason::kBadImage);
  const Image8 img(64, 64, 0);
  ImageView8 bad_stride = img.view();
  bad_stride.stride_bytes = 10;
  EXPECT_EQ(DetectChecker(bad_stride, board).reason, DetectReason::kBadImage);
  ImageView8 huge = img.view();
  huge.width = kMaxImageSide + 1;
  EXPECT_EQ(DetectChecker(huge, board).reason, DetectReason::kBadImage);
  EXPECT_EQ(DetectChecker(Image8(320, 240, 0).view(), board).reason, DetectReason::kLowContrast);
  EXPECT_EQ(DetectChecker(Image8(320, 240, 255).view(), board).reason, DetectReason::kLowContrast);
  const Image8 noise = test_scene::UniformNoiseImage(320, 240);
  const Detection d = DetectChecker(noise.view(), board);
  EXPECT_FALSE(d.found);
  EXPECT_TRUE(d.features.empty());
  BoardParams other;
  other.type = BoardType::kChessboard;
  EXPECT_EQ(DetectChecker(noise.view(), *Board::Create(other)).reason, DetectReason::kWrongBoard);
  CheckerOptions bad_options;
  bad_options.blur_sigma_px = 0.0;
  EXPECT_EQ(bad_options.Validate(), "blur_sigma_px");
  EXPECT_EQ(DetectChecker(noise.view(), board, bad_options).reason, DetectReason::kBadImage);
}

TEST(CheckerDetectorTest, SpeedAt1280x720) {
  BoardView view;
  view.params = Checker(9, 6, 0.025);
  view.distance_m = 1.0;
  view.yaw_deg = 30.0;
  CameraRenderOptions options = NoisyRender();
  options.clutter = true;
  const CameraFrame frame = RenderView(view, options, 5);
  const Board board = *Board::Create(view.params);
  constexpr int kRuns = 5;
  const double best_ms = test_scene::BestThreadCpuMs(kRuns, [&] {
    const Detection d = DetectChecker(frame.image8.view(), board);
    EXPECT_TRUE(d.found);
  });
  // Reported, not asserted: timing depends on the machine and the build type (the suite
  // also runs under ASan). Thread CPU time, so that other processes do not count.
  std::printf("checker 1280x720: %.2f ms CPU (best of %d)\n", best_ms, kRuns);
}

// The evaluation's hard renders (docs/detectors.md) of the board at its nearest, 64 px
// squares turned by 50 degrees of pitch (and 35 of yaw): the squares are sheared to
// parallelograms whose acute dark sectors (about 30 degrees) leave the blurred vertex far
// brighter than mid-grey under gamma 0.6, which the ring's centre test refused; and a 4 px
// ring at the integer peak can miss such a sector altogether. Both were misses (85% of
// the hard set).
TEST(CheckerDetectorTest, NearBoardTurnedFiftyDegreesUnderTheHardEffects) {
  const Board board = *Board::Create(BoardParams{.type = BoardType::kChecker});
  const CameraModel camera = circle_scene::Camera();
  // Its page over 80% of the image height: the evaluation's nearest distance.
  const double near_m =
      camera.intrinsics().fy * board.page_size_m().y() / (0.8 * camera.intrinsics().height);
  struct Case {
    double yaw, pitch, roll;
    std::uint64_t seed;
  };
  for (const Case& c : {Case{0, -50, -30, 15}, Case{35, 35, 0, 39}}) {
    SCOPED_TRACE(c.seed);
    const absl::StatusOr<CameraFrame> frame = circle_scene::RenderScene(
        circle_scene::OneBoard(BoardType::kChecker, circle_scene::EvaluationPose(
                                                        near_m, c.yaw, c.pitch, c.roll, c.seed)),
        circle_scene::HardEffects(c.seed), c.seed, camera);
    ASSERT_TRUE(frame.ok()) << frame.status();
    const Detection d = DetectChecker(frame->image8.view(), board);
    ExpectComplete(d, board);
    // Right correspondences: every corner far within 40% of a square (64 px) of its truth.
    EXPECT_LT(test_scene::MaxErrorPx(d, *frame), 1.0);
  }
}

}  // namespace
}  // namespace linecal

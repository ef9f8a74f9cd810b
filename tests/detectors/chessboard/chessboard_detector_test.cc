// The wide two-group chessboard detector on golden renders (station/sim/camera_render.h,
// exact ground truth): ids and sub-pixel errors over a grid of poses and sizes, clean and
// noisy, the upright rule of the board's 180-degree symmetry, nothing on other boards or
// board-free images, and the bad-input reasons.
#include "detectors/chessboard/chessboard_detector.h"

#include <gtest/gtest.h>
#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "detectors/detect.h"
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
using test_scene::MaxErrorPx;
using test_scene::NoisyRender;
using test_scene::RenderView;

constexpr int kFeatures = 20;

BoardParams Chessboard() {
  BoardParams p;
  p.type = BoardType::kChessboard;
  return p;
}

TEST(ChessboardDetectorTest, BoardIsSymmetricUnder180Degrees) {
  // Why the detector reports the upright orientation: the print is the same turned by 180
  // degrees, so no image can tell the two apart (header of chessboard_detector.h).
  const Board board = *Board::Create(Chessboard());
  const Eigen::Vector2d half = 0.5 * board.page_size_m();
  int checked = 0;
  for (int iy = 0; iy < 50; ++iy) {
    for (int ix = 0; ix < 260; ++ix) {
      // A 10 mm grid of points offset from every printed edge by 3 mm.
      const Eigen::Vector2d p(-half.x() + 0.003 + 0.01 * ix, -half.y() + 0.003 + 0.01 * iy);
      EXPECT_EQ(board.PaintAt(p), board.PaintAt(-p));
      ++checked;
    }
  }
  EXPECT_EQ(checked, 13000);
}

TEST(ChessboardDetectorTest, FrontalBoardHasExactIdsAndSubPixelCorners) {
  BoardView view;
  view.params = Chessboard();
  view.distance_m = 4.0;  // squares of 37.5 px, the board 650 px wide
  const CameraFrame frame = RenderView(view, CleanRender(), 1);
  const Board board = *Board::Create(view.params);
  const Detection d = DetectChessboard(frame.image8.view(), board);
  ExpectComplete(d, board);
  int matched = 0, unknown = 0;
  const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
  EXPECT_EQ(matched, kFeatures);
  EXPECT_EQ(unknown, 0);
  EXPECT_LT(rms, kCleanRmsBarPx);
  // Feature 0 is the left group's top-left corner, feature 19 the right group's
  // bottom-right one.
  EXPECT_LT(d.features[0].uv_px.x(), d.features[19].uv_px.x());
  EXPECT_LT(d.features[0].uv_px.y(), d.features[19].uv_px.y());
  // The dispatcher runs this detector.
  const std::optional<Detection> via = DetectBoard(frame.image8.view(), board);
  ASSERT_TRUE(via.has_value());
  EXPECT_TRUE(via->found);
}

TEST(ChessboardDetectorTest, PoseGridCleanAndNoisy) {
  const Board board = *Board::Create(Chessboard());
  int views = 0, detected = 0;
  double sum_sq_clean = 0.0, sum_sq_noisy = 0.0;
  int n_clean = 0, n_noisy = 0;
  std::uint64_t seed = 10;
  // 12 poses at the extremes of docs/acceptance.md (roll +-30, yaw -50/0/50, pitch +-50) over
  // three sizes: 2.6 m (board 77% of the image width, squares 58 px), 6 m (25 px) and 11 m
  // (13.6 px; 8 px wide on the far side at yaw 50); each rendered clean and noisy.
  constexpr std::array<double, 3> kDistances = {2.6, 6.0, 11.0};
  int index = 0;
  for (double roll : {-30.0, 30.0}) {
    for (double yaw : {-50.0, 0.0, 50.0}) {
      for (double pitch : {-50.0, 50.0}) {
        const double distance = kDistances[index++ % 3];
        for (bool noisy : {false, true}) {
          BoardView view;
          view.params = board.params();
          view.distance_m = distance;
          view.roll_deg = roll;
          view.yaw_deg = yaw;
          view.pitch_deg = pitch;
          const CameraFrame frame = RenderView(view, noisy ? NoisyRender() : CleanRender(), ++seed);
          ASSERT_EQ(frame.features.size(), static_cast<std::size_t>(kFeatures))
              << "the grid's views keep the whole board in the image";
          const Detection d = DetectChessboard(frame.image8.view(), board);
          ++views;
          if (!d.found) {
            ADD_FAILURE() << "roll " << roll << " yaw " << yaw << " pitch " << pitch << " distance "
                          << distance << " noisy " << noisy << ": " << DetectReasonName(d.reason);
            continue;
          }
          ++detected;
          int matched = 0, unknown = 0;
          const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
          EXPECT_EQ(matched, kFeatures);
          EXPECT_EQ(unknown, 0);
          EXPECT_LT(MaxErrorPx(d, frame), 0.5) << "roll " << roll << " yaw " << yaw;
          (noisy ? sum_sq_noisy : sum_sq_clean) += rms * rms * matched;
          (noisy ? n_noisy : n_clean) += matched;
        }
      }
    }
  }
  const double rms_clean = std::sqrt(sum_sq_clean / std::max(n_clean, 1));
  const double rms_noisy = std::sqrt(sum_sq_noisy / std::max(n_noisy, 1));
  std::printf("chessboard pose grid: %d / %d detected, RMS clean %.4f px, noisy %.4f px\n",
              detected, views, rms_clean, rms_noisy);
  EXPECT_EQ(detected, views);
  EXPECT_LT(rms_clean, kCleanRmsBarPx);
  EXPECT_LT(rms_noisy, kNoisyRmsBarPx);
}

TEST(ChessboardDetectorTest, SmallestSquaresOfTwelvePixelsWithLightingEffects) {
  BoardView view;
  view.params = Chessboard();
  view.distance_m = 1000.0 * 0.15 / 12.0;  // f = 1000 px: 12 px squares
  view.yaw_deg = 20.0;
  CameraRenderOptions options = NoisyRender();
  options.illumination_gradient_ratio = 3.0;
  options.gamma = 1.4;
  options.clutter = true;
  const CameraFrame frame = RenderView(view, options, 3);
  const Board board = *Board::Create(view.params);
  const Detection d = DetectChessboard(frame.image8.view(), board);
  ExpectComplete(d, board);
  EXPECT_LT(MaxErrorPx(d, frame), 0.5);
}

// docs/acceptance.md's harshest effects: a 4:1 illumination gradient across the board in four
// directions, gamma 0.6 and 1.6, noise 6, blur 1.5, JPEG 80, clutter. The paint check compares
// nearby probes under the same light, so the dark end of the gradient still reads as white
// paper (a binarised check refused 88% of such renders as wrong_board).
TEST(ChessboardDetectorTest, HardLightingAndNoiseStillFindTheBoard) {
  const Board board = *Board::Create(Chessboard());
  int found = 0, views = 0;
  for (double direction : {0.0, 90.0, 200.0, 300.0}) {
    for (double gamma : {0.6, 1.6}) {
      BoardView view;
      view.params = Chessboard();
      view.distance_m = 5.0;
      view.yaw_deg = 30.0;
      view.roll_deg = 15.0;
      CameraRenderOptions options = CleanRender();
      options.noise_sigma = 6.0;
      options.blur_sigma_px = 1.5;
      options.illumination_gradient_ratio = 4.0;
      options.illumination_gradient_direction_deg = direction;
      options.gamma = gamma;
      options.jpeg_quality = 80;
      options.clutter = true;
      const CameraFrame frame = RenderView(view, options, static_cast<std::uint64_t>(100 + views));
      const Detection d = DetectChessboard(frame.image8.view(), board);
      ++views;
      if (!d.found) {
        ADD_FAILURE() << "gradient towards " << direction << " deg, gamma " << gamma << ": "
                      << DetectReasonName(d.reason);
        continue;
      }
      ++found;
      ExpectComplete(d, board);
      EXPECT_LT(MaxErrorPx(d, frame), 0.5) << direction << " " << gamma;
    }
  }
  EXPECT_EQ(found, views);
}

// The evaluation's hard renders of the smallest squares (12 px) turned 50 degrees, where
// squares foreshortened to 7 px under blur 1.5 merge into blobs and only the second path's
// X-corners find the board (docs/detectors.md). Its 3 px ring, tested at the integer
// response peak only, missed a vertex 0.5 px off it in each of these (93% of the hard set).
TEST(ChessboardDetectorTest, SmallestSquaresTurnedFiftyDegreesUnderTheHardEffects) {
  const Board board = *Board::Create(Chessboard());
  const CameraModel camera = circle_scene::Camera();
  const double far_m = camera.intrinsics().fx * 0.150 / 12.0;  // docs/boards.md: 150 mm squares
  struct Case {
    double yaw, pitch, roll;
    std::uint64_t seed;
  };
  for (const Case& c : {Case{0, 50, -30, 138}, Case{0, -50, 0, 162}, Case{-35, -35, 0, 168}}) {
    SCOPED_TRACE(c.seed);
    const absl::StatusOr<CameraFrame> frame = circle_scene::RenderScene(
        circle_scene::OneBoard(BoardType::kChessboard,
                               circle_scene::EvaluationPose(far_m, c.yaw, c.pitch, c.roll, c.seed)),
        circle_scene::HardEffects(c.seed), c.seed, camera);
    ASSERT_TRUE(frame.ok()) << frame.status();
    const Detection d = DetectChessboard(frame->image8.view(), board);
    ExpectComplete(d, board);
    EXPECT_LT(MaxErrorPx(d, *frame), 0.4 * 12.0 * std::cos(50 * circle_scene::kDeg));
  }
}

TEST(ChessboardDetectorTest, UpsideDownBoardIsReportedUpright) {
  // Rolled by 170 degrees the board is reported as if rolled by -10 (the upright rule): the
  // reported feature k is the true feature at the 180-degree image of k's position.
  BoardView view;
  view.params = Chessboard();
  view.distance_m = 4.0;
  view.roll_deg = 170.0;
  const CameraFrame frame = RenderView(view, CleanRender(), 4);
  const Board board = *Board::Create(view.params);
  const Detection d = DetectChessboard(frame.image8.view(), board);
  ExpectComplete(d, board);
  EXPECT_LT(d.features[0].uv_px.x(), d.features[19].uv_px.x());
  int checked = 0;
  for (const DetectedFeature& f : d.features) {
    for (const BoardFeature& g : board.features()) {
      if ((g.p_board + f.p_board).norm() > 1e-9) continue;
      for (const RenderedFeature& t : frame.features) {
        if (t.feature_id != g.id) continue;
        EXPECT_LT((f.uv_px - t.uv_px).norm(), 0.1) << f.id;
        ++checked;
      }
    }
  }
  EXPECT_EQ(checked, kFeatures);
}

TEST(ChessboardDetectorTest, NothingOnOtherBoardsOrEmptyScenes) {
  const Board board = *Board::Create(Chessboard());
  std::vector<BoardView> views;
  BoardView v;
  for (BoardType type : {BoardType::kChecker, BoardType::kVertical, BoardType::kCircle,
                         BoardType::kAruco, BoardType::kApriltag, BoardType::kRoundHole}) {
    v.params = BoardParams();
    v.params.type = type;
    v.distance_m = type == BoardType::kChecker ? 0.8 : 2.0;
    views.push_back(v);
  }
  // A large checker (many diagonal triples, some 13 squares apart).
  v.params = BoardParams();
  v.params.type = BoardType::kChecker;
  v.params.cols = 19;
  v.params.rows = 9;
  v.params.square_m = 0.03;
  v.distance_m = 1.0;
  views.push_back(v);
  v.params = Chessboard();
  v.distance_m = 4.0;
  v.yaw_deg = 180.0;  // the board's unprinted back
  views.push_back(v);
  v.params = Chessboard();
  v.distance_m = 4.0;
  v.yaw_deg = 0.0;
  v.offset_m = Eigen::Vector2d(0.0, 30.0);  // far out of view: walls and floor only
  views.push_back(v);
  std::uint64_t seed = 100;
  for (const BoardView& view : views) {
    CameraRenderOptions options = NoisyRender();
    options.clutter = true;
    const CameraFrame frame = RenderView(view, options, ++seed);
    const Detection d = DetectChessboard(frame.image8.view(), board);
    EXPECT_FALSE(d.found) << BoardTypeName(view.params.type) << " " << view.params.cols;
    EXPECT_TRUE(d.features.empty());
    EXPECT_NE(d.reason, DetectReason::kNone);
  }
}

TEST(ChessboardDetectorTest, BadInputGivesAReason) {
  const Board board = *Board::Create(Chessboard());
  EXPECT_EQ(DetectChessboard(ImageView8{}, board).reason, DetectReason::kBadImage);
  const Image8 one(1, 1, 128);
  EXPECT_EQ(DetectChessboard(one.view(), board).reason, DetectReason::kBadImage);
  const Image8 img(64, 64, 0);
  ImageView8 bad_stride = img.view();
  bad_stride.stride_bytes = 10;
  EXPECT_EQ(DetectChessboard(bad_stride, board).reason, DetectReason::kBadImage);
  ImageView8 huge = img.view();
  huge.width = kMaxImageSide + 1;
  EXPECT_EQ(DetectChessboard(huge, board).reason, DetectReason::kBadImage);
  EXPECT_EQ(DetectChessboard(Image8(320, 240, 0).view(), board).reason, DetectReason::kLowContrast);
  EXPECT_EQ(DetectChessboard(Image8(320, 240, 255).view(), board).reason,
            DetectReason::kLowContrast);
  const Image8 noise = test_scene::UniformNoiseImage(320, 240);
  const Detection d = DetectChessboard(noise.view(), board);
  EXPECT_FALSE(d.found);
  EXPECT_TRUE(d.features.empty());
  EXPECT_NE(d.reason, DetectReason::kNone);
  BoardParams other;
  other.type = BoardType::kChecker;
  EXPECT_EQ(DetectChessboard(noise.view(), *Board::Create(other)).reason,
            DetectReason::kWrongBoard);
  ChessboardOptions bad_options;
  bad_options.touch_fraction = 0.0;
  EXPECT_EQ(bad_options.Validate(), "touch_fraction");
  EXPECT_EQ(DetectChessboard(noise.view(), board, bad_options).reason, DetectReason::kBadImage);
}

TEST(ChessboardDetectorTest, SpeedAt1280x720) {
  BoardView view;
  view.params = Chessboard();
  view.distance_m = 4.0;
  view.yaw_deg = 30.0;
  CameraRenderOptions options = NoisyRender();
  options.clutter = true;
  const CameraFrame frame = RenderView(view, options, 5);
  const Board board = *Board::Create(view.params);
  constexpr int kRuns = 5;
  const double best_ms = test_scene::BestThreadCpuMs(kRuns, [&] {
    const Detection d = DetectChessboard(frame.image8.view(), board);
    EXPECT_TRUE(d.found);
  });
  // Reported, not asserted: timing depends on the machine and the build type (the suite
  // also runs under ASan). Thread CPU time, so that other processes do not count.
  std::printf("chessboard 1280x720: %.2f ms CPU (best of %d)\n", best_ms, kRuns);

  // A board only the second path (X-corner pairs) finds: 13.6 px squares at roll 30, yaw
  // and pitch 50, noisy (a view of PoseGridCleanAndNoisy).
  view.distance_m = 11.0;
  view.roll_deg = 30.0;
  view.yaw_deg = 50.0;
  view.pitch_deg = 50.0;
  const CameraFrame small = RenderView(view, NoisyRender(), 6);
  const double second_path_ms = test_scene::BestThreadCpuMs(kRuns, [&] {
    const Detection d = DetectChessboard(small.image8.view(), board);
    EXPECT_TRUE(d.found);
  });
  std::printf("chessboard 1280x720, second path: %.2f ms CPU (best of %d)\n", second_path_ms,
              kRuns);
}

}  // namespace
}  // namespace linecal

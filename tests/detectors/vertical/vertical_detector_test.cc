// The vertical-board detector on golden renders (station/sim/camera_render.h, exact ground
// truth): ids and sub-pixel errors over a grid of poses, clean and noisy; partial views cut
// by the image border; nothing on other boards or board-free images; bad-input reasons.
#include "detectors/vertical/vertical_detector.h"

#include <gtest/gtest.h>
#include <time.h>

#include <cmath>
#include <cstdio>
#include <optional>
#include <utility>
#include <vector>

#include "detectors/detect.h"
#include "tests/detectors/board_scene.h"

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

// f = 1000 px: a 50 mm cell is 1000 * 0.05 / d px at distance d.
constexpr double kCellM = 0.05;
constexpr double kFocalPx = 1000.0;

BoardParams Vertical() {
  BoardParams p;
  p.type = BoardType::kVertical;
  return p;
}

TEST(VerticalDetectorTest, FrontalBoardHasExactIdsAndSubPixelCorners) {
  BoardView view;
  view.params = Vertical();
  view.distance_m = 2.0;  // cells of 25 px, the board 500 px tall
  const CameraFrame frame = RenderView(view, CleanRender(), 1);
  const Board board = *Board::Create(view.params);
  const Detection d = DetectVertical(frame.image8.view(), board);
  ExpectComplete(d, board);
  int matched = 0, unknown = 0;
  const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
  std::printf("frontal: rms %.4f px\n", rms);
  EXPECT_EQ(matched, 51);
  EXPECT_EQ(unknown, 0);
  EXPECT_LT(rms, kCleanRmsBarPx);
  // Feature 0 is on the top row: above the last one in an upright view.
  EXPECT_LT(d.features[0].uv_px.y(), d.features[50].uv_px.y());
}

// Runs the detector on one view; checks ids against the render's ground truth and adds the
// squared errors to *sum_sq / *n. Returns the detection.
Detection DetectAndScore(const BoardView& view, const CameraRenderOptions& options,
                         std::uint64_t seed, double* sum_sq, int* n, int* unknown_ids) {
  const CameraFrame frame = RenderView(view, options, seed);
  const Board board = *Board::Create(view.params);
  const Detection d = DetectVertical(frame.image8.view(), board);
  int matched = 0, unknown = 0;
  const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
  *sum_sq += rms * rms * matched;
  *n += matched;
  *unknown_ids += unknown;
  return d;
}

TEST(VerticalDetectorTest, PoseGridCleanAndNoisy) {
  const Board board = *Board::Create(Vertical());
  int views = 0, detected = 0, unknown_ids = 0;
  double sum_sq_clean = 0.0, sum_sq_noisy = 0.0;
  int n_clean = 0, n_noisy = 0;
  std::uint64_t seed = 10;
  // Roll -30 / 0 / 30, yaw and pitch at docs/acceptance.md's extremes (+-50) and between, two
  // sizes: cells of 25 px (2 m) and of 13 px (3.8 m); each clean and noisy (sigma 4, blur
  // 1.0, a 3:1 lighting gradient, gamma 1.4).
  int index = 0;
  for (double roll : {-30.0, 0.0, 30.0}) {
    for (const auto& [yaw, pitch] : {std::pair{-50.0, 0.0}, std::pair{50.0, 20.0},
                                     std::pair{0.0, 50.0}, std::pair{25.0, -40.0}}) {
      const double distance = (index++ % 2 == 0) ? 2.0 : kFocalPx * kCellM / 13.0;
      for (bool noisy : {false, true}) {
        BoardView view;
        view.params = Vertical();
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
        const Detection d =
            DetectAndScore(view, options, ++seed, noisy ? &sum_sq_noisy : &sum_sq_clean,
                           noisy ? &n_noisy : &n_clean, &unknown_ids);
        ++views;
        if (!d.found) {
          ADD_FAILURE() << "roll " << roll << " yaw " << yaw << " pitch " << pitch << " distance "
                        << distance << " noisy " << noisy << ": " << DetectReasonName(d.reason)
                        << " " << d.features.size();
          continue;
        }
        ++detected;
        EXPECT_EQ(d.features.size(), board.features().size());
      }
    }
  }
  const double rms_clean = std::sqrt(sum_sq_clean / std::max(n_clean, 1));
  const double rms_noisy = std::sqrt(sum_sq_noisy / std::max(n_noisy, 1));
  std::printf("vertical pose grid: %d / %d detected, RMS clean %.4f px, noisy %.4f px\n", detected,
              views, rms_clean, rms_noisy);
  EXPECT_EQ(detected, views);
  EXPECT_EQ(unknown_ids, 0);
  EXPECT_LT(rms_clean, kCleanRmsBarPx);
  EXPECT_LT(rms_noisy, kNoisyRmsBarPx);
}

TEST(VerticalDetectorTest, SmallestCellsOfTwelvePixels) {
  BoardView view;
  view.params = Vertical();
  view.distance_m = kFocalPx * kCellM / 12.0;
  view.yaw_deg = 20.0;
  view.roll_deg = 10.0;
  const CameraFrame frame = RenderView(view, NoisyRender(), 3);
  const Board board = *Board::Create(view.params);
  const Detection d = DetectVertical(frame.image8.view(), board);
  ExpectComplete(d, board);
  int matched = 0, unknown = 0;
  EXPECT_LT(FeatureRmsPx(d, frame, &matched, &unknown), kNoisyRmsBarPx);
  EXPECT_EQ(unknown, 0);
}

// The board at 1.2 m (cells of 42 px), shifted up or down so that the image border cuts off
// a third of it.
BoardView CutView(bool top_cut, double roll_deg, double yaw_deg) {
  BoardView view;
  view.params = Vertical();
  view.distance_m = 1.2;
  // The image's half height at 1.2 m is 0.432 m; the board's third from its edge (0.167 m
  // from its centre) lands on the border.
  view.offset_m = Eigen::Vector2d(0.0, top_cut ? 0.265 : -0.265);
  view.roll_deg = roll_deg;
  view.yaw_deg = yaw_deg;
  return view;
}

TEST(VerticalDetectorTest, PartialViewsAreReportedWithCorrectIds) {
  const Board board = *Board::Create(Vertical());
  std::uint64_t seed = 40;
  for (bool top_cut : {true, false}) {
    for (const auto& [roll, yaw] :
         {std::pair{0.0, 0.0}, std::pair{-20.0, 30.0}, std::pair{15.0, -40.0}}) {
      for (bool noisy : {false, true}) {
        const BoardView view = CutView(top_cut, roll, yaw);
        const CameraFrame frame = RenderView(view, noisy ? NoisyRender() : CleanRender(), ++seed);
        const Detection d = DetectVertical(frame.image8.view(), board);
        EXPECT_FALSE(d.found);
        EXPECT_EQ(d.reason, DetectReason::kPartial)
            << "top_cut " << top_cut << " roll " << roll << " yaw " << yaw << " noisy " << noisy
            << ": " << DetectReasonName(d.reason);
        int matched = 0, unknown = 0;
        const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
        EXPECT_EQ(unknown, 0);
        // Two thirds of the board: at least 12 of its 19 vertex rows hold certain features.
        EXPECT_GE(matched, 30) << "top_cut " << top_cut << " roll " << roll << " yaw " << yaw;
        EXPECT_LT(rms, noisy ? kNoisyRmsBarPx : kCleanRmsBarPx);
        for (const DetectedFeature& f : d.features) {
          EXPECT_EQ(f.p_board, board.features()[f.id].p_board);
          // Features of the cut third (board y above +0.167 m or below -0.167 m) are not
          // reported: they are outside the image.
          EXPECT_LT(top_cut ? f.p_board.y() : -f.p_board.y(), 0.17);
        }
      }
    }
  }
}

TEST(VerticalDetectorTest, NothingOnOtherBoardsOrEmptyScenes) {
  const Board board = *Board::Create(Vertical());
  std::vector<BoardView> views;
  BoardView v;
  v.distance_m = 2.5;
  for (BoardType type : {BoardType::kChessboard, BoardType::kCircle, BoardType::kAruco,
                         BoardType::kApriltag, BoardType::kRoundHole, BoardType::kChecker}) {
    v.params = BoardParams();
    v.params.type = type;
    v.distance_m = type == BoardType::kChecker ? 0.8 : 3.0;
    views.push_back(v);
  }
  // A large checker (its columns are runs of X-corners) and the board's unprinted back.
  v.params = BoardParams();
  v.params.type = BoardType::kChecker;
  v.params.cols = 17;
  v.params.rows = 3;
  v.distance_m = 1.0;
  views.push_back(v);
  v.params = Vertical();
  v.distance_m = 2.0;
  v.yaw_deg = 180.0;
  views.push_back(v);
  std::uint64_t seed = 100;
  for (const BoardView& view : views) {
    CameraRenderOptions options = NoisyRender();
    options.clutter = true;
    const CameraFrame frame = RenderView(view, options, ++seed);
    const Detection d = DetectVertical(frame.image8.view(), board);
    EXPECT_FALSE(d.found) << BoardTypeName(view.params.type);
    EXPECT_TRUE(d.features.empty()) << BoardTypeName(view.params.type);
    EXPECT_NE(d.reason, DetectReason::kNone);
    EXPECT_NE(d.reason, DetectReason::kPartial) << BoardTypeName(view.params.type);
  }
}

TEST(VerticalDetectorTest, BadInputGivesAReason) {
  const Board board = *Board::Create(Vertical());
  EXPECT_EQ(DetectVertical(ImageView8{}, board).reason, DetectReason::kBadImage);
  const Image8 one(1, 1, 128);
  EXPECT_EQ(DetectVertical(one.view(), board).reason, DetectReason::kBadImage);
  EXPECT_EQ(DetectVertical(Image8(320, 240, 0).view(), board).reason, DetectReason::kLowContrast);
  EXPECT_EQ(DetectVertical(Image8(320, 240, 255).view(), board).reason, DetectReason::kLowContrast);
  const Image8 noise = test_scene::UniformNoiseImage(320, 240);
  const Detection d = DetectVertical(noise.view(), board);
  EXPECT_FALSE(d.found);
  EXPECT_TRUE(d.features.empty());
  EXPECT_NE(d.reason, DetectReason::kNone);
  BoardParams other;
  other.type = BoardType::kCircle;
  EXPECT_EQ(DetectVertical(noise.view(), *Board::Create(other)).reason, DetectReason::kWrongBoard);
  VerticalOptions bad_options;
  bad_options.min_chain_corners = 2;
  EXPECT_EQ(bad_options.Validate(), "min_chain_corners");
  EXPECT_EQ(DetectVertical(noise.view(), board, bad_options).reason, DetectReason::kBadImage);
}

TEST(VerticalDetectorTest, DetectBoardDispatchesToTheVerticalDetector) {
  BoardView view;
  view.params = Vertical();
  view.distance_m = 2.0;
  const CameraFrame frame = RenderView(view, CleanRender(), 7);
  const Board board = *Board::Create(view.params);
  const std::optional<Detection> d = DetectBoard(frame.image8.view(), board);
  ASSERT_TRUE(d.has_value());
  EXPECT_TRUE(d->found) << DetectReasonName(d->reason);
  EXPECT_EQ(d->features.size(), 51u);
}

TEST(VerticalDetectorTest, SpeedAt1280x720) {
  BoardView view;
  view.params = Vertical();
  view.distance_m = 2.0;
  view.yaw_deg = 30.0;
  CameraRenderOptions options = NoisyRender();
  options.clutter = true;
  const CameraFrame frame = RenderView(view, options, 5);
  const Board board = *Board::Create(view.params);
  constexpr int kRuns = 5;
  const double best_ms = test_scene::BestThreadCpuMs(kRuns, [&] {
    const Detection d = DetectVertical(frame.image8.view(), board);
    EXPECT_TRUE(d.found) << DetectReasonName(d.reason);
  });
  // Reported, not asserted: timing depends on the machine and the build type (the suite
  // also runs under ASan). Thread CPU time, so that other processes do not count.
  std::printf("vertical 1280x720: %.2f ms CPU (best of %d)\n", best_ms, kRuns);
}

}  // namespace
}  // namespace linecal

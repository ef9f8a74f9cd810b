// The ArUco board detector (and the camera side of the round-hole board) on golden renders
// (station/sim/camera_render.h, exact ground truth): ids and sub-pixel errors over a grid of
// poses with noise, blur and lighting, partial views, nothing on other boards, board-free
// images or markers of other ids, and the bad-input reasons.
#include "detectors/aruco/aruco_detector.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <random>
#include <vector>

#include "detectors/boards/aruco_dict_4x4_50.h"
#include "tests/detectors/board_scene.h"
#include "tests/detectors/circle/circle_scene.h"

namespace linecal {
namespace {

using test_scene::BoardView;
using test_scene::CleanRender;
using test_scene::FeatureRmsPx;
using test_scene::NoisyRender;
using test_scene::RenderView;

// docs/acceptance.md's sub-pixel bars.
constexpr double kCleanRmsBarPx = 0.05;  // noise 0, blur 0.5
constexpr double kNoisyRmsBarPx = 0.12;  // noise sigma 4, blur 1.0

BoardParams Params(BoardType type) {
  BoardParams p;
  p.type = type;
  return p;
}

Board MakeBoard(BoardType type) { return *Board::Create(Params(type)); }

// All 16 marker corners with their own ids, board positions and marker ids.
void ExpectAllMarkerCorners(const Detection& d, const Board& board) {
  ASSERT_TRUE(d.found) << DetectReasonName(d.reason);
  EXPECT_EQ(d.reason, DetectReason::kNone);
  ASSERT_EQ(d.features.size(), 16u);
  for (std::size_t i = 0; i < d.features.size(); ++i) {
    EXPECT_EQ(d.features[i].id, static_cast<int>(i));
    EXPECT_EQ(d.features[i].p_board, board.features()[i].p_board);
    EXPECT_EQ(d.features[i].marker, board.features()[i].marker);
  }
}

TEST(ArucoDetectorTest, FrontalCleanBoardHasExactIdsAndSubPixelCorners) {
  const Board board = MakeBoard(BoardType::kAruco);
  BoardView view;
  view.params = board.params();
  view.distance_m = 1.8;
  view.roll_deg = 7.0;  // off the pixel grid, so corners are not at pixel centres
  const CameraFrame frame = RenderView(view, CleanRender(), 1);
  const Detection d = DetectAruco(frame.image8.view(), board);
  ExpectAllMarkerCorners(d, board);
  int matched = 0;
  int unknown = 0;
  const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
  EXPECT_EQ(matched, 16);
  EXPECT_EQ(unknown, 0);
  EXPECT_LE(rms, kCleanRmsBarPx);
  std::printf("clean RMS %.4f px\n", rms);
}

TEST(ArucoDetectorTest, NoisyBlurredBoardMeetsTheNoisyBar) {
  const Board board = MakeBoard(BoardType::kAruco);
  BoardView view;
  view.params = board.params();
  view.distance_m = 2.5;
  view.yaw_deg = 20.0;
  view.roll_deg = -12.0;
  const CameraFrame frame = RenderView(view, NoisyRender(), 2);
  const Detection d = DetectAruco(frame.image8.view(), board);
  ExpectAllMarkerCorners(d, board);
  int matched = 0;
  int unknown = 0;
  const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
  EXPECT_EQ(unknown, 0);
  EXPECT_LE(rms, kNoisyRmsBarPx);
  std::printf("noisy RMS %.4f px\n", rms);
}

// Corners of markers seen at the extremes of the pose range, small and large, under noise,
// blur, an illumination gradient and gamma: every board found, every id right. The error
// bound is looser than the bar: at 50 degrees a 4 m view has data cells of about 4 px,
// where a blurred cell's neighbours bias the edge fit.
constexpr double kGridRmsBoundPx = 0.25;

TEST(ArucoDetectorTest, FindsTheBoardOverAPoseGrid) {
  const Board board = MakeBoard(BoardType::kAruco);
  struct Pose {
    double distance_m, roll_deg, yaw_deg, pitch_deg;
  };
  const std::vector<Pose> poses = {
      {1.5, 30, 50, 0},   {1.5, -30, 0, -50}, {2.5, 0, -50, 50},  {2.5, 30, 50, 50},
      {4.0, -30, -50, 0}, {4.0, 0, 0, 50},    {4.0, 30, 50, -50}, {6.0, 15, 30, 30},
  };
  std::uint64_t seed = 10;
  for (const Pose& pose : poses) {
    BoardView view;
    view.params = board.params();
    view.distance_m = pose.distance_m;
    view.roll_deg = pose.roll_deg;
    view.yaw_deg = pose.yaw_deg;
    view.pitch_deg = pose.pitch_deg;
    CameraRenderOptions o = NoisyRender();
    o.illumination_gradient_ratio = 4.0;
    o.illumination_gradient_direction_deg = 30.0 * seed;
    // Every other view under a strong gamma, which moves a blurred edge's apparent position
    // (docs/acceptance.md's error bars are for the linear response): detection and ids only.
    const bool linear = seed % 2 == 0;
    if (!linear) o.gamma = (seed % 4 == 1) ? 0.6 : 1.6;
    const CameraFrame frame = RenderView(view, o, seed++);
    ASSERT_EQ(frame.features.size(), 16u) << "the whole board must be in view";
    const Detection d = DetectAruco(frame.image8.view(), board);
    SCOPED_TRACE(::testing::Message()
                 << "distance " << pose.distance_m << " roll " << pose.roll_deg << " yaw "
                 << pose.yaw_deg << " pitch " << pose.pitch_deg << " gamma " << o.gamma << ": "
                 << DetectReasonName(d.reason));
    ExpectAllMarkerCorners(d, board);
    int matched = 0;
    int unknown = 0;
    const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
    if (linear) {
      EXPECT_LE(rms, kGridRmsBoundPx);
    }
    EXPECT_EQ(unknown, 0);
  }
}

TEST(ArucoDetectorTest, RoundHoleBoardIsFoundThroughItsMarkersAndTellsTheBoardsApart) {
  const Board round_hole = MakeBoard(BoardType::kRoundHole);
  const Board aruco = MakeBoard(BoardType::kAruco);
  BoardView view;
  view.params = round_hole.params();
  view.distance_m = 2.2;
  view.yaw_deg = -25.0;
  const CameraFrame frame = RenderView(view, NoisyRender(), 3);
  const Detection d = DetectAruco(frame.image8.view(), round_hole);
  ASSERT_TRUE(d.found) << DetectReasonName(d.reason);
  ASSERT_EQ(d.features.size(), 16u);  // the hole centres 16..20 are the LiDAR's
  for (int i = 0; i < 16; ++i) EXPECT_EQ(d.features[i].id, i);
  int matched = 0;
  int unknown = 0;
  EXPECT_LE(FeatureRmsPx(d, frame, &matched, &unknown), kNoisyRmsBarPx);
  EXPECT_EQ(unknown, 0);

  // The same markers on the other board's print: the paint check refuses both ways.
  const Detection as_aruco = DetectAruco(frame.image8.view(), aruco);
  EXPECT_FALSE(as_aruco.found);
  EXPECT_EQ(as_aruco.reason, DetectReason::kWrongBoard);
  EXPECT_TRUE(as_aruco.features.empty());
  view.params = aruco.params();
  const CameraFrame aruco_frame = RenderView(view, NoisyRender(), 4);
  const Detection as_round_hole = DetectAruco(aruco_frame.image8.view(), round_hole);
  EXPECT_FALSE(as_round_hole.found);
  EXPECT_EQ(as_round_hole.reason, DetectReason::kWrongBoard);
  EXPECT_TRUE(as_round_hole.features.empty());
}

// docs/acceptance.md's hardest lighting: a 4:1 illumination gradient across the board, gamma 0.6
// and 1.6, noise 6, blur 1.5, JPEG 80, clutter behind. The white paper at the dim end is
// darker than the black print at the bright end, so the whole-board paint check compares
// nearby points under the same light (PaintAgrees); both boards that print these markers
// are found, each told from the other.
TEST(ArucoDetectorTest, HardLightingFindsBothMarkerBoards) {
  std::uint64_t seed = 70;
  for (const BoardType type : {BoardType::kAruco, BoardType::kRoundHole}) {
    const Board board = MakeBoard(type);
    const Board sibling =
        MakeBoard(type == BoardType::kAruco ? BoardType::kRoundHole : BoardType::kAruco);
    for (const double gamma : {0.6, 1.6}) {
      BoardView view;
      view.params = board.params();
      view.distance_m = 3.0;
      view.yaw_deg = 30.0;
      view.roll_deg = -20.0;
      CameraRenderOptions o = NoisyRender();
      o.noise_sigma = 6.0;
      o.blur_sigma_px = 1.5;
      o.illumination_gradient_ratio = 4.0;
      o.illumination_gradient_direction_deg = 37.0 * static_cast<double>(seed);
      o.gamma = gamma;
      o.jpeg_quality = 80;
      o.clutter = true;
      const CameraFrame frame = RenderView(view, o, seed++);
      SCOPED_TRACE(::testing::Message() << BoardTypeName(type) << " gamma " << gamma);
      const Detection d = DetectAruco(frame.image8.view(), board);
      ASSERT_TRUE(d.found) << DetectReasonName(d.reason);
      ASSERT_EQ(d.features.size(), 16u);
      // Every corner is the right one, within the detectors_eval's line for a wrong feature
      // (40% of a cell). Not within the noisy bar: a gamma applied after the blur moves every
      // blurred edge, the marker's dark square grows or shrinks, and its corners move out or
      // in along the diagonals (0.7-0.8 px RMS here; 0.15 px with the same blur and noise at
      // gamma 1). docs/acceptance.md sets no accuracy bar for this lighting.
      const double cell_px =
          (frame.features[1].uv_px - frame.features[0].uv_px).norm() / kAruco4x4MarkerCells;
      for (const DetectedFeature& f : d.features) {
        const RenderedFeature& truth = frame.features.at(f.id);
        ASSERT_EQ(truth.feature_id, f.id);
        EXPECT_LE((f.uv_px - truth.uv_px).norm(), 0.4 * cell_px) << "corner " << f.id;
      }
      const Detection other = DetectAruco(frame.image8.view(), sibling);
      EXPECT_FALSE(other.found);
      EXPECT_TRUE(other.features.empty());
    }
  }
}

// Large markers are found in the reduced images (DetectMarkerBoard) and refined at full
// resolution: the corners are those of a scan of the full image, within the clean bar's
// share, and as near the truth.
// The evaluation's noisy renders (noise 4, blur 1.0) of the board at its smallest, 4 px
// cells, turned 50 degrees, that it missed: every marker decoded, but the fine pass moved a
// corner 0.35-0.4 of a cell from the coarse pass's eight-point estimate, past the third of
// a cell it allowed, and dropped the marker.
TEST(ArucoDetectorTest, SmallestMarkersTurnedFiftyDegreesUnderNoise) {
  const Board board = MakeBoard(BoardType::kAruco);
  const CameraModel camera = circle_scene::Camera();
  const double far_m = camera.intrinsics().fx * 0.040 / 4.0;  // docs/boards.md: 40 mm cells
  struct Case {
    double yaw, pitch, roll;
    std::uint64_t seed;
  };
  for (const Case& c : {Case{0, 50, -30, 137}, Case{35, 35, -30, 143}, Case{-35, -35, -30, 146},
                        Case{0, 50, 30, 179}}) {
    SCOPED_TRACE(c.seed);
    const absl::StatusOr<CameraFrame> frame = circle_scene::RenderScene(
        circle_scene::OneBoard(BoardType::kAruco,
                               circle_scene::EvaluationPose(far_m, c.yaw, c.pitch, c.roll, c.seed)),
        circle_scene::Effects(4.0, 1.0), c.seed, camera);
    ASSERT_TRUE(frame.ok()) << frame.status();
    const Detection d = DetectAruco(frame->image8.view(), board);
    ExpectAllMarkerCorners(d, board);
    // Right correspondences: every corner within 40% of a 4 px cell of its truth.
    EXPECT_LT(test_scene::MaxErrorPx(d, *frame), 1.6);
  }
}

// The same smallest markers, foreshortened across one side or the other: their corners
// meet docs/acceptance.md's noisy bar. Edge-point centroids were 0.2-0.35 px RMS off on these
// renders (the border is one 2.6-4 px cell, and a dark cell behind it or a black board
// cell beyond the quiet zone moves each side's centroid by its own amount); the sides are
// now fitted to a model of the blurred page (detectors/markers/page_edge_fit.h).
TEST(ArucoDetectorTest, SmallestMarkersMeetTheNoisyBar) {
  const CameraModel camera = circle_scene::Camera();
  const double far_m = camera.intrinsics().fx * 0.040 / 4.0;  // docs/boards.md: 40 mm cells
  struct Case {
    double yaw, pitch, roll;
    std::uint64_t seed;
  };
  const std::vector<Case> cases = {
      Case{-50, 0, -30, 21}, Case{0, 50, 30, 22}, Case{35, 35, 0, 23},   Case{0, 0, 0, 24},
      Case{0, -50, -30, 25}, Case{50, 0, 30, 26}, Case{-35, -35, 30, 27}};
  for (const BoardType type : {BoardType::kAruco, BoardType::kRoundHole}) {
    const Board board = MakeBoard(type);
    for (const Case& c : cases) {
      // The round-hole board at this size under noise is not always found (docs/detectors.md:
      // 98% of the evaluation's noisy renders); this render shows only three of its markers.
      if (type == BoardType::kRoundHole && c.seed == 22) continue;
      SCOPED_TRACE(::testing::Message() << BoardTypeName(type) << " yaw " << c.yaw << " pitch "
                                        << c.pitch << " roll " << c.roll);
      const absl::StatusOr<CameraFrame> frame = circle_scene::RenderScene(
          circle_scene::OneBoard(
              type, circle_scene::EvaluationPose(far_m, c.yaw, c.pitch, c.roll, c.seed)),
          circle_scene::Effects(4.0, 1.0), c.seed, camera);
      ASSERT_TRUE(frame.ok()) << frame.status();
      const Detection d = DetectAruco(frame->image8.view(), board);
      ExpectAllMarkerCorners(d, board);
      int matched = 0;
      int unknown = 0;
      const double rms = FeatureRmsPx(d, *frame, &matched, &unknown);
      EXPECT_EQ(matched, 16);
      EXPECT_LE(rms, kNoisyRmsBarPx);
      std::printf("%s yaw %.0f pitch %.0f roll %.0f: RMS %.4f px\n", BoardTypeName(type), c.yaw,
                  c.pitch, c.roll, rms);
    }
  }
}

// The evaluation's hard renders (noise 6, blur 1.5, 4:1 gradient, gamma, JPEG 80) of the
// round-hole board at its smallest, 4 px cells, that it missed. Its black cells lie 2.6-3.4
// px beyond the markers; under blur 1.5 and gamma 1.6 that quiet zone keeps under half its
// contrast, so the halfway threshold joined markers to the cells and too few were read
// (MarkerDetectOptions::near_dark_fraction looks again nearer the dark level). The cells
// also pull edge-point corners by up to half a cell: a marker the board placed was refused
// before its page fit, and a turned board's markers, 5 px of border on average but 4 px
// across their short sides, were not page-fitted at all. Every board found, every corner
// within 40% of a cell.
TEST(ArucoDetectorTest, RoundHoleBoardAtItsSmallestUnderTheHardEffects) {
  const Board board = MakeBoard(BoardType::kRoundHole);
  const CameraModel camera = circle_scene::Camera();
  struct Case {
    double yaw, pitch, roll;
    int distance;  // in circle_scene::EvaluationDistances: 0 nearest, 2 smallest cells
    std::uint64_t seed;
  };
  const auto render = [&](const Case& c) {
    const double distance_m =
        circle_scene::EvaluationDistances(board, camera, false, c.yaw, c.pitch)[c.distance];
    absl::StatusOr<CameraFrame> frame = circle_scene::RenderScene(
        circle_scene::OneBoard(
            BoardType::kRoundHole,
            circle_scene::EvaluationPose(distance_m, c.yaw, c.pitch, c.roll, c.seed)),
        circle_scene::HardEffects(c.seed), c.seed, camera);
    EXPECT_TRUE(frame.ok()) << frame.status();
    return *std::move(frame);
  };
  // The last: turned 50 degrees at 3.56 m, where the pass nearer the dark level read a black
  // cell with the clutter behind its hole as another marker (id 17, one corrected bit) and
  // the board was refused for it; that pass now takes exact reads only.
  for (const Case& c :
       {Case{0, 0, -30, 2, 21}, Case{0, 0, 0, 2, 24}, Case{0, 0, -30, 2, 210},
        Case{0, 0, 30, 2, 216}, Case{50, 0, -30, 2, 237}, Case{0, 50, 30, 1, 3204}}) {
    SCOPED_TRACE(c.seed);
    const CameraFrame frame = render(c);
    const Detection d = DetectAruco(frame.image8.view(), board);
    ExpectAllMarkerCorners(d, board);
    EXPECT_LT(test_scene::MaxErrorPx(d, frame), 1.6);
  }
  // Without the pass nearer the dark level, only one marker of seed 24 is read.
  ArucoOptions halfway_only;
  halfway_only.markers.near_dark_fraction = 0.0;
  const Detection d = DetectAruco(render(Case{0, 0, 0, 2, 24}).image8.view(), board, halfway_only);
  EXPECT_FALSE(d.found);
  EXPECT_EQ(d.reason, DetectReason::kTooFewFeatures);
}

TEST(ArucoDetectorTest, CoarseLevelsGiveTheFullScansCorners) {
  const Board board = MakeBoard(BoardType::kAruco);
  const MarkerFamily family = Aruco4x4_50Family();
  std::uint64_t seed = 80;
  for (const double distance_m : {1.5, 2.2}) {
    BoardView view;
    view.params = board.params();
    view.distance_m = distance_m;
    view.yaw_deg = 25.0;
    view.roll_deg = 10.0;
    const CameraFrame frame = RenderView(view, CleanRender(), seed++);
    SCOPED_TRACE(::testing::Message() << "distance " << distance_m);
    const Detection coarse = DetectAruco(frame.image8.view(), board);
    const Detection full =
        VerifyMarkerBoard(ScanMarkers(frame.image8.view(), family, MarkerDetectOptions{}), board,
                          family, MarkerDetectOptions{}, frame.image8.view(), nullptr);
    ASSERT_TRUE(coarse.found) << DetectReasonName(coarse.reason);
    ASSERT_TRUE(full.found) << DetectReasonName(full.reason);
    ASSERT_EQ(coarse.features.size(), full.features.size());
    for (std::size_t i = 0; i < full.features.size(); ++i) {
      EXPECT_EQ(coarse.features[i].id, full.features[i].id);
      EXPECT_LE((coarse.features[i].uv_px - full.features[i].uv_px).norm(), 0.5 * kCleanRmsBarPx)
          << "corner " << i;
    }
    int matched = 0;
    int unknown = 0;
    EXPECT_LE(FeatureRmsPx(coarse, frame, &matched, &unknown), kCleanRmsBarPx);
    EXPECT_EQ(matched, 16);
  }
}

// A marker whose corners are a good part of a cell off the board is not reported: marker 19
// of a board of 5 px cells moved 3 px sideways in the image (0.6 of a cell). The board fit
// through all four markers takes up much of that: its largest residual is within 6% of a
// marker's side (0.36 of a cell), but not within a quarter of a cell.
TEST(ArucoDetectorTest, MarkerOffTheBoardByPartOfACellFailsVerification) {
  const Board board = MakeBoard(BoardType::kAruco);
  BoardView view;
  view.params = board.params();
  view.distance_m = 8.0;
  CameraFrame frame = RenderView(view, CleanRender(), 90);
  ASSERT_EQ(frame.features.size(), 16u);
  Eigen::AlignedBox2d box;
  for (int id = 12; id < 16; ++id) box.extend(frame.features.at(id).uv_px);
  const double cell_px = box.sizes().x() / kAruco4x4MarkerCells;
  ASSERT_NEAR(cell_px, 5.0, 0.2);
  // As rendered, the board is found.
  const Detection as_rendered = DetectAruco(frame.image8.view(), board);
  ASSERT_TRUE(as_rendered.found) << DetectReasonName(as_rendered.reason);
  int matched = 0;
  int unknown = 0;
  EXPECT_LE(FeatureRmsPx(as_rendered, frame, &matched, &unknown), kCleanRmsBarPx);
  constexpr int kShiftPx = 3;
  const int x0 = static_cast<int>(box.min().x()) - 3;
  const int x1 = static_cast<int>(box.max().x()) + 3;
  for (int y = static_cast<int>(box.min().y()) - 3; y <= static_cast<int>(box.max().y()) + 3; ++y) {
    for (int x = x1; x >= x0 + kShiftPx; --x)
      frame.image8.at(x, y) = frame.image8.at(x - kShiftPx, y);
  }
  const Detection d = DetectAruco(frame.image8.view(), board);
  EXPECT_FALSE(d.found);
  EXPECT_EQ(d.reason, DetectReason::kVerificationFailed);
  EXPECT_TRUE(d.features.empty());
  // The limit relative to the marker's side alone lets it through.
  ArucoOptions side_only;
  side_only.markers.max_residual_cells = 10.0;
  EXPECT_TRUE(DetectAruco(frame.image8.view(), board, side_only).found);
}

TEST(ArucoDetectorTest, PartialViewReportsOnlyTheVisibleMarkers) {
  const Board board = MakeBoard(BoardType::kAruco);
  BoardView view;
  view.params = board.params();
  view.distance_m = 1.6;
  view.offset_m = Eigen::Vector2d(0.0, 0.3);  // the top marker (id 4) is cut by the border
  const CameraFrame frame = RenderView(view, NoisyRender(), 5);
  const Detection d = DetectAruco(frame.image8.view(), board);
  EXPECT_FALSE(d.found);
  EXPECT_EQ(d.reason, DetectReason::kPartial);
  ASSERT_EQ(d.features.size(), 12u);
  for (int i = 0; i < 12; ++i) EXPECT_EQ(d.features[i].id, 4 + i);  // markers 11, 12, 19
  int matched = 0;
  int unknown = 0;
  EXPECT_LE(FeatureRmsPx(d, frame, &matched, &unknown), kNoisyRmsBarPx);
  EXPECT_EQ(matched, 12);
  EXPECT_EQ(unknown, 0);
}

// Two round-hole boards share their marker ids (the station's five do). The scene of issue 20:
// the front camera's view of bumper_lidar_right held one marker of the next round-hole board
// in its margin, and the board was refused as ambiguous in 4 of 62 frames. Here the board
// stands left of centre and a second one right of the image's edge, its left marker in view:
// the board is found, every corner at its own print. Both boards whole in view cannot be told
// apart: ambiguous, no features.
TEST(ArucoDetectorTest, AMarkerOfAnotherBoardWithTheSameIdsDoesNotHideTheBoard) {
  const Board board = MakeBoard(BoardType::kRoundHole);
  // Two boards 3 m ahead, their centres `left` and `right` m right of the optical axis.
  const auto render = [&board](double left, double right, std::uint64_t seed) {
    BoardView view;
    view.params = board.params();
    view.distance_m = 3.0;
    view.offset_m = Eigen::Vector2d(left, 0.0);
    StationLayout layout = test_scene::SceneOf(view);
    view.offset_m = Eigen::Vector2d(right, 0.0);
    layout.boards.push_back(test_scene::SceneOf(view).boards[0]);
    layout.boards[1].id = "neighbour";
    absl::StatusOr<CameraFrame> frame = RenderCameraFrame(
        test_scene::TestCamera(), test_scene::TestCameraPose(), layout, NoisyRender(), seed);
    EXPECT_TRUE(frame.ok()) << frame.status();
    return frame.ok() ? *std::move(frame) : CameraFrame();
  };
  // The image spans +-1.92 m at 3 m: the neighbour's left marker (board x -0.4..-0.2 m) at
  // 1.65..1.85 m, its top, bottom and right markers beyond the edge.
  const CameraFrame frame = render(-0.5, 2.05, 21);
  int neighbour_corners_in_view = 0;
  for (const RenderedFeature& t : frame.features) {
    neighbour_corners_in_view += t.board_id == "neighbour" && t.kind == FeatureKind::kMarkerCorner;
  }
  EXPECT_GE(neighbour_corners_in_view, 4);  // the scene has a duplicate id to resolve
  const Detection d = DetectAruco(frame.image8.view(), board);
  ExpectAllMarkerCorners(d, board);
  double worst = 0;
  for (const DetectedFeature& f : d.features) {
    for (const RenderedFeature& t : frame.features) {
      if (t.board_id == "board" && t.feature_id == f.id)
        worst = std::max(worst, (f.uv_px - t.uv_px).norm());
    }
  }
  EXPECT_LT(worst, 0.5);  // the board's own corners, not the neighbour's 2.5 m away

  const Detection two = DetectAruco(render(-0.9, 0.9, 22).image8.view(), board);
  EXPECT_FALSE(two.found);
  EXPECT_EQ(two.reason, DetectReason::kAmbiguous);
  EXPECT_TRUE(two.features.empty());
}

TEST(ArucoDetectorTest, FindsNothingOnOtherBoards) {
  const Board board = MakeBoard(BoardType::kAruco);
  for (BoardType other : {BoardType::kChessboard, BoardType::kCircle, BoardType::kVertical,
                          BoardType::kApriltag, BoardType::kChecker}) {
    BoardView view;
    view.params = Params(other);
    view.distance_m = other == BoardType::kChecker ? 0.5 : 2.5;
    const CameraFrame frame = RenderView(view, NoisyRender(), 6);
    const Detection d = DetectAruco(frame.image8.view(), board);
    EXPECT_FALSE(d.found) << BoardTypeName(other);
    EXPECT_TRUE(d.features.empty()) << BoardTypeName(other);
  }
}

TEST(ArucoDetectorTest, FindsNothingOnABoardFreeClutteredScene) {
  StationLayout layout;
  layout.name = "walls";
  StationSurface wall;
  wall.id = "wall";
  // A wall 6 m ahead, facing the camera (its z axis towards -x), 8 x 4 m.
  Eigen::Matrix3d r;
  r.col(0) = -Eigen::Vector3d::UnitY();
  r.col(1) = Eigen::Vector3d::UnitZ();
  r.col(2) = -Eigen::Vector3d::UnitX();
  wall.T_station_surface = Rigid3d(Eigen::Quaterniond(r), Eigen::Vector3d(6.0, 0.0, 1.5));
  wall.size_m = Eigen::Vector2d(8.0, 4.0);
  wall.reflectivity = 0.6;
  layout.surfaces.push_back(wall);
  CameraRenderOptions o = NoisyRender();
  o.clutter = true;
  o.clutter_density = 1.0;
  const absl::StatusOr<CameraFrame> frame =
      RenderCameraFrame(test_scene::TestCamera(), test_scene::TestCameraPose(), layout, o, 7);
  ASSERT_TRUE(frame.ok()) << frame.status();
  for (BoardType type : {BoardType::kAruco, BoardType::kRoundHole}) {
    const Detection d = DetectAruco(frame->image8.view(), MakeBoard(type));
    EXPECT_FALSE(d.found);
    EXPECT_TRUE(d.features.empty());
  }
}

// Draws DICT_4X4_50 marker `id` upright with its top-left at (x0, y0), cells of `cell` px.
void DrawMarker(Image8* img, int id, int x0, int y0, int cell) {
  for (int r = 0; r < kAruco4x4MarkerCells; ++r) {
    for (int c = 0; c < kAruco4x4MarkerCells; ++c) {
      const bool border =
          r == 0 || c == 0 || r == kAruco4x4MarkerCells - 1 || c == kAruco4x4MarkerCells - 1;
      const bool white = !border && Aruco4x4CellIsWhite(kAruco4x4_50Codes[id], r - 1, c - 1);
      for (int y = 0; y < cell; ++y) {
        for (int x = 0; x < cell; ++x) {
          img->at(x0 + c * cell + x, y0 + r * cell + y) = white ? 220 : 20;
        }
      }
    }
  }
}

TEST(ArucoDetectorTest, MarkersOfOtherIdsAreTheWrongBoard) {
  const Board board = MakeBoard(BoardType::kAruco);
  Image8 img(640, 480, 220);
  DrawMarker(&img, 0, 60, 60, 12);
  DrawMarker(&img, 1, 300, 60, 12);
  DrawMarker(&img, 2, 60, 300, 12);
  DrawMarker(&img, 3, 300, 300, 12);
  Detection d = DetectAruco(img.view(), board);
  EXPECT_FALSE(d.found);
  EXPECT_EQ(d.reason, DetectReason::kWrongBoard);
  EXPECT_TRUE(d.features.empty());

  // One marker of the board among others: too few to identify, and still not this board.
  DrawMarker(&img, 4, 60, 60, 12);
  d = DetectAruco(img.view(), board);
  EXPECT_FALSE(d.found);
  EXPECT_EQ(d.reason, DetectReason::kWrongBoard);
  EXPECT_TRUE(d.features.empty());

  // A lone marker of the board: too few features, none reported.
  Image8 lone(320, 240, 220);
  DrawMarker(&lone, 11, 100, 60, 12);
  d = DetectAruco(lone.view(), board);
  EXPECT_FALSE(d.found);
  EXPECT_EQ(d.reason, DetectReason::kTooFewFeatures);
  EXPECT_TRUE(d.features.empty());
}

TEST(ArucoDetectorTest, BadInputGivesAReasonAndNoFeatures) {
  const Board board = MakeBoard(BoardType::kAruco);
  const std::vector<std::uint8_t> pixels(64 * 64, 128);
  auto expect_reason = [&](const ImageView8& view, DetectReason reason, const char* what) {
    const Detection d = DetectAruco(view, board);
    EXPECT_FALSE(d.found) << what;
    EXPECT_EQ(d.reason, reason) << what << ": " << DetectReasonName(d.reason);
    EXPECT_TRUE(d.features.empty()) << what;
  };
  expect_reason(ImageView8{}, DetectReason::kBadImage, "empty");
  expect_reason(ImageView8{nullptr, 64, 64, 64}, DetectReason::kBadImage, "null data");
  expect_reason(ImageView8{pixels.data(), 1, 1, 1}, DetectReason::kBadImage, "1x1");
  expect_reason(ImageView8{pixels.data(), 64, 64, 32}, DetectReason::kBadImage, "short stride");
  expect_reason(ImageView8{pixels.data(), kMaxImageSide + 1, 1, kMaxImageSide + 1},
                DetectReason::kBadImage, "huge");
  const Image8 black(320, 240, 0);
  expect_reason(black.view(), DetectReason::kLowContrast, "all black");
  const Image8 white(320, 240, 255);
  expect_reason(white.view(), DetectReason::kLowContrast, "all white");
  Image8 noise(320, 240);
  std::mt19937 rng(42);
  for (std::uint8_t& p : noise.pixels) p = static_cast<std::uint8_t>(rng() & 0xff);
  const Detection d = DetectAruco(noise.view(), board);
  EXPECT_FALSE(d.found);
  EXPECT_TRUE(d.features.empty());

  ArucoOptions bad;
  bad.markers.max_residual_fraction = 0.0;
  EXPECT_EQ(bad.Validate(), "max_residual_fraction");
  bad.markers.max_residual_fraction = 0.06;
  bad.markers.max_residual_cells = 0.0;
  EXPECT_EQ(bad.Validate(), "max_residual_cells");
  EXPECT_EQ(DetectAruco(black.view(), board, bad).reason, DetectReason::kBadImage);
  EXPECT_EQ(DetectAruco(black.view(), MakeBoard(BoardType::kChessboard)).reason,
            DetectReason::kWrongBoard);
}

}  // namespace
}  // namespace linecal

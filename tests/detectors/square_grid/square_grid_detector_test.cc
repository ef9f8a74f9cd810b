// The square grid detector on golden renders (station/sim/camera_render.h, exact ground
// truth): BoofCV's grid of black squares found with exact ids and sub-pixel corners over
// poses, noise, blur and lighting and through strongly distorting and fisheye lenses; the
// upright rule; nothing found on other boards, on a larger grid or without a board; and the
// reasons for bad input.
#include "detectors/square_grid/square_grid_detector.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <vector>

#include "detectors/detect.h"
#include "tests/detectors/board_scene.h"
#include "tests/detectors/circle/circle_scene.h"
#include "tests/support/reference_cameras.h"

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

// cols x rows squares of 30 mm, gap_m apart (BoofCV's corpus board: 3 x 4, gaps of 30 mm).
BoardParams Grid(int cols = 5, int rows = 4, double gap_m = 0.02) {
  BoardParams p;
  p.type = BoardType::kSquareGrid;
  p.cols = cols;
  p.rows = rows;
  p.square_m = 0.03;
  p.gap_m = gap_m;
  return p;
}

CameraFrame RenderThrough(const CameraModel& camera, const BoardView& view,
                          const CameraRenderOptions& options, std::uint64_t seed) {
  absl::StatusOr<CameraFrame> frame = RenderCameraFrame(camera, test_scene::TestCameraPose(),
                                                        test_scene::SceneOf(view), options, seed);
  EXPECT_TRUE(frame.ok()) << frame.status();
  return frame.ok() ? *std::move(frame) : CameraFrame();
}

// The whole board with exact ids (a wrong id is off by a side, tens of pixels), its RMS error
// against the truth in *rms_px.
void ExpectFound(const CameraFrame& frame, const BoardParams& params, double* rms_px) {
  const Board board = *Board::Create(params);
  const Detection d = DetectSquareGrid(frame.image8.view(), board);
  ExpectComplete(d, board);
  int matched = 0, unknown = 0;
  *rms_px = FeatureRmsPx(d, frame, &matched, &unknown);
  EXPECT_EQ(matched, static_cast<int>(board.features().size()));
  EXPECT_EQ(unknown, 0);
  EXPECT_LT(test_scene::MaxErrorPx(d, frame), 1.0);
}

// ---- Found, with sub-pixel corners ------------------------------------------------------

TEST(SquareGridDetectorTest, FrontalGridHasExactIdsAndSubPixelCorners) {
  BoardView view;
  view.params = Grid();
  view.distance_m = 0.7;  // squares of 43 px
  const CameraFrame frame = RenderView(view, CleanRender(), 1);
  double rms = 0.0;
  ExpectFound(frame, view.params, &rms);
  EXPECT_LT(rms, kCleanRmsBarPx);
  // Id 0 is the top-left corner of the top-left square, id 9 ends the top row of corners,
  // id 79 is the bottom-right corner of the bottom-right square.
  const Detection d = DetectSquareGrid(frame.image8.view(), *Board::Create(view.params));
  ASSERT_TRUE(d.found);
  EXPECT_LT(d.features[0].uv_px.x(), d.features[9].uv_px.x());
  EXPECT_LT(d.features[0].uv_px.y(), d.features[79].uv_px.y());
  EXPECT_EQ(d.features[1].p_board.x() - d.features[0].p_board.x(), 0.03);
}

// A grid of views (roll, yaw and pitch at the extremes of docs/acceptance.md, two sizes), each
// rendered clean and noisy (sigma 4, blur 1.0, a 3:1 lighting gradient, gamma 1.4), as the
// checker and circle grid tests: every one found, RMS within the bars.
TEST(SquareGridDetectorTest, PoseGridWithNoiseBlurAndLighting) {
  const BoardParams params = Grid();
  double sum_sq[2] = {0.0, 0.0};
  int n[2] = {0, 0};
  int index = 0;
  std::uint64_t seed = 100;
  for (double roll : {-30.0, 30.0}) {
    for (double yaw : {-50.0, 0.0, 50.0}) {
      for (double pitch : {-40.0, 40.0}) {
        // Squares of 50 and 30 px face-on.
        const double distance = index++ % 2 == 0 ? 0.6 : 1.0;
        for (const int noisy : {0, 1}) {
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
          SCOPED_TRACE(testing::Message()
                       << "roll " << roll << " yaw " << yaw << " pitch " << view.pitch_deg
                       << " distance " << distance << " noisy " << noisy);
          double rms = 0.0;
          ExpectFound(RenderView(view, options, ++seed), params, &rms);
          sum_sq[noisy] += rms * rms;
          ++n[noisy];
        }
      }
    }
  }
  const double rms_clean = std::sqrt(sum_sq[0] / n[0]);
  const double rms_noisy = std::sqrt(sum_sq[1] / n[1]);
  std::printf("square grid pose grid: RMS clean %.4f px, noisy %.4f px\n", rms_clean, rms_noisy);
  EXPECT_LT(rms_clean, kCleanRmsBarPx);
  EXPECT_LT(rms_noisy, kNoisyRmsBarPx);
}

// The default 9 x 6 board pitched 50 degrees, squares of about 20 px face-on, clean and
// under blur 1.0 with gamma 1.4: squares whose contour gives Douglas-Peucker a fifth vertex on
// a side, or whose corners blur and the gamma round into chamfers (QuadOptions::
// max_polygon_vertices). The full render grid lost such views (docs/detectors.md).
TEST(SquareGridDetectorTest, PitchedGridWithRoundedCorners) {
  BoardParams params;
  params.type = BoardType::kSquareGrid;
  std::uint64_t seed = 300;
  for (double pitch : {-50.0, 50.0}) {
    for (double roll : {-30.0, 30.0}) {
      for (const int soft : {0, 1}) {
        BoardView view;
        view.params = params;
        view.distance_m = 1.3;
        view.pitch_deg = pitch;
        view.roll_deg = roll;
        CameraRenderOptions options = CleanRender();
        if (soft) {
          options.blur_sigma_px = 1.0;
          options.gamma = 1.4;
        }
        SCOPED_TRACE(testing::Message()
                     << "pitch " << pitch << " roll " << roll << " soft " << soft);
        double rms = 0.0;
        ExpectFound(RenderView(view, options, ++seed), params, &rms);
        EXPECT_LT(rms, kNoisyRmsBarPx);
      }
    }
  }
}

// One of detectors_eval's full-grid renders of the default 9 x 6 square grid under its hard
// effects (noise 6, blur 1.5, a 4:1 gradient, gamma 0.6 or 1.6, JPEG 80, clutter): its seed,
// turn in degrees and distance (an index into circle_scene::EvaluationDistances: near,
// middle, far).
struct HardCase {
  std::uint64_t seed;
  double roll, yaw, pitch;
  int distance;
};

// Renders `c` as detectors_eval does and expects the grid found whole with exact ids, the
// corners' RMS error under rms_bound_px and every corner under max_bound_px from the truth.
void ExpectFoundUnderHardEffects(const HardCase& c, double rms_bound_px, double max_bound_px) {
  SCOPED_TRACE(testing::Message() << "seed " << c.seed);
  BoardParams params;
  params.type = BoardType::kSquareGrid;
  const Board board = *Board::Create(params);
  const CameraModel camera = circle_scene::Camera();
  const double distance_m =
      circle_scene::EvaluationDistances(board, camera, false, c.yaw, c.pitch).at(c.distance);
  const absl::StatusOr<CameraFrame> frame = circle_scene::RenderScene(
      circle_scene::OneBoard(
          BoardType::kSquareGrid,
          circle_scene::EvaluationPose(distance_m, c.yaw, c.pitch, c.roll, c.seed)),
      circle_scene::HardEffects(c.seed), c.seed, camera);
  ASSERT_TRUE(frame.ok()) << frame.status();
  ASSERT_EQ(frame->features.size(), board.features().size()) << "the whole grid in view";
  const Detection d = DetectSquareGrid(frame->image8.view(), board);
  ExpectComplete(d, board);
  int matched = 0, unknown = 0;
  const double rms = FeatureRmsPx(d, *frame, &matched, &unknown);
  EXPECT_EQ(matched, static_cast<int>(board.features().size()));
  EXPECT_EQ(unknown, 0);
  const double worst = test_scene::MaxErrorPx(d, *frame);
  std::printf("seed %llu at %.2f m: RMS %.4f px, worst %.3f px\n",
              static_cast<unsigned long long>(c.seed), distance_m, rms, worst);
  EXPECT_LT(rms, rms_bound_px);
  EXPECT_LT(worst, max_bound_px);
}

// Renders of detectors_eval's full grid (1280 x 720, the default 9 x 6 board, docs/
// detectors.md) under its hard effects (noise 6, blur 1.5, a 4:1 gradient, gamma 0.6 or 1.6,
// JPEG 80, clutter) that the detector missed: a gamma after the blur dilated every square by
// about a pixel, which moved each gap against its 15 px squares by as much as the geometry's
// tolerance (seed 102); the squares' short sides rounded into arcs gave no quad (seeds 105,
// 123); the dim end of the gradient left gaps under half the median contrast (seed 168).
TEST(SquareGridDetectorTest, EvaluationMissesUnderTheHardEffects) {
  // docs/acceptance.md sets no RMS bar under the hard effects; these views measure 0.21-0.30
  // px (corners of 12-20 px squares), every corner within a pixel.
  // Seeds 21, 24 and 27: face-on at the far distance (squares of 12 px), every corner rounded
  // with a radius of a quarter side, so that the quad inscribed in the contour holds under
  // 0.85 of it; the lines of the sides' straight middles give the quad (contours.cc).
  for (const HardCase& c :
       {HardCase{102, -30, 0, 50, 2}, HardCase{105, 0, 0, 50, 2}, HardCase{123, 0, 0, -50, 1},
        HardCase{168, 0, -35, -35, 0}, HardCase{21, -30, 0, 0, 2}, HardCase{24, 0, 0, 0, 2},
        HardCase{27, 30, 0, 0, 2}}) {
    ExpectFoundUnderHardEffects(c, 0.35, 1.0);
  }
}

// The last four misses of detectors_eval's full grid (docs/detectors.md, "The four sheared
// misses"), at its far distance for the turn: 13-15 px squares sheared by yaw -50 degrees and
// roll -30 or 30 (seeds 75, 81), pitch -50 and roll 30 (135), yaw and pitch 35 (159), under
// the hard effects. The side fits make such squares more sheared than they are and their
// angles are noisy, which moves the gap geometry's residuals across their lines (0.8-1 px on
// average): 1-3 lines per render were over their tolerances of 2.6-3.0 px by that component
// (2.7-3.6 px), none by the component along the line, which the geometry now holds alone
// (LocallyConsistent). Found whole with exact ids; the corners carry that noise: RMS
// 0.39-0.47 px, the worst 1.2-2.0 px (the hard set has no accuracy bar), so the bounds are
// 0.55 px RMS and 2.5 px, a fifth of the smallest side seen; a wrong id is off by a side.
TEST(SquareGridDetectorTest, ShearedSmallSquaresUnderTheHardEffects) {
  for (const HardCase& c : {HardCase{75, -30, -50, 0, 2}, HardCase{81, 30, -50, 0, 2},
                            HardCase{135, 30, 0, -50, 2}, HardCase{159, 0, 35, 35, 2}}) {
    ExpectFoundUnderHardEffects(c, 0.55, 2.5);
  }
}

// The two misses of the run of every board (seeds from 1351; docs/detectors.md, "The two
// misses of the run of every board"), under the hard effects. Seed 1482, pitch -50 degrees at
// the far distance (1.28 m, 18-20 px squares): a dark clutter diamond above the board, its
// quad far from any square's image, carried its homography half a gap out onto the gap
// centre of a top-row square and took that square's link and grid point (the window was
// 81 px off along a line); a link now needs both squares to see the gap alike. Seed 1395,
// yaw 50 and roll 30 degrees at the middle distance (0.85 m, 31-34 px squares): a dark disc
// just off the page, linked beyond the window in its gap geometry, was taken for the grid
// going on (wrong_board); a square beyond now continues the grid only with sides as straight
// as the window's. Found whole with exact ids, RMS 0.25 and 0.18 px, the worst corners 0.58
// and 0.42 px (measured); bounds 0.35 px and 1 px, a wrong id being off by a side (18 px).
TEST(SquareGridDetectorTest, EveryBoardRunMisses) {
  for (const HardCase& c : {HardCase{1482, 0, 0, -50, 2}, HardCase{1395, 30, 50, 0, 1}}) {
    ExpectFoundUnderHardEffects(c, 0.35, 1.0);
  }
}

// Through the strong wide-angle pinhole (k1 -0.30) near the image corner and the 190-degree
// fisheye 40 degrees off its axis, BoofCV's 3 x 4 board with equal squares and gaps.
TEST(SquareGridDetectorTest, StrongDistortionAndFisheye) {
  // A side's edge bends a little over a square; the corners, where lines fitted to the
  // edges meet, carry that bend's fraction of a pixel.
  constexpr double kLensRmsBarPx = 0.15;
  struct Case {
    const char* name;
    CameraModel camera;
    BoardView view;
  };
  std::vector<Case> cases;
  BoardView v;
  v.params = Grid(3, 4, 0.03);
  v.distance_m = 0.5;
  v.offset_m = Eigen::Vector2d(0.32, 0.12);  // towards the image's top-right corner
  v.yaw_deg = -25.0;
  cases.push_back({"strong pinhole", *CameraModel::Create(reference_cameras::StrongPinhole()), v});
  v.distance_m = 0.3;
  v.offset_m = Eigen::Vector2d(0.25, 0.0);  // 40 degrees off the axis
  v.yaw_deg = -30.0;
  cases.push_back({"fisheye", *CameraModel::Create(reference_cameras::Fisheye190()), v});
  std::uint64_t seed = 50;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const CameraFrame frame = RenderThrough(c.camera, c.view, CleanRender(), ++seed);
    double rms = 0.0;
    ExpectFound(frame, c.view.params, &rms);
    std::printf("%s: RMS %.4f px\n", c.name, rms);
    EXPECT_LT(rms, kLensRmsBarPx);
  }
}

// ---- Orientation ------------------------------------------------------------------------

TEST(SquareGridDetectorTest, GridIsReportedUpright) {
  // Turned upside down the grid is the same board: id 0 stays at the image's top-left.
  // Square, turned by a quarter, likewise.
  for (const auto& [params, roll] :
       {std::pair{Grid(), 180.0}, std::pair{Grid(), 170.0}, std::pair{Grid(4, 4), 90.0}}) {
    SCOPED_TRACE(roll);
    BoardView view;
    view.params = params;
    view.distance_m = 0.7;
    view.roll_deg = roll;
    const CameraFrame frame = RenderView(view, CleanRender(), 9);
    const Detection d = DetectSquareGrid(frame.image8.view(), *Board::Create(params));
    ASSERT_TRUE(d.found) << DetectReasonName(d.reason);
    const int last = 4 * params.cols * params.rows - 1;
    EXPECT_LT(d.features[0].uv_px.x(), d.features[2 * params.cols - 1].uv_px.x());
    EXPECT_LT(d.features[0].uv_px.y(), d.features[last].uv_px.y());
  }
}

// ---- Nothing found where the board is not -------------------------------------------------

TEST(SquareGridDetectorTest, LargerGridIsTheWrongBoard) {
  BoardView view;
  view.params = Grid(7, 5);
  view.distance_m = 0.8;
  const CameraFrame frame = RenderView(view, CleanRender(), 13);
  const Detection d = DetectSquareGrid(frame.image8.view(), *Board::Create(Grid()));
  EXPECT_FALSE(d.found);
  EXPECT_EQ(d.reason, DetectReason::kWrongBoard);
  // Nor is a grid of other gaps the board: its neighbours are not where the gaps put them.
  const Detection other_gap = DetectSquareGrid(RenderView(view, CleanRender(), 14).image8.view(),
                                               *Board::Create(Grid(7, 5, 0.045)));
  EXPECT_FALSE(other_gap.found);
}

TEST(SquareGridDetectorTest, NothingOnOtherBoardsOrEmptyScenes) {
  // The checker's black squares form a square grid with gaps of one square, but for the
  // black squares at its crossings.
  const Board board = *Board::Create(Grid(3, 3, 0.03));
  const Board default_board = *Board::Create(Grid(5, 4));
  std::vector<BoardView> views;
  BoardView v;
  for (BoardType type :
       {BoardType::kChessboard, BoardType::kCircle, BoardType::kVertical, BoardType::kAruco,
        BoardType::kApriltag, BoardType::kRoundHole, BoardType::kChecker, BoardType::kCircleGrid}) {
    v.params = BoardParams();
    v.params.type = type;
    v.distance_m = type == BoardType::kChecker || type == BoardType::kCircleGrid ? 0.8
                   : type == BoardType::kChessboard                              ? 4.0
                                                                                 : 3.0;
    views.push_back(v);
  }
  v.params = Grid();
  v.distance_m = 0.6;
  v.yaw_deg = 180.0;  // the board's unprinted back
  views.push_back(v);
  std::uint64_t seed = 300;
  for (const BoardView& view : views) {
    CameraRenderOptions options = NoisyRender();
    options.clutter = true;
    const CameraFrame frame = RenderView(view, options, ++seed);
    for (const Board* b : {&board, &default_board}) {
      const Detection d = DetectSquareGrid(frame.image8.view(), *b);
      EXPECT_FALSE(d.found) << BoardTypeName(view.params.type);
      EXPECT_TRUE(d.features.empty());
      EXPECT_NE(d.reason, DetectReason::kNone);
    }
  }
}

TEST(SquareGridDetectorTest, TwoGridsAreAmbiguous) {
  StationLayout layout;
  for (const double right : {-0.15, 0.15}) {
    BoardView view;
    view.params = Grid(3, 2);
    view.distance_m = 0.8;
    view.offset_m = Eigen::Vector2d(right, 0.0);
    StationBoard b = test_scene::SceneOf(view).boards.at(0);
    b.id = right < 0 ? "left" : "right";
    layout.boards.push_back(b);
  }
  const absl::StatusOr<CameraFrame> frame = RenderCameraFrame(
      test_scene::TestCamera(), test_scene::TestCameraPose(), layout, CleanRender(), 16);
  ASSERT_TRUE(frame.ok());
  const Detection d = DetectSquareGrid(frame->image8.view(), *Board::Create(Grid(3, 2)));
  EXPECT_FALSE(d.found);
  EXPECT_EQ(d.reason, DetectReason::kAmbiguous);
}

TEST(SquareGridDetectorTest, ReasonsForBadInput) {
  const Board board = *Board::Create(Grid());
  EXPECT_EQ(DetectSquareGrid(ImageView8{}, board).reason, DetectReason::kBadImage);
  const Image8 flat(640, 480, 128);
  EXPECT_EQ(DetectSquareGrid(flat.view(), board).reason, DetectReason::kLowContrast);
  SquareGridOptions bad;
  bad.max_link_side_fraction = 0.0;
  EXPECT_EQ(bad.Validate(), "max_link_side_fraction");
  EXPECT_EQ(DetectSquareGrid(flat.view(), board, bad).reason, DetectReason::kBadImage);
  BoardParams checker;
  checker.type = BoardType::kChecker;
  EXPECT_EQ(DetectSquareGrid(flat.view(), *Board::Create(checker)).reason,
            DetectReason::kWrongBoard);
  // The dispatcher picks this detector for the board type.
  BoardView view;
  view.params = Grid();
  view.distance_m = 0.7;
  const CameraFrame frame = RenderView(view, CleanRender(), 3);
  const std::optional<Detection> d = DetectBoard(frame.image8.view(), board);
  ASSERT_TRUE(d.has_value());
  EXPECT_TRUE(d->found);
}

}  // namespace
}  // namespace linecal

// OpenCV's ChArUco board (docs/boards.md) and its detector on golden renders
// (station/sim/camera_render.h, exact ground truth): the layout, ids and errors of the board;
// every corner found with its id and sub-pixel over a grid of poses, through a strongly
// distorting and a fisheye lens; partial views with the seen corners and no wrong id; nothing
// on other boards or without a board; the reasons for bad input.
#include "detectors/charuco/charuco_detector.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <vector>

#include "detectors/common/image_filters.h"
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
using test_scene::MaxErrorPx;
using test_scene::NoisyRender;
using test_scene::RenderView;

// A 7 x 5 board of 40 mm squares and 30 mm markers (cells of 5 mm): at 1 m in front of the test
// camera (f 1000 px) squares of 40 px and marker cells of 5 px.
BoardParams Charuco(int cols = 7, int rows = 5, bool legacy = false) {
  BoardParams p;
  p.type = BoardType::kCharuco;
  p.cols = cols;
  p.rows = rows;
  p.square_m = 0.04;
  p.marker_m = 0.03;
  p.charuco_legacy = legacy;
  return p;
}

// ---- The board ----------------------------------------------------------------------------

TEST(CharucoBoardTest, CornerIdsAreRowMajorFromTheTopLeft) {
  const Board board = *Board::Create(Charuco(5, 4));
  EXPECT_STREQ(board.name(), "charuco");
  EXPECT_EQ(BoardTypeFromName("charuco"), BoardType::kCharuco);
  ASSERT_EQ(board.features().size(), 12u);  // (5 - 1) x (4 - 1)
  // The squares span x in [-0.1, 0.1] and y in [-0.08, 0.08]; one square of margin around.
  EXPECT_NEAR(board.page_size_m().x(), 0.28, 1e-12);
  EXPECT_NEAR(board.page_size_m().y(), 0.24, 1e-12);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) {
      const BoardFeature& f = board.features()[4 * r + c];
      EXPECT_EQ(f.id, 4 * r + c);
      EXPECT_EQ(f.kind, FeatureKind::kXCorner);
      EXPECT_EQ(f.marker, -1);
      EXPECT_NEAR(f.p_board.x(), -0.06 + 0.04 * c, 1e-12);
      EXPECT_NEAR(f.p_board.y(), 0.04 - 0.04 * r, 1e-12);
    }
  }
}

// The centre of square (row, col) and a point in its white margin near its top-left corner.
Eigen::Vector2d SquareCentre(const BoardParams& p, int row, int col) {
  return {-0.5 * p.cols * p.square_m + (col + 0.5) * p.square_m,
          0.5 * p.rows * p.square_m - (row + 0.5) * p.square_m};
}
Eigen::Vector2d MarginPoint(const BoardParams& p, int row, int col) {
  const double inset = 0.25 * (p.square_m - p.marker_m);
  return SquareCentre(p, row, col) +
         Eigen::Vector2d(-0.5 * p.square_m + inset, 0.5 * p.square_m - inset);
}

TEST(CharucoBoardTest, TopLeftSquareIsBlackUnlessTheLegacyPatternHasEvenRows) {
  for (const auto& [rows, legacy, top_left_white] :
       {std::tuple{4, false, false}, std::tuple{4, true, true}, std::tuple{5, false, false},
        std::tuple{5, true, false}}) {
    SCOPED_TRACE(testing::Message() << rows << " rows, legacy " << legacy);
    const BoardParams p = Charuco(5, rows, legacy);
    const Board board = *Board::Create(p);
    EXPECT_EQ(CharucoSquareHasMarker(p, 0, 0), top_left_white);
    EXPECT_EQ(board.PaintAt(MarginPoint(p, 0, 0)), top_left_white ? Paint::kWhite : Paint::kBlack);
    EXPECT_EQ(board.PaintAt(MarginPoint(p, 0, 1)), top_left_white ? Paint::kBlack : Paint::kWhite);
    // Every marker has the one-cell black border: the point a half cell inside its top-left.
    const double cell = p.marker_m / 6.0;
    const Eigen::Vector2d border =
        SquareCentre(p, 0, top_left_white ? 0 : 1) +
        Eigen::Vector2d(-0.5 * p.marker_m + 0.5 * cell, 0.5 * p.marker_m - 0.5 * cell);
    EXPECT_EQ(board.PaintAt(border), Paint::kBlack);
    EXPECT_EQ(CharucoMarkerCount(p), 5 * rows / 2);
  }
}

// Marker 0's data cells are those of DICT_4X4_50 id 0 (0xB532: first data row 1011), so the
// first data cell of the first marker square is white and the second black.
TEST(CharucoBoardTest, MarkersCarryTheirIdsInRowMajorOrder) {
  const BoardParams p = Charuco(5, 5);
  const Board board = *Board::Create(p);
  const double cell = p.marker_m / 6.0;
  const auto data_cell = [&](int row, int col, int dr, int dc) -> Eigen::Vector2d {
    return SquareCentre(p, row, col) + Eigen::Vector2d(-0.5 * p.marker_m + (1.5 + dc) * cell,
                                                       0.5 * p.marker_m - (1.5 + dr) * cell);
  };
  // id 0 in square (0, 1): 0xB532 = 1011 0101 0011 0010.
  EXPECT_EQ(board.PaintAt(data_cell(0, 1, 0, 0)), Paint::kWhite);
  EXPECT_EQ(board.PaintAt(data_cell(0, 1, 0, 1)), Paint::kBlack);
  EXPECT_EQ(board.PaintAt(data_cell(0, 1, 3, 3)), Paint::kBlack);
  // id 2 in square (1, 0): 0x332D = 0011 0011 0010 1101.
  EXPECT_EQ(board.PaintAt(data_cell(1, 0, 0, 0)), Paint::kBlack);
  EXPECT_EQ(board.PaintAt(data_cell(1, 0, 0, 2)), Paint::kWhite);
  EXPECT_EQ(board.PaintAt(data_cell(1, 0, 3, 3)), Paint::kWhite);
}

// A board of any of OpenCV's dictionaries prints its markers' cells: every data cell of the
// first two markers (ids 0 and 1, squares (0, 1) and (0, 3)) as the dictionary's code says, and
// the one-cell border black.
TEST(CharucoBoardTest, MarkersOfEveryDictionaryCarryTheirCodes) {
  for (const ArucoDictionaryInfo& info : AllArucoDictionaries()) {
    SCOPED_TRACE(info.name);
    BoardParams p = Charuco(5, 5);
    p.charuco_dictionary = info.dictionary;
    const Board board = *Board::Create(p);
    const int n = info.data_bits;
    const double cell = p.marker_m / info.marker_cells();
    int wrong = 0;
    for (const auto& [id, col] : {std::pair{0, 1}, std::pair{1, 3}}) {
      const Eigen::Vector2d top_left =
          SquareCentre(p, 0, col) + Eigen::Vector2d(-0.5 * p.marker_m, 0.5 * p.marker_m);
      for (int r = -1; r <= n; ++r) {
        for (int c = -1; c <= n; ++c) {
          const bool border = r < 0 || c < 0 || r == n || c == n;
          const bool white = !border && ArucoCellIsWhite(info.codes[id], n, r, c);
          const Eigen::Vector2d centre = top_left + cell * Eigen::Vector2d(c + 1.5, -(r + 1.5));
          wrong += board.PaintAt(centre) != (white ? Paint::kWhite : Paint::kBlack);
        }
      }
    }
    EXPECT_EQ(wrong, 0);
  }
}

TEST(CharucoBoardTest, BadParamsAreRefusedWithTheirReason) {
  BoardParams p = Charuco();
  p.marker_m = p.square_m;
  BoardParamsError e = BoardParamsError::kOk;
  EXPECT_FALSE(Board::Create(p, &e).has_value());
  EXPECT_EQ(e, BoardParamsError::kBadMarker);
  EXPECT_STREQ(BoardParamsErrorName(e), "bad_marker");
  p.marker_m = std::nan("");
  EXPECT_EQ(ValidateBoardParams(p), BoardParamsError::kBadMarker);
  p.marker_m = 0.0;
  EXPECT_EQ(ValidateBoardParams(p), BoardParamsError::kBadMarker);
  p = Charuco(11, 10);  // 55 markers
  EXPECT_EQ(ValidateBoardParams(p), BoardParamsError::kBadMarkerCount);
  EXPECT_STREQ(BoardParamsErrorName(BoardParamsError::kBadMarkerCount), "bad_marker_count");
  p = Charuco(10, 10);  // 50 markers: the whole dictionary
  EXPECT_EQ(ValidateBoardParams(p), BoardParamsError::kOk);
  // The bound is the board's dictionary's marker count.
  p = Charuco(11, 10);
  p.charuco_dictionary = ArucoDictionary::k6x6_100;
  EXPECT_EQ(ValidateBoardParams(p), BoardParamsError::kOk);
  p = Charuco(15, 14);  // 105 markers
  p.charuco_dictionary = ArucoDictionary::k6x6_100;
  EXPECT_EQ(ValidateBoardParams(p), BoardParamsError::kBadMarkerCount);
  p.charuco_dictionary = ArucoDictionary::kArucoOriginal;  // 1024 markers
  EXPECT_EQ(ValidateBoardParams(p), BoardParamsError::kOk);
  p = Charuco(1, 5);
  EXPECT_EQ(ValidateBoardParams(p), BoardParamsError::kBadCols);
  // marker_m is a ChArUco field only.
  BoardParams checker;
  checker.type = BoardType::kChecker;
  checker.marker_m = 1.0;
  EXPECT_EQ(ValidateBoardParams(checker), BoardParamsError::kOk);
}

// ---- Detection on renders -----------------------------------------------------------------

TEST(CharucoDetectorTest, FindsEveryCornerOverAPoseGrid) {
  double worst_clean = 0.0;
  double worst_noisy = 0.0;
  std::uint64_t seed = 1;
  for (const bool legacy : {false, true}) {
    for (const double distance : {0.8, 1.2}) {
      for (const double yaw : {-40.0, 0.0, 35.0}) {
        for (const double pitch : {-25.0, 20.0}) {
          for (const double roll : {0.0, 170.0}) {
            BoardView v;
            v.params = Charuco(7, legacy ? 4 : 5, legacy);
            v.distance_m = distance;
            v.yaw_deg = yaw;
            v.pitch_deg = pitch;
            v.roll_deg = roll;
            SCOPED_TRACE(testing::Message() << "legacy " << legacy << " d " << distance << " yaw "
                                            << yaw << " pitch " << pitch << " roll " << roll);
            const Board board = *Board::Create(v.params);
            for (const bool noisy : {false, true}) {
              const CameraFrame frame =
                  RenderView(v, noisy ? NoisyRender() : CleanRender(), ++seed);
              const Detection d = DetectCharuco(frame.image8.view(), board);
              ExpectComplete(d, board);
              int matched = 0;
              int unknown = 0;
              const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
              EXPECT_EQ(unknown, 0);
              EXPECT_EQ(matched, static_cast<int>(board.features().size()));
              EXPECT_LT(rms, noisy ? kNoisyRmsBarPx : kCleanRmsBarPx);
              (noisy ? worst_noisy : worst_clean) =
                  std::max(noisy ? worst_noisy : worst_clean, rms);
            }
          }
        }
      }
    }
  }
  std::printf("pose grid: worst RMS clean %.4f px, noisy %.4f px\n", worst_clean, worst_noisy);
}

// docs/conventions.md's strongly distorting pinhole (k1 -0.30) and its 190-degree fisheye, the
// board off the axis where the lens bends its rows: each corner is predicted from its own
// markers, so the bending does not matter. The saddle of a bent corner is not exactly
// point-symmetric; 0.1 px bounds the bias (as the circle grid's lens test).
TEST(CharucoDetectorTest, StrongDistortionAndFisheye) {
  constexpr double kLensRmsBarPx = 0.1;
  struct Case {
    const char* name;
    CameraModel camera;
    BoardView view;
  };
  BoardView pinhole;
  pinhole.params = Charuco();
  pinhole.distance_m = 0.7;
  pinhole.offset_m = Eigen::Vector2d(0.35, 0.15);
  pinhole.yaw_deg = -25.0;
  BoardView fisheye = pinhole;
  fisheye.distance_m = 0.45;
  fisheye.offset_m = Eigen::Vector2d(0.3, 0.0);
  fisheye.yaw_deg = -30.0;
  const std::vector<Case> cases = {
      {"strong pinhole", *CameraModel::Create(reference_cameras::StrongPinhole()), pinhole},
      {"fisheye", *CameraModel::Create(reference_cameras::Fisheye190()), fisheye}};
  std::uint64_t seed = 100;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const absl::StatusOr<CameraFrame> rendered = RenderCameraFrame(
        c.camera, test_scene::TestCameraPose(), test_scene::SceneOf(c.view), CleanRender(), ++seed);
    ASSERT_TRUE(rendered.ok()) << rendered.status();
    const CameraFrame& frame = *rendered;
    const Board board = *Board::Create(c.view.params);
    const Detection d = DetectCharuco(frame.image8.view(), board);
    ExpectComplete(d, board);
    int matched = 0;
    int unknown = 0;
    const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
    EXPECT_EQ(unknown, 0);
    EXPECT_LT(rms, kLensRmsBarPx);
    std::printf("%s: RMS %.4f px\n", c.name, rms);
  }
}

// A partial detection: found false, reason partial, at least 4 corners but not all, in id order,
// each with its own board position and within half a pixel of its truth (a wrong id is off by a
// square, tens of pixels).
void ExpectSeenCornersOnly(const Detection& d, const CameraFrame& frame, const Board& board) {
  EXPECT_FALSE(d.found);
  EXPECT_EQ(d.reason, DetectReason::kPartial);
  ASSERT_GE(d.features.size(), 4u);
  EXPECT_LT(d.features.size(), board.features().size());
  int matched = 0;
  int unknown = 0;
  FeatureRmsPx(d, frame, &matched, &unknown);
  EXPECT_EQ(unknown, 0);
  EXPECT_LT(MaxErrorPx(d, frame), 0.5);
  for (std::size_t i = 1; i < d.features.size(); ++i) {
    EXPECT_LT(d.features[i - 1].id, d.features[i].id);
  }
  for (const DetectedFeature& f : d.features) {
    EXPECT_EQ(f.p_board, board.features()[f.id].p_board);
  }
}

// Part of the board out of the image: the corners in view are reported with their ids
// (complete false), and none with a wrong id (a wrong id is off by a square, 40 px).
TEST(CharucoDetectorTest, PartialViewReportsTheSeenCornersWithTheirIds) {
  std::uint64_t seed = 200;
  for (const double offset_x : {-0.62, 0.6}) {
    for (const double offset_y : {0.0, 0.33}) {
      SCOPED_TRACE(testing::Message() << offset_x << ", " << offset_y);
      BoardView v;
      v.params = Charuco();
      v.distance_m = 1.0;
      v.offset_m = Eigen::Vector2d(offset_x, offset_y);
      const Board board = *Board::Create(v.params);
      const CameraFrame frame = RenderView(v, NoisyRender(), ++seed);
      ExpectSeenCornersOnly(DetectCharuco(frame.image8.view(), board), frame, board);
    }
  }
}

// Part of the board hidden by something in front of it (a grey post over its right side, and a
// dark one across its middle rows): the corners in view with their ids, none where it is hidden.
TEST(CharucoDetectorTest, HiddenPartLeavesTheSeenCornersWithTheirIds) {
  BoardView v;
  v.params = Charuco();
  v.distance_m = 1.0;
  v.yaw_deg = 15.0;
  const Board board = *Board::Create(v.params);
  std::uint64_t seed = 250;
  for (const auto& [x0, y0, x1, y1, grey] :
       {std::tuple{700, 0, 1280, 720, 150}, std::tuple{0, 330, 1280, 390, 30}}) {
    SCOPED_TRACE(testing::Message() << x0 << " " << y0 << " " << x1 << " " << y1);
    CameraFrame frame = RenderView(v, NoisyRender(), ++seed);
    for (int y = y0; y < y1; ++y) {
      for (int x = x0; x < x1; ++x) frame.image8.at(x, y) = static_cast<std::uint8_t>(grey);
    }
    const Detection d = DetectCharuco(frame.image8.view(), board);
    ExpectSeenCornersOnly(d, frame, board);
    for (const DetectedFeature& f : d.features) {
      const bool hidden = f.uv_px.x() >= x0 - 1 && f.uv_px.x() < x1 + 1 && f.uv_px.y() >= y0 - 1 &&
                          f.uv_px.y() < y1 + 1;
      EXPECT_FALSE(hidden) << f.id;
    }
  }
}

// One dictionary of each marker size (4, 5, 6 and 7 data bits a side, and ArUco's original):
// a 7 x 5 board of 50 mm squares and 37.5 mm markers (7 x 7 bits: cells of 4.2 mm, 4.6 px at
// 0.9 m) found whole over a few poses, clean and noisy, every corner with its id and within
// the render bars; half out of view, the corners in view with their ids; and not found as a
// board of another dictionary.
TEST(CharucoDetectorTest, EveryMarkerSizeIsFoundWithItsIds) {
  std::uint64_t seed = 500;
  for (const ArucoDictionary dictionary :
       {ArucoDictionary::k4x4_250, ArucoDictionary::k5x5_100, ArucoDictionary::k6x6_50,
        ArucoDictionary::k7x7_1000, ArucoDictionary::kArucoOriginal}) {
    SCOPED_TRACE(ArucoDictionaryInfoOf(dictionary).name);
    BoardView v;
    v.params = Charuco();
    v.params.square_m = 0.05;
    v.params.marker_m = 0.0375;
    v.params.charuco_dictionary = dictionary;
    v.distance_m = 0.9;
    const Board board = *Board::Create(v.params);
    for (const double yaw : {-35.0, 0.0, 30.0}) {
      for (const double roll : {0.0, 100.0}) {
        for (const bool noisy : {false, true}) {
          SCOPED_TRACE(testing::Message()
                       << "yaw " << yaw << " roll " << roll << " noisy " << noisy);
          v.yaw_deg = yaw;
          v.roll_deg = roll;
          const CameraFrame frame = RenderView(v, noisy ? NoisyRender() : CleanRender(), ++seed);
          const Detection d = DetectCharuco(frame.image8.view(), board);
          ExpectComplete(d, board);
          int matched = 0;
          int unknown = 0;
          const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
          EXPECT_EQ(unknown, 0);
          EXPECT_EQ(matched, static_cast<int>(board.features().size()));
          EXPECT_LT(rms, noisy ? kNoisyRmsBarPx : kCleanRmsBarPx);
        }
      }
    }
    BoardView partial = v;
    partial.yaw_deg = 0.0;
    partial.roll_deg = 0.0;
    partial.offset_m = Eigen::Vector2d(0.5, 0.0);
    const CameraFrame cut = RenderView(partial, NoisyRender(), ++seed);
    ExpectSeenCornersOnly(DetectCharuco(cut.image8.view(), board), cut, board);
    // The same board with the 4 x 4 (or, for those, the 5 x 5) dictionary: no marker of it.
    BoardParams other = v.params;
    other.charuco_dictionary = ArucoDictionaryInfoOf(dictionary).data_bits == 4
                                   ? ArucoDictionary::k5x5_50
                                   : ArucoDictionary::k4x4_50;
    const CameraFrame frame = RenderView(v, CleanRender(), ++seed);
    const Detection wrong = DetectCharuco(frame.image8.view(), *Board::Create(other));
    EXPECT_FALSE(wrong.found);
    EXPECT_TRUE(wrong.features.empty());
  }
}

// The ChArUco board as detectors_eval renders it in the hard set at its nearest distance for
// the view (yaw, pitch, roll in degrees) and the evaluation's seed.
absl::StatusOr<CameraFrame> RenderNearestHard(const Board& board, const CameraModel& camera,
                                              double yaw, double pitch, double roll,
                                              std::uint64_t seed) {
  const double distance =
      circle_scene::EvaluationDistances(board, camera, false, yaw, pitch).front();
  return circle_scene::RenderScene(
      circle_scene::OneBoard(BoardType::kCharuco,
                             circle_scene::EvaluationPose(distance, yaw, pitch, roll, seed)),
      circle_scene::HardEffects(seed), seed, camera);
}

// A hard render's board found whole with every corner's id right, none farther from the truth
// than a third of a far-side marker cell: a cell is 3.1 mm, 8 px face-on at the hard set's
// distances and 5 px on the far side. Prints the RMS and the largest error.
void ExpectWholeWithinAThirdOfAFarCell(const Board& board, const CameraFrame& frame,
                                       std::uint64_t seed) {
  const Detection d = DetectCharuco(frame.image8.view(), board);
  ExpectComplete(d, board);
  int matched = 0;
  int unknown = 0;
  const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
  std::printf("seed %llu: RMS %.4f px, max %.3f px\n", static_cast<unsigned long long>(seed), rms,
              MaxErrorPx(d, frame));
  EXPECT_EQ(unknown, 0);
  EXPECT_EQ(matched, static_cast<int>(board.features().size()));
  EXPECT_LT(MaxErrorPx(d, frame), 5.0 / 3.0);
}

// detectors_eval's hard set (noise 6, blur 1.5, a 4:1 light gradient, gamma, JPEG 80, clutter)
// on the default 9 x 6 board at its nearest distance, turned 35-50 degrees: the far side's
// markers are too foreshortened for the scan (cells of 1-2 px across) and some corners' saddle
// fits fail there. These renders (the evaluation's seeds 60 and 165) were partial detections
// until the missed markers were read where their neighbours put them; now every corner is
// found with its id, none farther from its truth than a third of a marker cell.
TEST(CharucoDetectorTest, HardRendersWithForeshortenedMarkersAreFoundWhole) {
  BoardParams params;
  params.type = BoardType::kCharuco;
  const Board board = *Board::Create(params);
  const CameraModel camera = circle_scene::Camera();
  for (const auto& [yaw, pitch, roll, seed] :
       {std::tuple{-50.0, 0.0, 0.0, std::uint64_t{60}},
        std::tuple{-35.0, -35.0, -30.0, std::uint64_t{165}}}) {
    SCOPED_TRACE(testing::Message() << "seed " << seed);
    const absl::StatusOr<CameraFrame> frame =
        RenderNearestHard(board, camera, yaw, pitch, roll, seed);
    ASSERT_TRUE(frame.ok()) << frame.status();
    ExpectWholeWithinAThirdOfAFarCell(board, *frame, seed);
  }
}

// More of the hard set's nearest renders turned 35-50 degrees that stayed partial (the
// evaluation's seeds 75, 375, 429 and 549 of `detectors_eval --board charuco --repeat 3`):
// a marker next to a corner unread (blur joins its sheared border to the black square through
// a margin of 2 px) left the corner with markers on two sides, too few to interpolate, and
// its saddle fit from one marker's homography failed; seed 429 lost 13 corners of its far
// side so. The corners found around such a corner now place it as a chessboard's neighbour,
// and its saddle fit and paint check are made there.
TEST(CharucoDetectorTest, CornersBesideUnreadMarkersArePlacedByTheirNeighbours) {
  BoardParams params;
  params.type = BoardType::kCharuco;
  const Board board = *Board::Create(params);
  const CameraModel camera = circle_scene::Camera();
  for (const auto& [yaw, pitch, roll, seed] :
       {std::tuple{-50.0, 0.0, -30.0, std::uint64_t{75}},
        std::tuple{-35.0, -35.0, 0.0, std::uint64_t{375}},
        std::tuple{50.0, 0.0, 0.0, std::uint64_t{429}},
        std::tuple{-35.0, -35.0, 30.0, std::uint64_t{549}}}) {
    SCOPED_TRACE(testing::Message() << "seed " << seed);
    const absl::StatusOr<CameraFrame> frame =
        RenderNearestHard(board, camera, yaw, pitch, roll, seed);
    ASSERT_TRUE(frame.ok()) << frame.status();
    ExpectWholeWithinAThirdOfAFarCell(board, *frame, seed);
  }
}

// The evaluation's last hard miss (seed 39: the middle distance, yaw 50, roll -30): the far
// corner of the board, where the 50 degree turn narrows the white margin between the corner
// and its markers to 3 px. The saddle fit's window of half side 3 px reached, at its corners,
// into the markers' black borders and failed to find a saddle; a window whose corners stay in
// the margin (half side 2 px) finds the corner, as it is: a sharp X-junction.
TEST(CharucoDetectorTest, CornerWhoseMarginIsNarrowedByTheTurnIsFitInsideIt) {
  BoardParams params;
  params.type = BoardType::kCharuco;
  const Board board = *Board::Create(params);
  const CameraModel camera = circle_scene::Camera();
  // The middle of the three distances at that turn: 0.39 m, far-side cells of 2 px.
  const double distance = circle_scene::EvaluationDistances(board, camera, false, 50.0, 0.0)[1];
  const absl::StatusOr<CameraFrame> frame = circle_scene::RenderScene(
      circle_scene::OneBoard(BoardType::kCharuco,
                             circle_scene::EvaluationPose(distance, 50.0, 0.0, -30.0, 39)),
      circle_scene::HardEffects(39), 39, camera);
  ASSERT_TRUE(frame.ok()) << frame.status();
  ExpectWholeWithinAThirdOfAFarCell(board, *frame, 39);
}

// A small board far off: the deepcharuco photos' 5 x 5 board (10 mm squares, 7.5 mm markers:
// cells of 1.25 mm) at 0.45 m, cells of 2.8 px, under the 4 px the marker scan is made for:
// clean renders are still found whole, every corner with its id. (The photos' heavier blur
// closes the 1.7 px margins between markers and squares; there the board's part of the image
// is read again at twice the resolution: PhotosTest.CharucoPhotoWithSmallMarkersIsFoundWhole.)
TEST(CharucoDetectorTest, MarkersWithCellsUnderFourPixelsAreFoundWithTheirIds) {
  BoardView v;
  v.params = Charuco(5, 5);
  v.params.square_m = 0.01;
  v.params.marker_m = 0.0075;
  v.distance_m = 0.45;
  const Board board = *Board::Create(v.params);
  std::uint64_t seed = 600;
  for (const double yaw : {0.0, 30.0}) {
    SCOPED_TRACE(testing::Message() << "yaw " << yaw);
    v.yaw_deg = yaw;
    const CameraFrame frame = RenderView(v, CleanRender(), ++seed);
    const Detection d = DetectCharuco(frame.image8.view(), board);
    ExpectComplete(d, board);
    int matched = 0;
    int unknown = 0;
    const double rms = FeatureRmsPx(d, frame, &matched, &unknown);
    EXPECT_EQ(unknown, 0);
    EXPECT_EQ(matched, 16);
    EXPECT_LT(rms, kNoisyRmsBarPx);
  }
}

// ---- Boards whose markers are too small to read one by one ----------------------------------

// The deepcharuco photos' 5 x 5 board (10 mm squares, 7.5 mm markers of DICT_4X4_50) rendered
// with `render` and halved (HalveImage: the 2 x 2 mean, as a camera's binning or a photo
// scaled down), and what DetectCharuco makes of it: whether it is found whole, and how many
// features lie more than half a square from the truth of their id (wrong ids: a corner given
// another corner's id is a whole square off).
struct SmallBoardRead {
  bool whole = false;
  int wrong = 0;
};

SmallBoardRead ReadHalvedSmallBoard(const BoardParams& drawn, const Board& board, BoardView v,
                                    const CameraRenderOptions& render, std::uint64_t seed) {
  v.params = drawn;
  const CameraFrame frame = RenderView(v, render, seed);
  const Image8 half = HalveImage(frame.image8.view());
  const Detection d = DetectCharuco(half.view(), board);
  SmallBoardRead read;
  read.whole = d.found;
  // Half a square in the render's pixels (f 1000 px).
  const double half_square_px = 0.5 * 1000.0 * drawn.square_m / v.distance_m;
  for (const DetectedFeature& f : d.features) {
    bool right = false;
    for (const RenderedFeature& t : frame.features) {
      // A level-1 pixel's centre lies at 2 u + 0.5 in the render (HalveImage).
      if (t.feature_id == f.id)
        right = (LevelToImage(f.uv_px, 1) - t.uv_px).norm() < half_square_px;
    }
    read.wrong += right ? 0 : 1;
  }
  return read;
}

BoardParams DeepcharucoBoard() {
  BoardParams p = Charuco(5, 5);
  p.square_m = 0.01;
  p.marker_m = 0.0075;
  return p;
}

// Markers of 1.8-2.4 px cells, of which the marker scan reads few or none: those it reads
// place a partial board, read again at twice the resolution, and where that is not whole
// either the board's inner corners are found as a chessboard's and its orientation voted over
// all markers' cells (charuco_detector.h). Over 3 distances (squares of 19.2, 16.7 and 14.7 px
// after halving: cells of 2.4, 2.1 and 1.8 px), 3 yaws, 2 pitches and 4 turns of the board (a
// quarter turn apart, so that every orientation must be read from the cells), clean, noisy and
// noisy under a blur of 1.6 px: the counts found whole are at least the measured ones, and no
// corner of the 216 renders ever carries a wrong id.
TEST(CharucoDetectorTest, SmallBoardsAreFoundWholeFromTheirCornerGridWithNoWrongId) {
  const BoardParams params = DeepcharucoBoard();
  const Board board = *Board::Create(params);
  std::uint64_t seed = 700;
  CameraRenderOptions blurred = NoisyRender();
  blurred.blur_sigma_px = 1.6;
  for (const int condition : {0, 1, 2}) {
    const CameraRenderOptions render = condition == 0   ? CleanRender()
                                       : condition == 1 ? NoisyRender()
                                                        : blurred;
    std::map<double, int> whole_at;  // by distance
    int wrong = 0;
    for (const double distance : {0.26, 0.3, 0.34}) {
      for (const double yaw : {-35.0, 0.0, 35.0}) {
        for (const double pitch : {-20.0, 20.0}) {
          for (const double roll : {8.0, 98.0, 188.0, 278.0}) {
            BoardView v;
            v.distance_m = distance;
            v.yaw_deg = yaw;
            v.pitch_deg = pitch;
            v.roll_deg = roll;
            const SmallBoardRead read = ReadHalvedSmallBoard(params, board, v, render, ++seed);
            whole_at[distance] += read.whole ? 1 : 0;
            wrong += read.wrong;
          }
        }
      }
    }
    std::printf("condition %d: whole %d %d %d of 24 each, wrong %d\n", condition, whole_at[0.26],
                whole_at[0.3], whole_at[0.34], wrong);
    EXPECT_EQ(wrong, 0);
    // Measured (2026-12-07; docs/detectors.md): at least these are found whole.
    const std::array<std::array<int, 3>, 3> kMeasured = {
        std::array<int, 3>{24, 24, 24}, {24, 24, 20}, {24, 19, 4}};
    EXPECT_GE(whole_at[0.26], kMeasured[condition][0]);
    EXPECT_GE(whole_at[0.3], kMeasured[condition][1]);
    EXPECT_GE(whole_at[0.34], kMeasured[condition][2]);
  }
}

// ---- Nothing where there is no such board ---------------------------------------------------

TEST(CharucoDetectorTest, FindsNothingOnOtherBoards) {
  const Board board = *Board::Create(Charuco());
  std::uint64_t seed = 300;
  for (BoardType type :
       {BoardType::kAruco, BoardType::kRoundHole, BoardType::kChecker, BoardType::kApriltag}) {
    SCOPED_TRACE(BoardTypeName(type));
    BoardView v;
    v.params.type = type;
    v.distance_m = type == BoardType::kChecker ? 1.0 : 3.0;
    const CameraFrame frame = RenderView(v, CleanRender(), ++seed);
    const Detection d = DetectCharuco(frame.image8.view(), board);
    EXPECT_FALSE(d.found);
    EXPECT_TRUE(d.features.empty());
  }
  // A ChArUco board of another size: its markers share ids 0..16 but not their squares.
  BoardView v;
  v.params = Charuco(9, 6);
  v.distance_m = 1.0;
  const CameraFrame frame = RenderView(v, CleanRender(), ++seed);
  const Detection d = DetectCharuco(frame.image8.view(), board);
  EXPECT_FALSE(d.found);
  int matched = 0;
  int unknown = 0;
  FeatureRmsPx(d, frame, &matched, &unknown);
  EXPECT_EQ(unknown, 0);
}

// With an even row count the legacy layout is the current one shifted by a square, with mostly
// the same ids in the same places: each board must refuse the other's print (its markers in the
// margin, where the shifted board prints none), never report corners a square off.
TEST(CharucoDetectorTest, LegacyAndCurrentLayoutsAreToldApart) {
  std::uint64_t seed = 350;
  for (const bool drawn_legacy : {false, true}) {
    SCOPED_TRACE(drawn_legacy ? "legacy print" : "current print");
    BoardView v;
    v.params = Charuco(7, 4, drawn_legacy);
    v.distance_m = 1.0;
    v.yaw_deg = 20.0;
    const CameraFrame frame = RenderView(v, NoisyRender(), ++seed);
    ExpectComplete(DetectCharuco(frame.image8.view(), *Board::Create(v.params)),
                   *Board::Create(v.params));
    const Detection d =
        DetectCharuco(frame.image8.view(), *Board::Create(Charuco(7, 4, !drawn_legacy)));
    EXPECT_FALSE(d.found);
    EXPECT_EQ(d.reason, DetectReason::kWrongBoard);
    EXPECT_TRUE(d.features.empty());
  }
}

TEST(CharucoDetectorTest, BoardFreeImagesGiveNoFeatures) {
  const Board board = *Board::Create(Charuco());
  const Image8 noise = test_scene::UniformNoiseImage(1280, 720);
  Detection d = DetectCharuco(noise.view(), board);
  EXPECT_FALSE(d.found);
  EXPECT_TRUE(d.features.empty());
  const Image8 grey(640, 480, 128);
  d = DetectCharuco(grey.view(), board);
  EXPECT_FALSE(d.found);
  EXPECT_TRUE(d.features.empty());
}

TEST(CharucoDetectorTest, BadInputGivesAReason) {
  const Board board = *Board::Create(Charuco());
  const Image8 image(64, 64, 128);
  EXPECT_EQ(DetectCharuco(ImageView8{}, board).reason, DetectReason::kBadImage);
  CharucoOptions bad;
  bad.blur_sigma_px = 0.1;
  EXPECT_EQ(bad.Validate(), "blur_sigma_px");
  EXPECT_EQ(DetectCharuco(image.view(), board, bad).reason, DetectReason::kBadImage);
  bad = CharucoOptions();
  bad.max_neighbour_error = 0.0;
  EXPECT_EQ(bad.Validate(), "max_neighbour_error");
  BoardParams checker;
  checker.type = BoardType::kChecker;
  EXPECT_EQ(DetectCharuco(image.view(), *Board::Create(checker)).reason, DetectReason::kWrongBoard);
}

// Speed is not asserted here (a timed test fails under the sanitizers and on a loaded
// machine); the 5-8 ms at 1280 x 720 of docs/detectors.md were measured by hand.
TEST(CharucoDetectorTest, DetectBoardDispatches) {
  BoardView v;
  v.params = Charuco();
  v.distance_m = 1.0;
  const Board board = *Board::Create(v.params);
  const CameraFrame frame = RenderView(v, NoisyRender(), 400);
  const std::optional<Detection> d = DetectBoard(frame.image8.view(), board);
  ASSERT_TRUE(d.has_value());
  ExpectComplete(*d, board);
}

}  // namespace
}  // namespace linecal

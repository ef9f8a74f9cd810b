// The checker detector on boards as they are printed and seen through real lenses, drawn
// here with exact truth: a pinhole view through a homography, bent by a strong barrel lens
// (a field of view of about 115 degrees across the diagonal, as a wide-angle camera's),
// outer squares cut to half a square with no white margin over a textured room, either
// colour at the corners, squares that do not touch, and a larger board that only holds the
// size asked for. The station renderer draws boards as docs/boards.md defines them (whole
// squares, a white margin); these are the prints the real photos of docs/external-data.md
// show, checked there too (detectors_photos_test).
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <vector>

#include "detectors/checker/checker_detector.h"

namespace linecal {
namespace {

// How a board is printed, in square units around the inner corners (corner (c, r) at board
// point (c, r)).
struct Print {
  int cols = 9;
  int rows = 6;
  double outer = 0.5;    // how far the outer squares reach beyond the outer corners (1: whole)
  double margin = 0.0;   // white paper beyond the squares
  bool flipped = false;  // the top-left square white instead of black
  double gap = 0.0;      // dark squares shrunk by this on every side (0: they touch)
};

// The camera: board (square units) -> undistorted pixel by H, then a barrel lens about the
// image centre with focal length f, in the division form x_u = x_d (1 + kappa |x_d|^2) (units
// of f): monotonic, so every pixel sees one board point, and the image's corners (|x_d|
// 1.25) see 1.7 times as far out as a pinhole would.
struct Lens {
  Eigen::Matrix3d H;
  double f = 400.0;
  double kappa = 0.45;
  Eigen::Vector2d centre{400.0, 300.0};
};

// The pixel of board point `board`: |x_d| from |x_u| by Newton's method on
// r (1 + kappa r^2) = |x_u| (increasing in r, so it converges from r = |x_u|).
Eigen::Vector2d Project(const Lens& lens, const Eigen::Vector2d& board) {
  const Eigen::Vector3d h = lens.H * Eigen::Vector3d(board.x(), board.y(), 1.0);
  const Eigen::Vector2d xu = (h.head<2>() / h.z() - lens.centre) / lens.f;
  const double ru = xu.norm();
  double r = ru;
  for (int k = 0; k < 30; ++k) {
    r -= (r * (1.0 + lens.kappa * r * r) - ru) / (1.0 + 3.0 * lens.kappa * r * r);
  }
  return lens.centre + lens.f * (ru > 0.0 ? xu * (r / ru) : xu);
}

// The board point seen at pixel (u, v).
Eigen::Vector2d BoardPoint(const Lens& lens, const Eigen::Matrix3d& H_inv, double u, double v) {
  const Eigen::Vector2d xd = (Eigen::Vector2d(u, v) - lens.centre) / lens.f;
  const Eigen::Vector2d p = lens.centre + lens.f * xd * (1.0 + lens.kappa * xd.squaredNorm());
  const Eigen::Vector3d b = H_inv * Eigen::Vector3d(p.x(), p.y(), 1.0);
  return b.head<2>() / b.z();
}

// Grey level of board point b: print where the board is, a textured room (stripes and
// blotches, 40..140) beyond it.
double Paint(const Print& print, const Eigen::Vector2d& b) {
  const double x0 = -print.outer, x1 = print.cols - 1 + print.outer;
  const double y0 = -print.outer, y1 = print.rows - 1 + print.outer;
  const bool on_squares = b.x() >= x0 && b.x() <= x1 && b.y() >= y0 && b.y() <= y1;
  if (!on_squares) {
    const bool on_paper = b.x() >= x0 - print.margin && b.x() <= x1 + print.margin &&
                          b.y() >= y0 - print.margin && b.y() <= y1 + print.margin;
    if (on_paper) return 230.0;
    return 90.0 + 50.0 * std::sin(3.1 * b.x()) * std::cos(1.7 * b.y() + 0.5 * b.x());
  }
  const double fx = b.x() + 1.0 - std::floor(b.x() + 1.0);  // within the square
  const double fy = b.y() + 1.0 - std::floor(b.y() + 1.0);
  const int sx = static_cast<int>(std::floor(b.x() + 1.0));
  const int sy = static_cast<int>(std::floor(b.y() + 1.0));
  bool dark = ((sx + sy) % 2 == 0) != print.flipped;
  if (dark && print.gap > 0.0) {
    dark = fx >= print.gap && fx <= 1.0 - print.gap && fy >= print.gap && fy <= 1.0 - print.gap;
  }
  return dark ? 25.0 : 230.0;
}

// An 800 x 600 image of the print, 4 x 4 samples per pixel (the anti-aliasing a lens and
// sensor give).
Image8 Draw(const Print& print, const Lens& lens) {
  const Eigen::Matrix3d H_inv = lens.H.inverse();
  Image8 image(800, 600);
  for (int v = 0; v < image.height; ++v) {
    for (int u = 0; u < image.width; ++u) {
      double sum = 0.0;
      for (int k = 0; k < 16; ++k) {
        sum += Paint(
            print, BoardPoint(lens, H_inv, u - 0.375 + 0.25 * (k % 4), v - 0.375 + 0.25 * (k / 4)));
      }
      image.at(u, v) = static_cast<std::uint8_t>(std::lround(sum / 16.0));
    }
  }
  return image;
}

// A view of the board filling most of the image, turned by 15 degrees in its plane and 25
// and 20 degrees about its axes: the lens bends its outer corners by tens of pixels.
Lens WideView(const Print& print) {
  Lens lens;
  constexpr double kDeg = 3.14159265358979 / 180.0;
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(15 * kDeg, Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(25 * kDeg, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(20 * kDeg, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  // Far enough that the board's half width (square units) spans 300 px at the centre.
  const double z = lens.f * 0.5 * (print.cols + 1) / 300.0;
  const Eigen::Vector3d centre(0.5 * (print.cols - 1), 0.5 * (print.rows - 1), 0.0);
  const Eigen::Vector3d t = Eigen::Vector3d(0.0, 0.0, z) - R * centre;
  Eigen::Matrix3d K;
  K << lens.f, 0.0, lens.centre.x(), 0.0, lens.f, lens.centre.y(), 0.0, 0.0, 1.0;
  Eigen::Matrix3d Rt;
  Rt << R.col(0), R.col(1), t;
  lens.H = K * Rt;
  return lens;
}

Board CheckerBoard(int cols, int rows) {
  BoardParams p;
  p.type = BoardType::kChecker;
  p.cols = cols;
  p.rows = rows;
  return *Board::Create(p);
}

// The largest distance between a detected corner and the true image of corner `truth_id(id)`.
template <typename IdMap>
double MaxErrorPx(const Detection& d, const Print& print, const Lens& lens, IdMap truth_id) {
  double worst = 0.0;
  for (const DetectedFeature& f : d.features) {
    const int t = truth_id(f.id);
    const Eigen::Vector2d truth = Project(lens, Eigen::Vector2d(t % print.cols, t / print.cols));
    worst = std::max(worst, (f.uv_px - truth).norm());
  }
  return worst;
}

int Same(int id) { return id; }

// How far the lens bends the board: the largest distance between a corner's image and where
// the homography alone puts it.
double LensBendPx(const Print& print, const Lens& lens) {
  double bend = 0.0;
  for (int r = 0; r < print.rows; ++r) {
    for (int c = 0; c < print.cols; ++c) {
      const Eigen::Vector3d h = lens.H * Eigen::Vector3d(c, r, 1.0);
      bend = std::max(bend, (Project(lens, Eigen::Vector2d(c, r)) - h.head<2>() / h.z()).norm());
    }
  }
  return bend;
}

TEST(CheckerPrintTest, CutSquaresWithoutMarginThroughAStrongLens) {
  const Print print;
  const Lens lens = WideView(print);
  ASSERT_GT(LensBendPx(print, lens), 40.0);  // far beyond any whole-board homography check
  const Detection d = DetectChecker(Draw(print, lens).view(), CheckerBoard(9, 6));
  ASSERT_TRUE(d.found) << DetectReasonName(d.reason);
  ASSERT_EQ(d.features.size(), 54u);
  EXPECT_LT(MaxErrorPx(d, print, lens, Same), 0.15);
}

TEST(CheckerPrintTest, WhiteTopLeftSquareIsTheBoardTurnedWhenColsPlusRowsIsOdd) {
  Print print;
  print.flipped = true;
  const Lens lens = WideView(print);
  const Detection d = DetectChecker(Draw(print, lens).view(), CheckerBoard(9, 6));
  ASSERT_TRUE(d.found) << DetectReasonName(d.reason);
  // The same paint as the standard board turned by 180 degrees: corner id k is at the
  // print's corner 53 - k.
  EXPECT_LT(MaxErrorPx(d, print, lens, [](int id) { return 53 - id; }), 0.15);
}

TEST(CheckerPrintTest, WhiteTopLeftSquareIsFoundWhenColsPlusRowsIsEven) {
  Print print;
  print.cols = 8;
  print.flipped = true;
  const Lens lens = WideView(print);
  const Detection d = DetectChecker(Draw(print, lens).view(), CheckerBoard(8, 6));
  ASSERT_TRUE(d.found) << DetectReasonName(d.reason);
  // Symmetric under 180 degrees: the upright orientation, board x along the image's +u.
  EXPECT_LT(MaxErrorPx(d, print, lens, Same), 0.15);
}

TEST(CheckerPrintTest, SquaresThatDoNotTouch) {
  Print print;
  print.cols = 9;
  print.rows = 8;
  print.outer = 1.0;
  print.margin = 1.0;
  print.gap = 0.025;  // squares 0.05 apart: 2-3 px here, as in Kalibr's photo
  const Lens lens = WideView(print);
  const Detection d = DetectChecker(Draw(print, lens).view(), CheckerBoard(9, 8));
  ASSERT_TRUE(d.found) << DetectReasonName(d.reason);
  // The vertex of a gapped corner is the middle of the gap, where the saddle is.
  EXPECT_LT(MaxErrorPx(d, print, lens, Same), 0.25);
}

TEST(CheckerPrintTest, ALargerBoardIsNotASmallerOne) {
  const Print print;  // 9 x 6 inner corners
  const Lens lens = WideView(print);
  const Image8 image = Draw(print, lens);
  const Detection d = DetectChecker(image.view(), CheckerBoard(6, 4));
  EXPECT_FALSE(d.found);
  EXPECT_TRUE(d.features.empty());
  EXPECT_EQ(d.reason, DetectReason::kWrongBoard);
  EXPECT_FALSE(DetectChecker(image.view(), CheckerBoard(8, 6)).found);
}

}  // namespace
}  // namespace linecal

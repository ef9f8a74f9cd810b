// The camera renderer checked against geometry: rendered discs and edges against exact
// projections through the camera model, ground-truth features against independent ray
// tests, and the camera response against its definition.
#include "station/sim/camera_render.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <numbers>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace linecal {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;
constexpr double kInf = std::numeric_limits<double>::infinity();

// The bars of the renderer's issue: a straight edge's sub-pixel position, the corners where
// fitted edges meet, and a disc's intensity centroid.
constexpr double kEdgeBarPx = 0.01;
constexpr double kCornerBarPx = 0.02;
constexpr double kCentroidBarPx = 0.02;
// The same projection through differently composed transforms: rounding, ~1e-12 px.
constexpr double kRoundingPx = 1e-9;
// 16-bit full scale.
constexpr double kFull16 = 65535.0;

// ---- Cameras and scenes ------------------------------------------------------------------

CameraModel Pinhole(double k1 = 0.0, double k2 = 0.0) {
  CameraIntrinsics c;
  c.type = CameraModelType::kPinhole;
  c.width = 640;
  c.height = 480;
  c.fx = 600.0;
  c.fy = 602.0;
  c.cx = 321.3;
  c.cy = 238.6;
  c.k1 = k1;
  c.k2 = k2;
  return *CameraModel::Create(c);
}

// The reference car's surround fisheye (deploy/cars/reference.json), ~190 degrees.
CameraModel Fisheye() {
  CameraIntrinsics c;
  c.type = CameraModelType::kFisheye;
  c.width = 1280;
  c.height = 960;
  c.fx = 330.0;
  c.fy = 330.0;
  c.cx = 640.5;
  c.cy = 478.2;
  c.k1 = 0.04;
  c.k2 = -0.008;
  c.k3 = 0.0015;
  c.k4 = -0.0002;
  return *CameraModel::Create(c);
}

// The camera 1.5 m above the station origin, looking along +x (docs/conventions.md's camera
// base rotation), turned by yaw about the vertical.
Rigid3d CameraPose(double yaw_deg = 0.0) {
  return Rigid3d(RotationFromYawPitchRoll({yaw_deg * kDeg, 0, 0}) * CameraBaseRotation(),
                 Eigen::Vector3d(0, 0, 1.5));
}

// A board's zero orientation (docs/station-and-car.md): upright, its print facing -x.
Eigen::Matrix3d BoardBase() {
  Eigen::Matrix3d r;
  r.col(0) = -Eigen::Vector3d::UnitY();
  r.col(1) = Eigen::Vector3d::UnitZ();
  r.col(2) = -Eigen::Vector3d::UnitX();
  return r;
}

Rigid3d BoardPose(const Eigen::Vector3d& p_station, double yaw_deg, double pitch_deg,
                  double roll_deg) {
  return Rigid3d(MountingRotation({yaw_deg * kDeg, pitch_deg * kDeg, roll_deg * kDeg}, BoardBase()),
                 p_station);
}

StationBoard MakeBoard(const std::string& id, BoardType type, double scale, const Rigid3d& pose) {
  StationBoard b;
  b.id = id;
  b.params.type = type;
  b.params.scale = scale;
  b.board = *Board::Create(b.params);
  b.T_station_board = pose;
  return b;
}

StationBoard Checker(const std::string& id, double square_m, const Rigid3d& pose) {
  StationBoard b;
  b.id = id;
  b.params.type = BoardType::kChecker;
  b.params.square_m = square_m;
  b.board = *Board::Create(b.params);
  b.T_station_board = pose;
  return b;
}

// A wall facing -x (towards the camera) at distance x, big enough to fill any view.
StationSurface Wall(double x, double reflectivity) {
  StationSurface w;
  w.id = "wall";
  w.T_station_surface = BoardPose(Eigen::Vector3d(x, 0, 1.5), 0, 0, 0);
  w.size_m = Eigen::Vector2d(200, 200);
  w.reflectivity = reflectivity;
  return w;
}

// Linear light straight to 16 bits: white print 1, black print 0, so a pixel's grey is its
// white coverage times 65535.
CameraRenderOptions GeometryOptions() {
  CameraRenderOptions o;
  o.white_reflectance = 1.0;
  o.black_reflectance = 0.0;
  o.illumination = 1.0;
  o.bit_depth = 16;
  return o;
}

CameraFrame Render(const CameraModel& camera, const Rigid3d& T_station_camera,
                   const StationLayout& layout, const CameraRenderOptions& options,
                   std::uint64_t seed = 1) {
  absl::StatusOr<CameraFrame> frame =
      RenderCameraFrame(camera, T_station_camera, layout, options, seed);
  EXPECT_TRUE(frame.ok()) << frame.status();
  return frame.ok() ? *std::move(frame) : CameraFrame();
}

double Grey(const CameraFrame& f, int x, int y) { return f.image16.at(x, y) / kFull16; }

// The projection of a board point, which must succeed.
Eigen::Vector2d ProjectBoardPoint(const CameraModel& camera, const Rigid3d& T_station_camera,
                                  const StationBoard& b, const Eigen::Vector2d& p_board) {
  const Eigen::Vector3d p_camera =
      T_station_camera.Inverse() *
      (b.T_station_board * Eigen::Vector3d(p_board.x(), p_board.y(), 0));
  Eigen::Vector2d uv;
  EXPECT_TRUE(camera.Project(p_camera, &uv));
  return uv;
}

// ---- Discs -------------------------------------------------------------------------------

// The centroid of the region a board disc projects to: the region bounded by the projected
// circle, as a polygon of 4096 vertices (Green's theorem). The polygon's area and
// centroid differ from the smooth curve's by ~(2 pi / 4096)^2 relative: 1e-6 px here.
Eigen::Vector2d ProjectedDiscCentroid(const CameraModel& camera, const Rigid3d& T_station_camera,
                                      const StationBoard& b, const Eigen::Vector2d& centre,
                                      double radius) {
  constexpr int kVertices = 4096;
  std::vector<Eigen::Vector2d> polygon;
  for (int i = 0; i < kVertices; ++i) {
    const double a = 2 * kPi * i / kVertices;
    polygon.push_back(ProjectBoardPoint(
        camera, T_station_camera, b, centre + radius * Eigen::Vector2d(std::cos(a), std::sin(a))));
  }
  double twice_area = 0.0;
  Eigen::Vector2d moment = Eigen::Vector2d::Zero();
  for (int i = 0; i < kVertices; ++i) {
    const Eigen::Vector2d& p = polygon[i];
    const Eigen::Vector2d& q = polygon[(i + 1) % kVertices];
    const double cross = p.x() * q.y() - q.x() * p.y();
    twice_area += cross;
    moment += cross * (p + q);
  }
  return moment / (3.0 * twice_area);
}

struct DiscResult {
  double worst_error_px = 0.0;  // rendered centroid vs projected region's centroid
  double worst_bias_px = 0.0;   // projected region's centroid vs projected centre
  int discs = 0;
};

// Intensity-weighted centroids of the white discs of a circle board. The window around a
// disc is the set of pixels whose centre sees the board within kWindowM of the disc's
// centre: it holds the whole disc (25 mm) and, at 31 mm, stays clear of the neighbours
// (>= 45 mm away) and of the white bar (35 mm from the centres of the discs above and below
// it) by more than a pixel's footprint (< 2 mm here). So every window pixel is black but
// for the disc.
DiscResult MeasureDiscs(const CameraModel& camera, const Rigid3d& T_station_camera,
                        const StationLayout& layout, const CameraRenderOptions& options) {
  constexpr double kWindowM = 0.031;
  const CameraFrame frame = Render(camera, T_station_camera, layout, options);
  const StationBoard& b = layout.boards[0];
  // Where each pixel centre's ray meets the board plane, in board coordinates.
  const Rigid3d T_board_camera = b.T_station_board.Inverse() * T_station_camera;
  const int width = camera.intrinsics().width, height = camera.intrinsics().height;
  std::vector<Eigen::Vector2d> seen(static_cast<std::size_t>(width) * height,
                                    Eigen::Vector2d::Constant(kInf));
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      Eigen::Vector3d ray;
      if (!camera.Unproject(Eigen::Vector2d(x, y), &ray)) continue;
      const Eigen::Vector3d o = T_board_camera.translation();
      const Eigen::Vector3d d = T_board_camera.rotation() * ray;
      const double t = -o.z() / d.z();
      if (t > 0) seen[static_cast<std::size_t>(y) * width + x] = (o + t * d).head<2>();
    }
  }
  DiscResult result;
  for (const BoardShape& shape : b.board.shapes()) {
    if (shape.geometry != ShapeGeometry::kCircle || shape.paint != Paint::kWhite) continue;
    const Eigen::Vector2d centre = shape.centre_board();
    double sum = 0.0;
    Eigen::Vector2d moment = Eigen::Vector2d::Zero();
    for (int y = 0; y < height; ++y) {
      for (int x = 0; x < width; ++x) {
        if ((seen[static_cast<std::size_t>(y) * width + x] - centre).norm() > kWindowM) continue;
        const double w = Grey(frame, x, y);
        sum += w;
        moment += w * Eigen::Vector2d(x, y);
      }
    }
    const Eigen::Vector2d measured = moment / sum;
    const Eigen::Vector2d expected =
        ProjectedDiscCentroid(camera, T_station_camera, b, centre, shape.radius_m());
    const Eigen::Vector2d projected_centre = ProjectBoardPoint(camera, T_station_camera, b, centre);
    result.worst_error_px = std::max(result.worst_error_px, (measured - expected).norm());
    result.worst_bias_px = std::max(result.worst_bias_px, (expected - projected_centre).norm());
    ++result.discs;
  }
  return result;
}

TEST(CameraRenderDiscs, PinholeCentroidsMatchTheProjectedDiscs) {
  // A circle board seen obliquely (35 degrees of yaw) and close, so that perspective moves
  // the centroid of a projected disc well away from the projected centre.
  StationLayout layout;
  layout.boards.push_back(MakeBoard("circles", BoardType::kCircle, 1.0,
                                    BoardPose(Eigen::Vector3d(1.1, 0.1, 1.45), 35, 0, 8)));
  const DiscResult r = MeasureDiscs(Pinhole(), CameraPose(), layout, GeometryOptions());
  EXPECT_EQ(r.discs, 28);
  EXPECT_LE(r.worst_error_px, kCentroidBarPx);
  // The configuration distinguishes the perspective-correct expectation from the projected
  // centre (otherwise the test above would not check perspective).
  EXPECT_GT(r.worst_bias_px, 5 * kCentroidBarPx);
  std::printf("pinhole discs: worst centroid error %.2e px, perspective bias up to %.3f px\n",
              r.worst_error_px, r.worst_bias_px);
}

TEST(CameraRenderDiscs, FisheyeCentroidsMatchTheProjectedDiscs) {
  StationLayout layout;
  layout.boards.push_back(MakeBoard("circles", BoardType::kCircle, 1.0,
                                    BoardPose(Eigen::Vector3d(0.7, 0.45, 1.3), 50, 10, -12)));
  const DiscResult r = MeasureDiscs(Fisheye(), CameraPose(), layout, GeometryOptions());
  EXPECT_EQ(r.discs, 28);
  EXPECT_LE(r.worst_error_px, kCentroidBarPx);
  EXPECT_GT(r.worst_bias_px, kCentroidBarPx);
  std::printf("fisheye discs: worst centroid error %.2e px, perspective bias up to %.3f px\n",
              r.worst_error_px, r.worst_bias_px);
}

// ---- Straight edges and corners ---------------------------------------------------------

// One edge of an ArUco marker's black square, from corner a to corner b (board frame).
struct MarkerEdge {
  Eigen::Vector2d a_board, b_board;
  Eigen::Vector2d inside_board;  // a point inside the marker, for the side of black
};

// Sub-pixel positions of one edge measured across it, one per pixel row (near-vertical
// edges) or column (near-horizontal ones), and the exact positions.
struct EdgeProfile {
  bool vertical = false;  // positions are u at rows v, else v at columns u
  std::vector<double> along, measured, expected;
};

// The exact mean position of the projected edge across the pixel line at `along`: the
// projected curve's crossing of each line at Gauss-Legendre nodes over [along - 0.5,
// along + 0.5] (5 nodes integrate the smooth crossing curve to ~1e-12 px), each found by
// bisection on the edge parameter.
double ExpectedCrossing(const CameraModel& camera, const Rigid3d& T_station_camera,
                        const StationBoard& b, const MarkerEdge& e, bool vertical, double along) {
  const auto uv_at = [&](double lambda) {
    return ProjectBoardPoint(camera, T_station_camera, b,
                             e.a_board + lambda * (e.b_board - e.a_board));
  };
  const int a_axis = vertical ? 1 : 0;  // the coordinate that runs along the edge
  const double nodes[5] = {-0.9061798459386640, -0.5384693101056831, 0.0, 0.5384693101056831,
                           0.9061798459386640};
  const double weights[5] = {0.2369268850561891, 0.4786286704993665, 0.5688888888888889,
                             0.4786286704993665, 0.2369268850561891};
  double mean = 0.0;
  for (int i = 0; i < 5; ++i) {
    const double target = along + 0.5 * nodes[i];
    double lo = 0.0, hi = 1.0;
    const bool increasing = uv_at(1.0)[a_axis] > uv_at(0.0)[a_axis];
    for (int k = 0; k < 60; ++k) {
      const double mid = 0.5 * (lo + hi);
      ((uv_at(mid)[a_axis] < target) == increasing ? lo : hi) = mid;
    }
    mean += 0.5 * weights[i] * uv_at(0.5 * (lo + hi))[1 - a_axis];
  }
  return mean;
}

// Measures edge e along every pixel line at least kCornerClearancePx from its ends: the
// sub-pixel position is where the coverage of the pixels across the edge puts it (the
// window's start plus the summed coverage of the paint on the low side). The window reaches
// kWindowPx either side of the edge: past a blurred edge's tail (4 sigma at sigma 1) and
// short of the marker's inner edges (the border cell is > 15 px wide in these views).
EdgeProfile MeasureEdge(const CameraModel& camera, const Rigid3d& T_station_camera,
                        const StationBoard& b, const MarkerEdge& e, const CameraFrame& frame) {
  constexpr double kCornerClearancePx = 5.0;
  constexpr int kWindowPx = 6;
  const Eigen::Vector2d ua = ProjectBoardPoint(camera, T_station_camera, b, e.a_board);
  const Eigen::Vector2d ub = ProjectBoardPoint(camera, T_station_camera, b, e.b_board);
  const Eigen::Vector2d inside = ProjectBoardPoint(camera, T_station_camera, b, e.inside_board);
  EdgeProfile p;
  p.vertical = std::abs(ub.y() - ua.y()) > std::abs(ub.x() - ua.x());
  const int along_axis = p.vertical ? 1 : 0, across_axis = 1 - along_axis;
  const double lo = std::min(ua[along_axis], ub[along_axis]) + kCornerClearancePx;
  const double hi = std::max(ua[along_axis], ub[along_axis]) - kCornerClearancePx;
  for (int line = static_cast<int>(std::ceil(lo)); line <= static_cast<int>(std::floor(hi));
       ++line) {
    const double expected = ExpectedCrossing(camera, T_station_camera, b, e, p.vertical, line);
    // Black on the low side of the edge if the marker's inside projects there (the marker
    // is convex and its edges nearly straight at this scale).
    const double edge_at_inside =
        ExpectedCrossing(camera, T_station_camera, b, e, p.vertical, inside[along_axis]);
    const bool black_low = inside[across_axis] < edge_at_inside;
    const int first = static_cast<int>(std::floor(expected)) - kWindowPx;
    double position = first - 0.5;
    for (int k = first; k <= first + 2 * kWindowPx; ++k) {
      const double white = p.vertical ? Grey(frame, k, line) : Grey(frame, line, k);
      position += black_low ? 1.0 - white : white;
    }
    p.along.push_back(line);
    p.measured.push_back(position);
    p.expected.push_back(expected);
  }
  return p;
}

// The four edges of each of the four markers of an ArUco board: features 4m..4m+3 are the
// corners top-left, top-right, bottom-right, bottom-left of marker m.
std::vector<MarkerEdge> MarkerEdges(const Board& board) {
  std::vector<MarkerEdge> edges;
  for (int m = 0; m < 4; ++m) {
    Eigen::Vector2d centre = Eigen::Vector2d::Zero();
    for (int k = 0; k < 4; ++k) centre += 0.25 * board.features()[4 * m + k].p_board;
    for (int k = 0; k < 4; ++k) {
      edges.push_back({board.features()[4 * m + k].p_board,
                       board.features()[4 * m + (k + 1) % 4].p_board, centre});
    }
  }
  return edges;
}

// Fits across = c0 + c1 t + ... + c_degree t^degree, t = along - t0, by least squares.
Eigen::VectorXd FitPolynomial(const std::vector<double>& along, const std::vector<double>& across,
                              int degree, double t0) {
  Eigen::MatrixXd a(along.size(), degree + 1);
  Eigen::VectorXd y(along.size());
  for (std::size_t i = 0; i < along.size(); ++i) {
    for (int k = 0; k <= degree; ++k) a(i, k) = std::pow(along[i] - t0, k);
    y(i) = across[i];
  }
  return a.colPivHouseholderQr().solve(y);
}

double EvalPolynomial(const Eigen::VectorXd& c, double t) {
  double v = 0.0;
  for (int k = static_cast<int>(c.size()) - 1; k >= 0; --k) v = v * t + c(k);
  return v;
}

struct EdgeResult {
  double worst_edge_px = 0.0;    // per-line position vs the exact projected edge
  double worst_line_px = 0.0;    // fitted line/curve vs the exact projected edge
  double worst_corner_px = 0.0;  // fitted curves' intersection vs the projected corner
  int lines = 0;
  int corners = 0;
};

// Renders an ArUco board and measures its 16 marker edges and corners. Near each corner the
// two edges are fitted (over kFitSpanPx from the corner) with polynomials of `degree`
// (1: straight lines for an undistorted pinhole; 3: lens-curved edges, whose quartic terms
// over 40 px are < 1e-4 px here) and intersected.
EdgeResult MeasureMarkers(const CameraModel& camera, const Rigid3d& T_station_camera,
                          const StationLayout& layout, const CameraRenderOptions& options,
                          int degree) {
  constexpr double kFitSpanPx = 40.0;
  const CameraFrame frame = Render(camera, T_station_camera, layout, options);
  // The whole board in view: every marker corner listed.
  EXPECT_EQ(frame.features.size(), 16u);
  const StationBoard& b = layout.boards[0];
  const std::vector<MarkerEdge> edges = MarkerEdges(b.board);
  std::vector<EdgeProfile> profiles;
  EdgeResult r;
  for (const MarkerEdge& e : edges) {
    profiles.push_back(MeasureEdge(camera, T_station_camera, b, e, frame));
    const EdgeProfile& p = profiles.back();
    for (std::size_t i = 0; i < p.along.size(); ++i) {
      r.worst_edge_px = std::max(r.worst_edge_px, std::abs(p.measured[i] - p.expected[i]));
      ++r.lines;
    }
  }
  // Corner k of marker m joins edge 4m + (k+3)%4 (ending there) and edge 4m + k (starting).
  for (int m = 0; m < 4; ++m) {
    for (int k = 0; k < 4; ++k) {
      const int feature = 4 * m + k;
      const Eigen::Vector2d corner =
          ProjectBoardPoint(camera, T_station_camera, b, b.board.features()[feature].p_board);
      std::array<Eigen::VectorXd, 2> fit;
      std::array<const EdgeProfile*, 2> prof = {&profiles[4 * m + (k + 3) % 4],
                                                &profiles[4 * m + k]};
      for (int j = 0; j < 2; ++j) {
        const EdgeProfile& p = *prof[j];
        const int axis = p.vertical ? 1 : 0;
        std::vector<double> along, across;
        for (std::size_t i = 0; i < p.along.size(); ++i) {
          if (std::abs(p.along[i] - corner[axis]) > kFitSpanPx) continue;
          along.push_back(p.along[i]);
          across.push_back(p.measured[i]);
        }
        fit[j] = FitPolynomial(along, across, degree, corner[axis]);
        // The fitted curve against the exact edge over the fitted span.
        for (std::size_t i = 0; i < along.size(); ++i) {
          const double exact = ExpectedCrossing(camera, T_station_camera, b,
                                                edges[&p - profiles.data()], p.vertical, along[i]);
          r.worst_line_px = std::max(
              r.worst_line_px, std::abs(EvalPolynomial(fit[j], along[i] - corner[axis]) - exact));
        }
      }
      // Intersect: one curve gives u(v), the other v(u) (adjacent edges of a square
      // cross at a large angle); fixed-point iteration from the projected corner.
      const bool first_vertical = prof[0]->vertical;
      if (first_vertical == prof[1]->vertical) {
        ADD_FAILURE() << "corner " << feature << ": both edges run the same way";
        continue;
      }
      const Eigen::VectorXd& u_of_v = first_vertical ? fit[0] : fit[1];
      const Eigen::VectorXd& v_of_u = first_vertical ? fit[1] : fit[0];
      Eigen::Vector2d x = corner;
      for (int it = 0; it < 50; ++it) {
        x.x() = corner.x() + EvalPolynomial(u_of_v, x.y() - corner.y()) - corner.x();
        x.y() = EvalPolynomial(v_of_u, x.x() - corner.x());
      }
      r.worst_corner_px = std::max(r.worst_corner_px, (x - corner).norm());
      ++r.corners;
    }
  }
  return r;
}

StationLayout ArucoLayout(const Rigid3d& pose) {
  StationLayout layout;
  layout.boards.push_back(MakeBoard("aruco", BoardType::kAruco, 1.0, pose));
  return layout;
}

// Every measured line, fitted curve and corner within the bars; the whole board measured.
void ExpectWithinBars(const EdgeResult& r, int min_lines, const char* what) {
  EXPECT_GT(r.lines, min_lines) << what;
  EXPECT_EQ(r.corners, 16) << what;
  EXPECT_LE(r.worst_edge_px, kEdgeBarPx) << what;
  EXPECT_LE(r.worst_line_px, kEdgeBarPx) << what;
  EXPECT_LE(r.worst_corner_px, kCornerBarPx) << what;
  std::printf("%s edges: %d lines, worst %.2e px; fitted curves %.2e px; corners %.2e px\n", what,
              r.lines, r.worst_edge_px, r.worst_line_px, r.worst_corner_px);
}

TEST(CameraRenderEdges, PinholeLinesAndCornersMatchTheProjection) {
  // Rolled and turned so that no edge is near an image axis; ~100 px markers.
  const StationLayout layout =
      ArucoLayout(BoardPose(Eigen::Vector3d(1.6, 0.05, 1.52), 25, -15, 17));
  ExpectWithinBars(MeasureMarkers(Pinhole(), CameraPose(), layout, GeometryOptions(), 1), 1000,
                   "pinhole");
}

TEST(CameraRenderEdges, DistortedPinholeEdgesMatchTheProjection) {
  // Barrel distortion of a wide-angle lens; the board off-centre, where it bends edges most.
  const StationLayout layout = ArucoLayout(BoardPose(Eigen::Vector3d(1.5, 0.3, 1.4), -20, 10, -8));
  ExpectWithinBars(MeasureMarkers(Pinhole(-0.3, 0.12), CameraPose(), layout, GeometryOptions(), 3),
                   1000, "distorted pinhole");
}

TEST(CameraRenderEdges, FisheyeEdgesMatchTheProjection) {
  // Off axis (about 40 degrees), where the fisheye bends edges visibly.
  const StationLayout layout = ArucoLayout(BoardPose(Eigen::Vector3d(0.9, -0.6, 1.1), -30, 15, 12));
  ExpectWithinBars(MeasureMarkers(Fisheye(), CameraPose(), layout, GeometryOptions(), 3), 500,
                   "fisheye");
}

TEST(CameraRenderEdges, BlurKeepsStraightEdgesInPlace) {
  // A symmetric kernel moves no straight edge: the coverage sum across it is unchanged.
  const StationLayout layout =
      ArucoLayout(BoardPose(Eigen::Vector3d(1.6, 0.05, 1.52), 25, -15, 17));
  CameraRenderOptions o = GeometryOptions();
  o.blur_sigma_px = 1.0;
  const EdgeResult r = MeasureMarkers(Pinhole(), CameraPose(), layout, o, 1);
  EXPECT_LE(r.worst_edge_px, kEdgeBarPx);
  EXPECT_LE(r.worst_corner_px, kCornerBarPx);
}

// ---- Dense patterns: every pixel against its exact coverage ------------------------------

// Area of the convex polygon `poly` clipped to the axis-aligned box [lo, hi]
// (Sutherland-Hodgman against the box's four sides, then the shoelace formula).
double ClippedArea(std::vector<Eigen::Vector2d> poly, const Eigen::Vector2d& lo,
                   const Eigen::Vector2d& hi) {
  for (int side = 0; side < 4 && !poly.empty(); ++side) {
    const int axis = side % 2;
    const bool keep_above = side < 2;
    const double bound = keep_above ? lo[axis] : hi[axis];
    const auto inside = [&](const Eigen::Vector2d& p) {
      return keep_above ? p[axis] >= bound : p[axis] <= bound;
    };
    std::vector<Eigen::Vector2d> out;
    for (std::size_t i = 0; i < poly.size(); ++i) {
      const Eigen::Vector2d& a = poly[i];
      const Eigen::Vector2d& b = poly[(i + 1) % poly.size()];
      if (inside(a)) out.push_back(a);
      if (inside(a) != inside(b))
        out.push_back(a + (bound - a[axis]) / (b[axis] - a[axis]) * (b - a));
    }
    poly = std::move(out);
  }
  double twice_area = 0.0;
  for (std::size_t i = 0; i < poly.size(); ++i) {
    const Eigen::Vector2d& a = poly[i];
    const Eigen::Vector2d& b = poly[(i + 1) % poly.size()];
    twice_area += a.x() * b.y() - b.x() * a.y();
  }
  return 0.5 * std::abs(twice_area);
}

// A checkerboard of sub-pixel to few-pixel squares, parallel to the image plane of an
// undistorted pinhole and rolled: each pixel's preimage on the board is then exactly the
// quadrilateral of its corners' preimages, and its white coverage is 1 minus the area of the
// black squares inside that quadrilateral over its area.
double WorstDenseCoverageError(double square_m) {
  const CameraModel camera = Pinhole();
  const Rigid3d T_station_camera = CameraPose();
  StationLayout layout;
  // 2 m ahead: 1 px is 3.33 mm on the board. The page centre projects at (321.3, 238.6),
  // near the principal point.
  layout.boards.push_back(
      Checker("dense", square_m, BoardPose(Eigen::Vector3d(2.0, 0.0, 1.5), 0, 0, 20)));
  StationBoard& b = layout.boards[0];
  b.params.cols = b.params.rows = 30;
  b.board = *Board::Create(b.params);
  const CameraFrame frame = Render(camera, T_station_camera, layout, GeometryOptions());
  const Rigid3d T_board_camera = b.T_station_board.Inverse() * T_station_camera;
  const auto preimage = [&](double u, double v) {
    Eigen::Vector3d ray;
    EXPECT_TRUE(camera.Unproject(Eigen::Vector2d(u, v), &ray));
    const Eigen::Vector3d o = T_board_camera.translation(), d = T_board_camera.rotation() * ray;
    return Eigen::Vector2d((o - o.z() / d.z() * d).head<2>());
  };
  // The pattern's extent (the black squares span (cols + 1) squares), inset by 2 px.
  const double half_pattern = 0.5 * (b.params.cols + 1) * square_m - 0.0067;
  double worst = 0.0;
  int pixels = 0;
  for (int y = 0; y < 480; ++y) {
    for (int x = 0; x < 640; ++x) {
      const std::vector<Eigen::Vector2d> quad = {
          preimage(x - 0.5, y - 0.5), preimage(x + 0.5, y - 0.5), preimage(x + 0.5, y + 0.5),
          preimage(x - 0.5, y + 0.5)};
      if (std::any_of(quad.begin(), quad.end(), [&](const Eigen::Vector2d& q) {
            return q.cwiseAbs().maxCoeff() > half_pattern;
          })) {
        continue;
      }
      double black = 0.0;
      for (const BoardShape& shape : b.board.shapes()) {
        if (shape.paint == Paint::kBlack)
          black += ClippedArea(quad, shape.box_board.min(), shape.box_board.max());
      }
      const double area =
          ClippedArea(quad, Eigen::Vector2d::Constant(-1), Eigen::Vector2d::Constant(1));
      worst = std::max(worst, std::abs(Grey(frame, x, y) - (1.0 - black / area)));
      ++pixels;
    }
  }
  EXPECT_GT(pixels, 500);
  return worst;
}

TEST(CameraRenderDense, EveryPixelHasItsExactCoverage) {
  // Squares of 1.3 px: nearly every pixel holds a corner where four squares meet, many hold
  // several edges. Corner pixels are split down to 1/32 px and the last cell point-sampled,
  // so a pixel may be off by a fraction of (1/32)^2 ~ 1e-3 per corner it holds.
  constexpr double kCornerPixelBar = 2e-3;
  const double fine = WorstDenseCoverageError(0.0043);
  EXPECT_LE(fine, kCornerPixelBar);
  // Squares of 4 px: about one pixel in four holds a corner.
  const double coarse = WorstDenseCoverageError(0.0133);
  EXPECT_LE(coarse, kCornerPixelBar);
  std::printf(
      "dense checkerboards: worst pixel coverage error %.2e (1.3 px squares), %.2e (4 px)\n", fine,
      coarse);
}

// ---- Ground truth ------------------------------------------------------------------------

// Where the sight line from the camera centre to p_station meets surface `pose`'s plane
// inside the rectangle of half sizes `half` (strictly between camera and point); an
// independent ray test for the expectations below.
bool SightLineHits(const Rigid3d& T_station_camera, const Eigen::Vector3d& p_station,
                   const Rigid3d& pose, const Eigen::Vector2d& half, Eigen::Vector2d* p_surface) {
  const Eigen::Vector3d o = pose.Inverse() * T_station_camera.translation();
  const Eigen::Vector3d q = pose.Inverse() * p_station;
  const double t = o.z() / (o.z() - q.z());
  if (!(t > 0.0 && t < 1.0)) return false;
  const Eigen::Vector3d x = o + t * (q - o);
  *p_surface = x.head<2>();
  return std::abs(x.x()) < half.x() && std::abs(x.y()) < half.y();
}

Eigen::Vector3d FeatureInStation(const StationBoard& b, int feature) {
  const Eigen::Vector2d& p = b.board.features()[feature].p_board;
  return b.T_station_board * Eigen::Vector3d(p.x(), p.y(), 0.0);
}

TEST(CameraRenderGroundTruth, ListsExactlyTheUnoccludedFeaturesInView) {
  const CameraModel camera = Pinhole();
  const Rigid3d T_station_camera = CameraPose();
  StationLayout layout;
  // 0: a checkerboard 3 m ahead; 1: a small ArUco board in front of part of it; 2: a board
  // behind the camera facing it; 3: a board in view whose print faces away.
  layout.boards.push_back(Checker("far", 0.08, BoardPose(Eigen::Vector3d(3.0, 0.1, 1.5), 5, 0, 3)));
  layout.boards.push_back(MakeBoard("near", BoardType::kAruco, 0.25,
                                    BoardPose(Eigen::Vector3d(1.8, 0.2, 1.45), 0, 0, 0)));
  layout.boards.push_back(
      Checker("behind", 0.08, BoardPose(Eigen::Vector3d(-3.0, 0, 1.5), 180, 0, 0)));
  layout.boards.push_back(
      Checker("away", 0.05, BoardPose(Eigen::Vector3d(3.0, -1.2, 1.5), 180, 0, 0)));
  CameraRenderOptions options;
  options.feature_margin_px = 3.0;
  const CameraFrame frame = Render(camera, T_station_camera, layout, options);

  // The expectation, from independent ray tests: in front of the camera and projecting 3 px
  // inside the image, printed face towards the camera, sight line clear of the near
  // board's page (it has no holes, so its whole page is opaque).
  const StationBoard& near = layout.boards[1];
  const Eigen::Vector2d near_half = 0.5 * near.board.page_size_m();
  std::set<std::pair<int, int>> expected;
  int hidden = 0;
  for (int b = 0; b < 4; ++b) {
    const StationBoard& board = layout.boards[b];
    const Eigen::Vector3d n_station = board.T_station_board.rotation() * Eigen::Vector3d::UnitZ();
    for (const BoardFeature& f : board.board.features()) {
      const Eigen::Vector3d p = FeatureInStation(board, f.id);
      const Eigen::Vector3d p_camera = T_station_camera.Inverse() * p;
      Eigen::Vector2d uv;
      if (p_camera.z() <= 0 || !camera.Project(p_camera, &uv)) continue;
      if (uv.x() < 2.5 || uv.x() > 636.5 || uv.y() < 2.5 || uv.y() > 476.5) continue;
      if (n_station.dot(T_station_camera.translation() - p) <= 0) continue;
      Eigen::Vector2d on_near;
      if (b != 1 && SightLineHits(T_station_camera, p, near.T_station_board, near_half, &on_near)) {
        ++hidden;
        continue;
      }
      expected.insert({b, f.id});
    }
  }
  std::set<std::pair<int, int>> listed;
  for (const RenderedFeature& f : frame.features) {
    listed.insert({f.board_index, f.feature_id});
    EXPECT_EQ(f.board_id, layout.boards[f.board_index].id);
    EXPECT_EQ(f.kind, layout.boards[f.board_index].board.features()[f.feature_id].kind);
    // The exact projection, and inside the image by the margin.
    Eigen::Vector2d uv;
    ASSERT_TRUE(camera.Project(
        T_station_camera.Inverse() * FeatureInStation(layout.boards[f.board_index], f.feature_id),
        &uv));
    EXPECT_LE((f.uv_px - uv).norm(), kRoundingPx);
    EXPECT_GE(f.uv_px.x(), -0.5 + options.feature_margin_px);
    EXPECT_LE(f.uv_px.x(), 639.5 - options.feature_margin_px);
    EXPECT_GE(f.uv_px.y(), -0.5 + options.feature_margin_px);
    EXPECT_LE(f.uv_px.y(), 479.5 - options.feature_margin_px);
    EXPECT_TRUE(f.board_index == 0 || f.board_index == 1) << f.board_id;
  }
  EXPECT_EQ(listed, expected);
  // The scene exercises every rule: some far features hidden, some seen, all near ones.
  EXPECT_GT(hidden, 5);
  EXPECT_GT(std::count_if(listed.begin(), listed.end(), [](auto& f) { return f.first == 0; }), 5);
  EXPECT_EQ(std::count_if(listed.begin(), listed.end(), [](auto& f) { return f.first == 1; }), 16);
  // Sorted by board, then feature id.
  EXPECT_TRUE(std::is_sorted(frame.features.begin(), frame.features.end(),
                             [](const RenderedFeature& a, const RenderedFeature& b) {
                               return std::pair(a.board_index, a.feature_id) <
                                      std::pair(b.board_index, b.feature_id);
                             }));
}

TEST(CameraRenderGroundTruth, FisheyeListsWhatItSeesBehindItsImagePlaneOnly) {
  // The ~190 degree fisheye's image reaches ~103 degrees off axis (its valid region 143):
  // it sees a board beside it partly behind its image plane (z < 0), and nothing of a
  // board straight behind it.
  const CameraModel camera = Fisheye();
  const Rigid3d T_station_camera = CameraPose();
  StationLayout layout;
  layout.boards.push_back(
      Checker("behind", 0.08, BoardPose(Eigen::Vector3d(-2.0, 0, 1.5), 180, 0, 0)));
  layout.boards.push_back(
      Checker("beside", 0.04, BoardPose(Eigen::Vector3d(-0.2, 1.0, 1.5), 90, 0, 0)));
  const CameraRenderOptions options;
  const CameraFrame frame = Render(camera, T_station_camera, layout, options);
  std::set<int> expected;
  const StationBoard& beside = layout.boards[1];
  for (const BoardFeature& f : beside.board.features()) {
    const Eigen::Vector3d p_camera = T_station_camera.Inverse() * FeatureInStation(beside, f.id);
    Eigen::Vector2d uv;
    if (!camera.Project(p_camera, &uv)) continue;
    const double m = options.feature_margin_px;
    if (uv.x() >= -0.5 + m && uv.x() <= 1279.5 - m && uv.y() >= -0.5 + m && uv.y() <= 959.5 - m) {
      expected.insert(f.id);
    }
  }
  std::set<int> listed;
  int behind_image_plane = 0;
  for (const RenderedFeature& f : frame.features) {
    EXPECT_EQ(f.board_index, 1);
    listed.insert(f.feature_id);
    const Eigen::Vector3d p_camera =
        T_station_camera.Inverse() * FeatureInStation(beside, f.feature_id);
    if (p_camera.z() < 0) ++behind_image_plane;
  }
  EXPECT_EQ(listed, expected);
  EXPECT_GT(behind_image_plane, 0);
  // Part of the board lies beyond the image's edge.
  EXPECT_LT(listed.size(), beside.board.features().size());
}

TEST(CameraRenderGroundTruth, OccludersHideTheFeaturesBehindThem) {
  const CameraModel camera = Pinhole();
  const Rigid3d T_station_camera = CameraPose();
  StationLayout layout;
  layout.boards.push_back(Checker("board", 0.1, BoardPose(Eigen::Vector3d(2.5, 0, 1.5), 10, 0, 5)));
  CameraRenderOptions options = GeometryOptions();
  options.occluder_count = 4;
  options.occluder_size_px = 60;
  const CameraFrame frame = Render(camera, T_station_camera, layout, options, 3);
  ASSERT_EQ(frame.occluders.size(), 4u);
  const std::vector<RenderedFeature> all =
      VisibleCameraFeatures(camera, T_station_camera, layout, {}, options.feature_margin_px);
  std::vector<int> hides(frame.occluders.size(), 0);
  std::set<int> expected;
  int checked_pixels = 0;
  for (const RenderedFeature& f : all) {
    const Eigen::Vector3d p = FeatureInStation(layout.boards[0], f.feature_id);
    // The nearest occluder on the sight line, if any.
    int nearest = -1;
    double nearest_distance = kInf;
    Eigen::Vector2d nearest_hit;
    for (std::size_t i = 0; i < frame.occluders.size(); ++i) {
      const StationSurface& o = frame.occluders[i];
      Eigen::Vector2d hit;
      if (!SightLineHits(T_station_camera, p, o.T_station_surface, 0.5 * o.size_m, &hit)) continue;
      ++hides[i];
      const double distance = (o.T_station_surface * Eigen::Vector3d(hit.x(), hit.y(), 0) -
                               T_station_camera.translation())
                                  .norm();
      if (distance < nearest_distance) {
        nearest = static_cast<int>(i);
        nearest_distance = distance;
        nearest_hit = hit;
      }
    }
    if (nearest < 0) {
      expected.insert(f.feature_id);
      continue;
    }
    // Well inside the occluder (80% of its half sizes), the pixel shows its grey.
    const StationSurface& o = frame.occluders[nearest];
    if (std::abs(nearest_hit.x()) < 0.4 * o.size_m.x() &&
        std::abs(nearest_hit.y()) < 0.4 * o.size_m.y()) {
      const int x = static_cast<int>(std::lround(f.uv_px.x())),
                y = static_cast<int>(std::lround(f.uv_px.y()));
      EXPECT_NEAR(frame.image16.at(x, y), o.reflectivity * kFull16, 0.5) << o.id;
      ++checked_pixels;
    }
  }
  std::set<int> listed;
  for (const RenderedFeature& f : frame.features) listed.insert(f.feature_id);
  EXPECT_EQ(listed, expected);
  // Each occluder stands on the line of sight of a feature it was placed on.
  for (std::size_t i = 0; i < hides.size(); ++i) EXPECT_GE(hides[i], 1) << frame.occluders[i].id;
  EXPECT_GE(checked_pixels, 4);
  for (const StationSurface& o : frame.occluders) {
    EXPECT_GE(o.reflectivity, 0.0);
    EXPECT_LE(o.reflectivity, 1.0);
    EXPECT_GT(o.size_m.minCoeff(), 0.0);
  }
}

// ---- The scene's looks ---------------------------------------------------------------------

TEST(CameraRenderScene, HolesBacksWallsFloorAndBackground) {
  const CameraModel camera = Pinhole();
  const Rigid3d T_station_camera = CameraPose();
  StationLayout layout;
  layout.floor_reflectivity = 0.15;
  layout.boards.push_back(MakeBoard("holes", BoardType::kRoundHole, 0.5,
                                    BoardPose(Eigen::Vector3d(2.0, 0.25, 1.5), 0, 0, 0)));
  // Seen from behind: its print faces +x, away from the camera.
  layout.boards.push_back(
      Checker("back", 0.05, BoardPose(Eigen::Vector3d(2.5, -0.6, 1.5), 180, 0, 0)));
  StationSurface wall;
  wall.id = "wall";
  wall.T_station_surface = BoardPose(Eigen::Vector3d(4.0, 0, 1.5), 0, 0, 0);
  wall.size_m = Eigen::Vector2d(4.0, 2.0);
  wall.reflectivity = 0.3;
  layout.surfaces.push_back(wall);
  CameraRenderOptions o = GeometryOptions();
  o.board_back_reflectance = 0.4;
  o.background_reflectance = 0.2;
  const CameraFrame frame = Render(camera, T_station_camera, layout, o);
  const auto level = [&](const Eigen::Vector2d& uv) {
    return frame.image16.at(static_cast<int>(std::lround(uv.x())),
                            static_cast<int>(std::lround(uv.y())));
  };
  // Through the holes: the wall.
  int holes = 0;
  for (const RenderedFeature& f : frame.features) {
    if (f.kind != FeatureKind::kHoleCentre) continue;
    EXPECT_NEAR(level(f.uv_px), 0.3 * kFull16, 0.5);
    ++holes;
  }
  EXPECT_EQ(holes, 5);
  // The back of the second board, at its centre.
  EXPECT_NEAR(
      level(ProjectBoardPoint(camera, T_station_camera, layout.boards[1], Eigen::Vector2d::Zero())),
      0.4 * kFull16, 0.5);
  // Straight up: nothing; straight down at the bottom row: the floor.
  EXPECT_NEAR(frame.image16.at(320, 0), 0.2 * kFull16, 0.5);
  EXPECT_NEAR(frame.image16.at(320, 479), 0.15 * kFull16, 0.5);
}

TEST(CameraRenderScene, ClutterBelongsToTheWallsNotToTheFrame) {
  const CameraModel camera = Pinhole();
  StationLayout layout;
  layout.surfaces.push_back(Wall(3.0, 0.5));
  CameraRenderOptions o;
  const CameraFrame plain = Render(camera, CameraPose(), layout, o, 1);
  o.clutter = true;
  const CameraFrame a = Render(camera, CameraPose(), layout, o, 1);
  const CameraFrame b = Render(camera, CameraPose(), layout, o, 2);
  o.clutter_seed = 2;
  const CameraFrame c = Render(camera, CameraPose(), layout, o, 1);
  std::set<int> plain_levels(plain.image8.pixels.begin(), plain.image8.pixels.end());
  std::set<int> clutter_levels(a.image8.pixels.begin(), a.image8.pixels.end());
  EXPECT_EQ(plain_levels.size(), 1u);
  // Objects of many greys, anti-aliased edges in between.
  EXPECT_GT(clutter_levels.size(), 100u);
  EXPECT_EQ(a.image8.pixels, b.image8.pixels);  // another frame seed: the same walls
  EXPECT_NE(a.image8.pixels, c.image8.pixels);  // another clutter seed: other walls
}

// ---- Camera response ---------------------------------------------------------------------

TEST(CameraRenderResponse, SameSeedSameBytesWhateverTheThreads) {
  const CameraModel camera = Pinhole(-0.1, 0.02);
  StationLayout layout;
  layout.boards.push_back(
      Checker("board", 0.06, BoardPose(Eigen::Vector3d(2.0, 0, 1.4), 15, 5, 10)));
  layout.surfaces.push_back(Wall(5.0, 0.5));
  CameraRenderOptions o;
  o.clutter = true;
  o.occluder_count = 2;
  o.illumination_gradient_ratio = 2.5;
  o.vignetting = 0.3;
  o.blur_sigma_px = 0.8;
  o.gamma = 1.4;
  o.noise_sigma = 3.0;
  o.jpeg_quality = 85;
  o.threads = 1;
  const CameraFrame one = Render(camera, CameraPose(), layout, o, 11);
  const CameraFrame again = Render(camera, CameraPose(), layout, o, 11);
  o.threads = 2;
  const CameraFrame two = Render(camera, CameraPose(), layout, o, 11);
  const CameraFrame other = Render(camera, CameraPose(), layout, o, 12);
  EXPECT_EQ(one.image8.pixels, again.image8.pixels);
  EXPECT_EQ(one.image8.pixels, two.image8.pixels);
  EXPECT_NE(one.image8.pixels, other.image8.pixels);
  ASSERT_EQ(one.occluders.size(), 2u);
  ASSERT_EQ(other.occluders.size(), 2u);
  EXPECT_NE(one.occluders[0].T_station_surface.translation(),
            other.occluders[0].T_station_surface.translation());
}

// A camera facing a uniform wall (which fills its view) of reflectance 0.5.
CameraFrame WallFrame(const CameraRenderOptions& o, std::uint64_t seed = 1) {
  StationLayout layout;
  layout.surfaces.push_back(Wall(2.0, 0.5));
  return Render(Pinhole(), CameraPose(), layout, o, seed);
}

template <typename T>
std::pair<double, double> MeanAndSigma(const std::vector<T>& pixels, double scale) {
  double sum = 0.0, sum_sq = 0.0;
  for (T p : pixels) {
    sum += p / scale;
    sum_sq += (p / scale) * (p / scale);
  }
  const double mean = sum / pixels.size();
  return {mean, std::sqrt(sum_sq / pixels.size() - mean * mean)};
}

TEST(CameraRenderResponse, NoiseHasTheRequestedSigma) {
  // 307200 samples estimate sigma to 0.13% (1 / sqrt(2N)); 1% is 7 standard errors.
  constexpr double kSigmaRelative = 0.01;
  CameraRenderOptions o;
  o.noise_sigma = 3.0;
  o.bit_depth = 16;
  const auto [mean16, sigma16] = MeanAndSigma(WallFrame(o).image16.pixels, 257.0);
  EXPECT_NEAR(sigma16, 3.0, kSigmaRelative * 3.0);
  EXPECT_NEAR(mean16, 0.5 * 255, 0.05);
  // 8 bits add the rounding's 1/12 grey level^2.
  o.noise_sigma = 2.0;
  o.bit_depth = 8;
  const auto [mean8, sigma8] = MeanAndSigma(WallFrame(o).image8.pixels, 1.0);
  EXPECT_NEAR(sigma8, std::sqrt(4.0 + 1.0 / 12), kSigmaRelative * 2.0);
  // Another seed, other noise.
  EXPECT_NE(WallFrame(o, 1).image8.pixels, WallFrame(o, 2).image8.pixels);
}

TEST(CameraRenderResponse, GradientAndVignettingAsRequested) {
  CameraRenderOptions o;
  o.bit_depth = 16;
  o.illumination_gradient_ratio = 3.0;
  o.illumination_gradient_direction_deg = 30.0;
  const CameraFrame f = WallFrame(o);
  // log(grey) is linear in (u, v); fit it and read off the ratio between the extreme
  // pixels along the fitted direction, and the direction.
  Eigen::MatrixXd a(640 * 480, 3);
  Eigen::VectorXd b(640 * 480);
  for (int y = 0; y < 480; ++y) {
    for (int x = 0; x < 640; ++x) {
      a.row(y * 640 + x) << 1.0, x, y;
      b(y * 640 + x) = std::log(f.image16.at(x, y));
    }
  }
  const Eigen::Vector3d c = a.colPivHouseholderQr().solve(b);
  const double lo = std::min({0.0, 639 * c(1), 479 * c(2), 639 * c(1) + 479 * c(2)});
  const double hi = std::max({0.0, 639 * c(1), 479 * c(2), 639 * c(1) + 479 * c(2)});
  // 16-bit rounding of greys >= 0.29 of full scale is < 3e-5 relative.
  EXPECT_NEAR(std::exp(hi - lo), 3.0, 1e-3);
  EXPECT_NEAR(std::atan2(c(2), c(1)) / kDeg, 30.0, 0.01);
  // Vignetting: the corner pixels are darker than the principal point's by the requested
  // fraction of (r / r_max)^2, r_max the distance to the farthest image corner.
  o.illumination_gradient_ratio = 1.0;
  o.vignetting = 0.4;
  const CameraFrame v = WallFrame(o);
  const Eigen::Vector2d pp(321.3, 238.6);
  const double r2_max = (Eigen::Vector2d(-0.5, 479.5) - pp).squaredNorm();
  const double centre = v.image16.at(321, 239);
  for (const auto& [x, y] :
       {std::pair(0, 0), std::pair(639, 0), std::pair(0, 479), std::pair(639, 479)}) {
    const double expected = (1 - 0.4 * (Eigen::Vector2d(x, y) - pp).squaredNorm() / r2_max) /
                            (1 - 0.4 * (Eigen::Vector2d(321, 239) - pp).squaredNorm() / r2_max);
    EXPECT_NEAR(v.image16.at(x, y) / centre, expected, 1e-4) << x << "," << y;
  }
}

TEST(CameraRenderResponse, GammaEncodesLinearLight) {
  CameraRenderOptions o;
  o.bit_depth = 16;
  o.gamma = 2.2;
  const CameraFrame f = WallFrame(o);
  EXPECT_NEAR(f.image16.at(100, 100), std::pow(0.5, 1 / 2.2) * kFull16, 0.5);
}

TEST(CameraRenderResponse, JpegQuantisationIsBoundedAndFaithfulAtHighQuality) {
  StationLayout layout;
  layout.boards.push_back(
      Checker("board", 0.04, BoardPose(Eigen::Vector3d(1.5, 0, 1.5), 20, 0, 10)));
  layout.surfaces.push_back(Wall(4.0, 0.5));
  CameraRenderOptions o;
  o.clutter = true;
  const CameraFrame plain = Render(Pinhole(), CameraPose(), layout, o);
  const auto rms_difference = [&](int quality) {
    o.jpeg_quality = quality;
    const CameraFrame f = Render(Pinhole(), CameraPose(), layout, o);
    double sum_sq = 0.0;
    for (std::size_t i = 0; i < f.image8.pixels.size(); ++i) {
      const double d = f.image8.pixels[i] - plain.image8.pixels[i];
      sum_sq += d * d;
    }
    return std::sqrt(sum_sq / f.image8.pixels.size());
  };
  // At quality 100 every coefficient is rounded to an integer: an orthonormal DCT carries
  // that uniform rounding (RMS sqrt(1/12) = 0.29 levels) to the pixels; with the final
  // rounding to 8 bits the difference stays below half a level.
  const double q100 = rms_difference(100);
  EXPECT_GT(q100, 0.0);
  EXPECT_LT(q100, 0.5);
  // Quality 80 quantises high frequencies coarsely: visibly more, still a few levels.
  const double q80 = rms_difference(80);
  EXPECT_GT(q80, 2 * q100);
  EXPECT_LT(q80, 8.0);
}

// ---- Validation ----------------------------------------------------------------------------

TEST(CameraRenderOptionsTest, DefaultsAreValid) {
  EXPECT_TRUE(CameraRenderOptions().Validate().ok());
}

TEST(CameraRenderOptionsTest, ErrorsNameTheField) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<std::pair<std::string, std::function<void(CameraRenderOptions&)>>> cases = {
      {"edge_probes_per_side", [](auto& o) { o.edge_probes_per_side = 1; }},
      {"edge_tolerance_px", [](auto& o) { o.edge_tolerance_px = 0.0; }},
      {"max_subdivision_depth", [](auto& o) { o.max_subdivision_depth = 11; }},
      {"white_reflectance", [](auto& o) { o.white_reflectance = 1.5; }},
      {"black_reflectance", [](auto& o) { o.black_reflectance = 0.9; }},
      {"board_back_reflectance", [](auto& o) { o.board_back_reflectance = -0.1; }},
      {"background_reflectance", [&](auto& o) { o.background_reflectance = nan; }},
      {"illumination", [](auto& o) { o.illumination = 0.0; }},
      {"illumination_gradient_ratio", [](auto& o) { o.illumination_gradient_ratio = 5.0; }},
      {"illumination_gradient_direction_deg",
       [](auto& o) { o.illumination_gradient_direction_deg = kInf; }},
      {"vignetting", [](auto& o) { o.vignetting = 1.0; }},
      {"blur_sigma_px", [](auto& o) { o.blur_sigma_px = -1.0; }},
      {"gamma", [](auto& o) { o.gamma = 0.0; }},
      {"noise_sigma", [](auto& o) { o.noise_sigma = 100.0; }},
      {"jpeg_quality", [](auto& o) { o.jpeg_quality = 50; }},
      {"bit_depth", [](auto& o) { o.bit_depth = 12; }},
      {"clutter_density", [](auto& o) { o.clutter_density = 0.0; }},
      {"occluder_count", [](auto& o) { o.occluder_count = 65; }},
      {"occluder_size_px", [](auto& o) { o.occluder_size_px = 0.0; }},
      {"feature_margin_px", [](auto& o) { o.feature_margin_px = -1.0; }},
      {"threads", [](auto& o) { o.threads = 0; }},
  };
  StationLayout layout;
  for (const auto& [field, set] : cases) {
    CameraRenderOptions o;
    set(o);
    const absl::Status s = o.Validate();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << field;
    EXPECT_EQ(std::string(s.message()).rfind(field + " = ", 0), 0u) << s.message();
    const absl::StatusOr<CameraFrame> frame =
        RenderCameraFrame(Pinhole(), CameraPose(), layout, o, 1);
    EXPECT_EQ(frame.status(), s);
  }
}

TEST(CameraRenderOptionsTest, BadPoseAndLayoutAreRefused) {
  StationLayout layout;
  const absl::StatusOr<CameraFrame> pose =
      RenderCameraFrame(Pinhole(), Rigid3d::Translation(Eigen::Vector3d(kInf, 0, 0)), layout,
                        CameraRenderOptions(), 1);
  EXPECT_EQ(pose.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(pose.status().message()).rfind("T_station_camera", 0), 0u);
  layout.surfaces.push_back(Wall(2.0, 0.5));
  layout.surfaces[0].size_m.x() = 0.0;
  const absl::StatusOr<CameraFrame> size =
      RenderCameraFrame(Pinhole(), CameraPose(), layout, CameraRenderOptions(), 1);
  EXPECT_EQ(size.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(size.status().message()).rfind("surfaces[0] 'wall': size_m", 0), 0u)
      << size.status();
  layout.surfaces[0].size_m.x() = 1.0;
  layout.surfaces[0].reflectivity = 2.0;
  const absl::StatusOr<CameraFrame> reflectivity =
      RenderCameraFrame(Pinhole(), CameraPose(), layout, CameraRenderOptions(), 1);
  EXPECT_EQ(
      std::string(reflectivity.status().message()).rfind("surfaces[0] 'wall'.reflectivity", 0), 0u)
      << reflectivity.status();
}

}  // namespace
}  // namespace linecal

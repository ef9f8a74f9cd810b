// The camera renderer checked against geometry: rendered discs and edges against exact
// projections through the camera model, ground-truth features against independent ray
// tests, and the camera response against its definition.
#include "station/sim/camera_render.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Dense>

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

// The camera 1.5 m above the station origin, looking along +x (conventions.md's camera
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

// A wall facing -x (towards the camera) at distance x, big enough to fill any view.
[[maybe_unused]] StationSurface Wall(double x, double reflectivity) {
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
  const Eigen::Vector3d p_camera = T_station_camera.Inverse() *
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
    polygon.push_back(ProjectBoardPoint(camera, T_station_camera, b,
                                        centre + radius * Eigen::Vector2d(std::cos(a), std::sin(a))));
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
    return ProjectBoardPoint(camera, T_station_camera, b, e.a_board + lambda * (e.b_board - e.a_board));
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
  for (int line = static_cast<int>(std::ceil(lo)); line <= static_cast<int>(std::floor(hi)); ++line) {
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
      std::array<const EdgeProfile*, 2> prof = {&profiles[4 * m + (k + 3) % 4], &profiles[4 * m + k]};
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
          const double exact = ExpectedCrossing(camera, T_station_camera, b, edges[&p - profiles.data()],
                                                p.vertical, along[i]);
          r.worst_line_px = std::max(r.worst_line_px,
                                     std::abs(EvalPolynomial(fit[j], along[i] - corner[axis]) - exact));
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

TEST(CameraRenderEdges, PinholeLinesAndCornersMatchTheProjection) {
  // Rolled and turned so that no edge is near an image axis; ~100 px markers.
  const StationLayout layout = ArucoLayout(BoardPose(Eigen::Vector3d(1.6, 0.05, 1.52), 25, -15, 17));
  const EdgeResult r = MeasureMarkers(Pinhole(), CameraPose(), layout, GeometryOptions(), 1);
  EXPECT_GT(r.lines, 1000);
  EXPECT_EQ(r.corners, 16);
  EXPECT_LE(r.worst_edge_px, kEdgeBarPx);
  EXPECT_LE(r.worst_line_px, kEdgeBarPx);
  EXPECT_LE(r.worst_corner_px, kCornerBarPx);
  std::printf("pinhole edges: %d lines, worst %.2e px; fitted lines %.2e px; corners %.2e px\n",
              r.lines, r.worst_edge_px, r.worst_line_px, r.worst_corner_px);
}

TEST(CameraRenderEdges, DistortedPinholeEdgesMatchTheProjection) {
  // Barrel distortion of a wide-angle lens; the board off-centre, where it bends edges most.
  const StationLayout layout = ArucoLayout(BoardPose(Eigen::Vector3d(1.5, 0.3, 1.4), -20, 10, -8));
  const EdgeResult r =
      MeasureMarkers(Pinhole(-0.3, 0.12), CameraPose(), layout, GeometryOptions(), 3);
  EXPECT_GT(r.lines, 1000);
  EXPECT_EQ(r.corners, 16);
  EXPECT_LE(r.worst_edge_px, kEdgeBarPx);
  EXPECT_LE(r.worst_line_px, kEdgeBarPx);
  EXPECT_LE(r.worst_corner_px, kCornerBarPx);
  std::printf("distorted pinhole edges: %d lines, worst %.2e px; fits %.2e px; corners %.2e px\n",
              r.lines, r.worst_edge_px, r.worst_line_px, r.worst_corner_px);
}

TEST(CameraRenderEdges, FisheyeEdgesMatchTheProjection) {
  // Off axis (about 40 degrees), where the fisheye bends edges visibly.
  const StationLayout layout = ArucoLayout(BoardPose(Eigen::Vector3d(0.9, -0.6, 1.1), -30, 15, 12));
  const EdgeResult r = MeasureMarkers(Fisheye(), CameraPose(), layout, GeometryOptions(), 3);
  EXPECT_GT(r.lines, 500);
  EXPECT_EQ(r.corners, 16);
  EXPECT_LE(r.worst_edge_px, kEdgeBarPx);
  EXPECT_LE(r.worst_line_px, kEdgeBarPx);
  EXPECT_LE(r.worst_corner_px, kCornerBarPx);
  std::printf("fisheye edges: %d lines, worst %.2e px; fits %.2e px; corners %.2e px\n", r.lines,
              r.worst_edge_px, r.worst_line_px, r.worst_corner_px);
}

TEST(CameraRenderEdges, BlurKeepsStraightEdgesInPlace) {
  // A symmetric kernel moves no straight edge: the coverage sum across it is unchanged.
  const StationLayout layout = ArucoLayout(BoardPose(Eigen::Vector3d(1.6, 0.05, 1.52), 25, -15, 17));
  CameraRenderOptions o = GeometryOptions();
  o.blur_sigma_px = 1.0;
  const EdgeResult r = MeasureMarkers(Pinhole(), CameraPose(), layout, o, 1);
  EXPECT_LE(r.worst_edge_px, kEdgeBarPx);
  EXPECT_LE(r.worst_corner_px, kCornerBarPx);
}

}  // namespace
}  // namespace linecal

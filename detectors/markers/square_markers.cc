#include "detectors/markers/square_markers.h"

#include <apriltag/tag36h11.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <span>

#include "detectors/boards/aruco_dictionaries.h"
#include "detectors/common/binarise.h"
#include "detectors/common/contours.h"
#include "detectors/common/edge_lines.h"
#include "detectors/common/homography.h"
#include "detectors/common/image_filters.h"
#include "detectors/common/paint_check.h"
#include "detectors/markers/page_edge_fit.h"

namespace linecal {
namespace {

// Refines a quad's corners (clockwise in the image, dark inside, family.cells cells a side)
// by fitting a line to each side's edge and intersecting neighbouring lines. Edge points:
// along the side's outward normal, the centroid of the positive grey-level gradient (dark
// inside to light outside) within a window of half the dark band's width behind the edge
// (the next edge inside the marker is that far away; at least 1 px, at most 4 px: beyond
// that only the tail of the blur is seen), at `samples` points spread over the side between
// its corner cells (the corners are blurred and may touch other shapes).
// `light`: the marker's cells in the quad's own orientation (row-major, 1 = light) once
// decoded, else nullptr. With it, the dark band is known per cell (the border, plus the data
// cell behind it when that is dark) and only points with the widest band are used when
// there are enough of them: a narrow band lets the inner edge pull the centroid.
// `curved_sides`: each side's edge points are fitted with a parabola instead of a line, and
// the corners put where the parabolas' tangents meet: a side seen through a strong lens bends
// by a few tenths of a pixel, which a line turns into a corner error of that size.
// Returns false when a side has too few edge points or a corner moves more than
// max_move_cells cells.
// A side's edge as a parabola in the side's frame: m(s) = c0 + c1 s + c2 s^2, s along the side
// from its first corner, m along its outward normal.
struct SideCurve {
  Eigen::Vector2d a = Eigen::Vector2d::Zero();
  Eigen::Vector2d d = Eigen::Vector2d::UnitX();
  Eigen::Vector2d n = Eigen::Vector2d::UnitY();
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
};

// The weighted least-squares parabola through the edge points of a side (frame a, d, n);
// nullopt when it is singular. O(points).
std::optional<SideCurve> FitSideCurve(std::span<const EdgePoint> points, const Eigen::Vector2d& a,
                                      const Eigen::Vector2d& d, const Eigen::Vector2d& n) {
  Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (const EdgePoint& e : points) {
    const double t = (e.uv_px - a).dot(d);
    const Eigen::Vector3d row(1.0, t, t * t);
    normal += e.weight * row * row.transpose();
    rhs += e.weight * row * (e.uv_px - a).dot(n);
  }
  const Eigen::LDLT<Eigen::Matrix3d> solve(normal);
  if (solve.info() != Eigen::Success || !solve.isPositive()) return std::nullopt;
  SideCurve curve{a, d, n, solve.solve(rhs)};
  if (!curve.c.allFinite()) return std::nullopt;
  return curve;
}

// The tangent of a side's curve at s. O(1).
Line2d TangentAt(const SideCurve& curve, double t) {
  const Eigen::Vector3d& c = curve.c;
  Line2d line;
  line.point = curve.a + t * curve.d + (c(0) + c(1) * t + c(2) * t * t) * curve.n;
  line.dir = (curve.d + (c(1) + 2.0 * c(2) * t) * curve.n).normalized();
  return line;
}

bool RefineQuadCorners(const ImageView8& image, const MarkerFamily& family,
                       const std::vector<std::uint8_t>* light, int samples, double max_move_cells,
                       std::array<Eigen::Vector2d, 4>* corners, bool curved_sides = false) {
  const int cells = family.cells;
  const int border = family.border_cells;
  std::array<Line2d, 4> lines;
  std::array<SideCurve, 4> curves;
  std::array<double, 4> lengths{};
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d a = (*corners)[k];
    const Eigen::Vector2d b = (*corners)[(k + 1) % 4];
    const double len = (b - a).norm();
    if (len < 2.0) return false;
    const Eigen::Vector2d d = (b - a) / len;
    // The cell size across this side: the mean length of the two neighbouring sides.
    const double across_px =
        0.5 * (((*corners)[(k + 2) % 4] - b).norm() + (a - (*corners)[(k + 3) % 4]).norm()) / cells;
    const Eigen::Vector2d n(d.y(), -d.x());  // outward for a clockwise, y-down quad
    // Per sample: the dark band behind the edge, in cells.
    std::vector<int> band(samples, border);
    int widest = border;
    if (light != nullptr) {
      for (int i = 0; i < samples; ++i) {
        const double t = (border + (cells - 2.0 * border) * (i + 0.5) / samples) / cells;
        const int along = std::min(static_cast<int>(t * cells), cells - 1);
        // The cell behind the border at this point of side k (corner k is the quad's
        // top-left when k = 0; the sides run clockwise).
        int r = 0;
        int c = 0;
        switch (k) {
          case 0:
            r = border, c = along;
            break;
          case 1:
            r = along, c = cells - 1 - border;
            break;
          case 2:
            r = cells - 1 - border, c = cells - 1 - along;
            break;
          default:
            r = cells - 1 - along, c = border;
            break;
        }
        if ((*light)[static_cast<std::size_t>(r) * cells + c] == 0) band[i] = border + 1;
        widest = std::max(widest, band[i]);
      }
      // The wide points alone must still fix the line's direction: at least four of them,
      // spread over half the side (its length, corner to corner: the line is extrapolated to
      // the corners, so a short spread multiplies the points' scatter; the wide points of a
      // tag of 4 px bits, over a quarter of its side and within 0.3 px of its edge, tilted it
      // by 2 px). Otherwise use all.
      int first_wide = samples;
      int last_wide = -1;
      int wide_count = 0;
      for (int i = 0; i < samples; ++i) {
        if (band[i] != widest) continue;
        first_wide = std::min(first_wide, i);
        last_wide = i;
        ++wide_count;
      }
      const double spread = static_cast<double>(last_wide - first_wide + 1) / samples *
                            (cells - 2.0 * border) / cells;
      if (wide_count < 4 || spread < 0.5) widest = border;
    }
    std::vector<EdgePoint> pts;
    pts.reserve(samples);
    for (int i = 0; i < samples; ++i) {
      if (band[i] < widest) continue;
      const double half_window_px = std::clamp(0.5 * band[i] * across_px, 1.0, 4.0);
      const double t = (border + (cells - 2.0 * border) * (i + 0.5) / samples) / cells;
      const std::optional<EdgePoint> e =
          MeasureEdgePoint(image, a + t * (b - a), n, half_window_px);
      if (e.has_value()) pts.push_back(*e);
    }
    // Two points define a line; four make a fit that averages noise.
    if (pts.size() < 4) return false;
    const std::optional<Line2d> line = FitWeightedLine(pts, d);
    if (!line.has_value()) return false;
    lines[k] = *line;
    lengths[k] = len;
    if (curved_sides) {
      // A parabola needs points to spare: six, else the side stays a line.
      const std::optional<SideCurve> curve =
          pts.size() >= 6 ? FitSideCurve(pts, a, d, n) : std::nullopt;
      if (!curve.has_value()) return false;
      curves[k] = *curve;
    }
  }
  std::array<Eigen::Vector2d, 4> out;
  for (int k = 0; k < 4; ++k) {
    // Corner k starts side k and ends side k - 1.
    const int j = (k + 3) % 4;
    // Sides within ~3 degrees of parallel do not define a corner. Curved sides meet where
    // their tangents at the corner do (the corner moves a fraction of a pixel, over which the
    // curve is its tangent).
    const std::optional<Eigen::Vector2d> corner =
        curved_sides ? IntersectLines(TangentAt(curves[j], lengths[j]), TangentAt(curves[k], 0.0))
                     : IntersectLines(lines[j], lines[k]);
    if (!corner.has_value()) return false;
    out[k] = *corner;
    const double cell_px = 0.5 *
                           (((*corners)[(k + 1) % 4] - (*corners)[k]).norm() +
                            ((*corners)[k] - (*corners)[j]).norm()) /
                           cells;
    if ((out[k] - (*corners)[k]).norm() > max_move_cells * cell_px) return false;
  }
  *corners = out;
  return true;
}

// Grey level of each cell (row-major, cells x cells) of the quad, from a 3 x 3 grid of
// bilinear samples over the middle half of the cell (clear of blurred cell edges).
// False when the homography fails or a sample leaves the image.
bool SampleCells(const ImageView8& image, const std::array<Eigen::Vector2d, 4>& corners, int cells,
                 std::vector<double>* values) {
  const std::array<Eigen::Vector2d, 4> src = {Eigen::Vector2d(0, 0), Eigen::Vector2d(cells, 0),
                                              Eigen::Vector2d(cells, cells),
                                              Eigen::Vector2d(0, cells)};
  HomographyFitOptions fit_options;
  fit_options.refine = false;  // four points: the DLT is exact
  const std::optional<HomographyFit> fit =
      FitHomography(std::span<const Eigen::Vector2d>(src),
                    std::span<const Eigen::Vector2d>(corners), fit_options);
  if (!fit.has_value()) return false;
  const Eigen::Matrix3d& H = fit->H;
  values->assign(static_cast<std::size_t>(cells) * cells, 0.0);
  constexpr std::array<double, 3> kOffsets = {0.25, 0.5, 0.75};
  for (int r = 0; r < cells; ++r) {
    for (int c = 0; c < cells; ++c) {
      double sum = 0.0;
      for (double oy : kOffsets) {
        for (double ox : kOffsets) {
          const Eigen::Vector3d h = H * Eigen::Vector3d(c + ox, r + oy, 1.0);
          if (!(h.z() > 0.0 || h.z() < 0.0)) return false;
          const Eigen::Vector2d p = h.hnormalized();
          if (!InsideForBilinearGrey(image, p)) return false;
          sum += BilinearGrey(image, p.x(), p.y());
        }
      }
      (*values)[static_cast<std::size_t>(r) * cells + c] = sum / 9.0;
    }
  }
  return true;
}

// Otsu's threshold over a few values: the split of the sorted values that maximises the
// between-class variance. Returns the midpoint between the two class means at that split,
// and the means; false when all values are equal.
bool SplitLevels(std::vector<double> values, double* dark, double* light) {
  std::sort(values.begin(), values.end());
  const int n = static_cast<int>(values.size());
  double total = 0.0;
  for (double v : values) total += v;
  double best = -1.0;
  double left = 0.0;
  for (int i = 1; i < n; ++i) {
    left += values[i - 1];
    const double m0 = left / i;
    const double m1 = (total - left) / (n - i);
    const double score = static_cast<double>(i) * (n - i) * (m1 - m0) * (m1 - m0);
    if (score > best) {
      best = score;
      *dark = m0;
      *light = m1;
    }
  }
  return best > 0.0;
}

// The grid turned so that observed corner k becomes the top-left: cell (r, c) of the
// turned grid is cell (c, n - 1 - r) of the grid turned by k - 1.
std::vector<std::uint8_t> Turn(const std::vector<std::uint8_t>& g, int n) {
  std::vector<std::uint8_t> out(g.size());
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < n; ++c) out[r * n + c] = g[c * n + (n - 1 - r)];
  }
  return out;
}

struct Decode {
  int id = -1;
  int rotation = 0;
  int hamming = 0;
};

// Decodes a grid of light (1) / dark (0) cells against the whole family in all four
// rotations. id = -1 when no code is within max_correction_bits, or when two (code,
// rotation) pairs are equally close.
Decode DecodeGrid(const std::vector<std::uint8_t>& light, const MarkerFamily& family) {
  const int n = family.cells;
  const int bits = static_cast<int>(family.bit_cells.size());
  Decode best;
  int best_distance = bits + 1;
  int ties = 0;
  std::vector<std::uint8_t> g = light;
  for (int k = 0; k < 4; ++k) {
    if (k > 0) g = Turn(g, n);
    std::uint64_t code = 0;
    for (int i = 0; i < bits; ++i) {
      const auto& rc = family.bit_cells[i];
      if (g[rc[0] * n + rc[1]] != 0) code |= std::uint64_t{1} << (bits - 1 - i);
    }
    for (int id = 0; id < static_cast<int>(family.codes.size()); ++id) {
      const int d = std::popcount(code ^ family.codes[id]);
      if (d < best_distance) {
        best_distance = d;
        best = Decode{id, k, d};
        ties = 0;
      } else if (d == best_distance) {
        ++ties;
      }
    }
  }
  if (best_distance > family.max_correction_bits || ties > 0) return Decode{};
  return best;
}

struct ReadResult {
  DecodedMarker marker;
  int rotation = 0;                 // the observed corner that is the marker's top-left
  std::vector<std::uint8_t> light;  // the cells as observed (quad corner 0 top-left), 1 = light
};

// Reads one candidate quad: samples and classifies its cells, checks the black border,
// decodes. min_contrast: the light and dark cell levels must differ by at least this.
std::optional<ReadResult> ReadMarker(const ImageView8& image,
                                     const std::array<Eigen::Vector2d, 4>& corners,
                                     const MarkerFamily& family, double min_contrast) {
  std::vector<double> values;
  if (!SampleCells(image, corners, family.cells, &values)) return std::nullopt;
  double dark = 0.0;
  double light = 0.0;
  if (!SplitLevels(values, &dark, &light) || light - dark < min_contrast) return std::nullopt;
  const double threshold = 0.5 * (dark + light);
  const int n = family.cells;
  std::vector<std::uint8_t> grid(values.size());
  for (std::size_t i = 0; i < values.size(); ++i) grid[i] = values[i] > threshold ? 1 : 0;
  const int b = family.border_cells;
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < n; ++c) {
      const bool border = r < b || c < b || r >= n - b || c >= n - b;
      if (border && grid[r * n + c] != 0) return std::nullopt;
    }
  }
  const Decode decode = DecodeGrid(grid, family);
  if (decode.id < 0) return std::nullopt;
  ReadResult result;
  result.rotation = decode.rotation;
  result.light = grid;
  result.marker.id = decode.id;
  result.marker.hamming = decode.hamming;
  for (int c = 0; c < 4; ++c) result.marker.corners_px[c] = corners[(decode.rotation + c) % 4];
  return result;
}

// Refines, reads and decodes one candidate quad. A coarse pass (8 edge points per side)
// for every candidate, since the contour corners may be a cell off on blurred, small quads;
// the fine pass (an edge point per pixel of side, up to 80) only for decoded markers,
// twice: the first within half a cell of the coarse corners, the second re-centring the edge
// windows on the refined lines within a third of a cell.
std::optional<DecodedMarker> ReadQuad(const ImageView8& image, const Quad& quad,
                                      const MarkerFamily& family, double min_contrast) {
  std::array<Eigen::Vector2d, 4> corners = quad.corners_px;
  double side = 0.0;
  for (int k = 0; k < 4; ++k) side += 0.25 * (corners[(k + 1) % 4] - corners[k]).norm();
  if (!RefineQuadCorners(image, family, nullptr, 8, 1.0, &corners)) return std::nullopt;
  std::optional<ReadResult> marker = ReadMarker(image, corners, family, min_contrast);
  if (!marker.has_value()) return std::nullopt;
  const int fine_samples = std::clamp(static_cast<int>(side), 8, 80);
  // Half a cell for the first, as for markers found on a halved image (DetectMarkerBoard):
  // the coarse pass's eight points on a side of a few cells, blind to the cells, can leave a
  // corner more than a third of a cell off (markers of 4 px cells foreshortened by 50
  // degrees, noise 4).
  if (!RefineQuadCorners(image, family, &marker->light, fine_samples, 0.5, &corners) ||
      !RefineQuadCorners(image, family, &marker->light, fine_samples, 0.34, &corners)) {
    return std::nullopt;
  }
  for (int c = 0; c < 4; ++c) marker->marker.corners_px[c] = corners[(marker->rotation + c) % 4];
  return marker->marker;
}

// The cells of marker `id` in its canonical orientation (row-major, 1 = light). O(cells^2).
std::vector<std::uint8_t> MarkerCells(const MarkerFamily& family, int id) {
  const int n = family.cells;
  const int bits = static_cast<int>(family.bit_cells.size());
  std::vector<std::uint8_t> light(static_cast<std::size_t>(n) * n, 0);
  for (int i = 0; i < bits; ++i) {
    const auto& rc = family.bit_cells[i];
    light[rc[0] * n + rc[1]] = static_cast<std::uint8_t>((family.codes[id] >> (bits - 1 - i)) & 1U);
  }
  return light;
}

// A marker placed by the board homography may disagree with its printed cells in this
// fraction of its code bits (over all its cells, border included). A blind read needs a
// margin against decoding some other pattern as a code (at most family.max_correction_bits);
// a placed read only has to show that the marker sampled is the board's, in the board's
// orientation: a read a cell off puts a side of its border on the light surround and
// disagrees in a whole row of cells, and a random pattern is within 6 of 36 bits of a given
// code with a probability of 2e-5 (within 2 of 16: 2e-3, and the board is already
// identified). Small, foreshortened and blurred markers lose a few cells on their edges:
// this is what finds them.
constexpr double kPlacedMarkerMaxWrongFraction = 1.0 / 6.0;
// What of the bending the pairs' prediction leaves (its third order), as a share of what it
// took out (the second order); the fine check's bound grows by it.
constexpr double kBentRemainderFraction = 0.5;
// How far, in cells, the edges may move a placed marker's corner from where the board's
// homography puts it (ReadPredictedMarker).
constexpr double kPlacedMarkerMaxMoveCells = 0.25;

// How many of a marker's cells disagree with its printed cells `expected` (1 = light), and
// whether their contrast is at least min_contrast. The grey levels are modelled as
// a + b x + c y + d expected (x, y: the cell's column and row): the plane takes out the
// illumination gradient and the gamma's local slope across the marker, which a single
// threshold between the light and dark levels would read as wrong cells at the dim end; a
// cell disagrees when it lies on the other side of the plane + d / 2. nullopt when d <
// min_contrast or the fit is singular. O(cells^2).
std::optional<int> CellsDisagreeing(const std::vector<double>& values,
                                    const std::vector<std::uint8_t>& expected, int cells,
                                    double min_contrast) {
  Eigen::Matrix4d normal = Eigen::Matrix4d::Zero();
  Eigen::Vector4d rhs = Eigen::Vector4d::Zero();
  const double mid = 0.5 * (cells - 1);
  for (int r = 0; r < cells; ++r) {
    for (int c = 0; c < cells; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * cells + c;
      const Eigen::Vector4d row(1.0, c - mid, r - mid, expected[i]);
      normal += row * row.transpose();
      rhs += row * values[i];
    }
  }
  const Eigen::LDLT<Eigen::Matrix4d> solve(normal);
  if (solve.info() != Eigen::Success || !solve.isPositive()) return std::nullopt;
  const Eigen::Vector4d m = solve.solve(rhs);
  if (!(m(3) >= min_contrast)) return std::nullopt;
  int wrong = 0;
  for (int r = 0; r < cells; ++r) {
    for (int c = 0; c < cells; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * cells + c;
      const bool light = values[i] > m(0) + m(1) * (c - mid) + m(2) * (r - mid) + 0.5 * m(3);
      wrong += light != (expected[i] != 0);
    }
  }
  return wrong;
}

// Reads marker `id` where the board puts it: `corners` (canonical corner order, clockwise in
// the image) come from the board homography. They are refined on the marker's edges knowing
// its cells (the prediction is within a fraction of a cell; lens distortion and the
// homography's own error are what is left), and the marker is accepted when its cells show
// its print (CellsDisagreeing) within kPlacedMarkerMaxWrongFraction of its code bits. The
// caller checks how far the corners moved (kPlacedMarkerMaxMoveCells), after placing small
// markers' sides on the page.
std::optional<DecodedMarker> ReadPredictedMarker(const ImageView8& image,
                                                 const MarkerFamily& family, int id,
                                                 std::array<Eigen::Vector2d, 4> corners,
                                                 double min_contrast) {
  double side = 0.0;
  for (int k = 0; k < 4; ++k) side += 0.25 * (corners[(k + 1) % 4] - corners[k]).norm();
  const int samples = std::clamp(static_cast<int>(side), 8, 80);
  const std::vector<std::uint8_t> expected = MarkerCells(family, id);
  if (!RefineQuadCorners(image, family, &expected, samples, 0.5, &corners)) return std::nullopt;
  std::vector<double> values;
  if (!SampleCells(image, corners, family.cells, &values)) return std::nullopt;
  const std::optional<int> wrong = CellsDisagreeing(values, expected, family.cells, min_contrast);
  const int bits = static_cast<int>(family.bit_cells.size());
  if (!wrong.has_value() ||
      *wrong > std::max<int>(family.max_correction_bits,
                             static_cast<int>(kPlacedMarkerMaxWrongFraction * bits))) {
    return std::nullopt;
  }
  if (!RefineQuadCorners(image, family, &expected, samples, 0.34, &corners)) return std::nullopt;
  DecodedMarker marker;
  marker.id = id;
  marker.hamming = *wrong;
  marker.corners_px = corners;
  return marker;
}

// True when every corner of `moved` is within `max_cells` cells (of `predicted`'s mean side,
// `cells` cells per side) of its corner in `predicted`. O(1).
bool WithinCells(const std::array<Eigen::Vector2d, 4>& moved,
                 const std::array<Eigen::Vector2d, 4>& predicted, int cells, double max_cells) {
  double side = 0.0;
  for (int k = 0; k < 4; ++k) side += 0.25 * (predicted[(k + 1) % 4] - predicted[k]).norm();
  for (int k = 0; k < 4; ++k) {
    if ((moved[k] - predicted[k]).norm() > max_cells * side / cells) return false;
  }
  return true;
}

// True when p is inside the convex quad (corners in either winding). O(1).
bool InsideQuad(const std::array<Eigen::Vector2d, 4>& q, const Eigen::Vector2d& p) {
  int positive = 0;
  int negative = 0;
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d e = q[(k + 1) % 4] - q[k];
    const Eigen::Vector2d r = p - q[k];
    const double cross = e.x() * r.y() - e.y() * r.x();
    positive += cross > 0.0;
    negative += cross < 0.0;
  }
  return positive == 0 || negative == 0;
}

}  // namespace

std::string_view MarkerDetectOptions::Validate() const {
  if (min_contrast < 1 || min_contrast > 255) return "min_contrast";
  if (!(noise_contrast_factor >= 0.0 && noise_contrast_factor <= 100.0)) {
    return "noise_contrast_factor";
  }
  if (min_marker_side_px < 8 || min_marker_side_px > kMaxImageSide) return "min_marker_side_px";
  if (max_candidates < 1) return "max_candidates";
  if (max_erosion_px < 0 || max_erosion_px > 4) return "max_erosion_px";
  if (!(near_dark_fraction >= 0.0 && near_dark_fraction < 0.5)) return "near_dark_fraction";
  if (!(max_residual_fraction > 0.0 && max_residual_fraction <= 1.0)) {
    return "max_residual_fraction";
  }
  if (!(max_residual_cells > 0.0 && max_residual_cells <= 10.0)) return "max_residual_cells";
  if (!(min_paint_agreement >= 0.0 && min_paint_agreement <= 1.0)) return "min_paint_agreement";
  return {};
}

MarkerFamily ArucoFamily(ArucoDictionary dictionary) {
  const ArucoDictionaryInfo& info = ArucoDictionaryInfoOf(dictionary);
  MarkerFamily family;
  family.cells = info.marker_cells();
  family.border_cells = 1;
  for (int i = 0; i < info.data_bits * info.data_bits; ++i) {
    family.bit_cells.push_back({1 + i / info.data_bits, 1 + i % info.data_bits});
  }
  family.codes.assign(info.codes.begin(), info.codes.end());
  family.max_correction_bits = info.max_correction_bits;
  return family;
}

MarkerFamily Aruco4x4_50Family() { return ArucoFamily(ArucoDictionary::k4x4_50); }

MarkerFamily Tag36h11Family(int border_bits) {
  apriltag_family_t* tf = tag36h11_create();
  MarkerFamily family;
  // libapriltag's layout has a 1-bit border (width_at_border 8, data bits at 1..6); a wider
  // border moves every data cell inwards by the extra border width.
  const int extra = border_bits - 1;
  family.cells = static_cast<int>(tf->width_at_border) + 2 * extra;
  family.border_cells = border_bits;
  for (unsigned i = 0; i < tf->nbits; ++i) {
    family.bit_cells.push_back(
        {static_cast<int>(tf->bit_y[i]) + extra, static_cast<int>(tf->bit_x[i]) + extra});
  }
  family.codes.assign(tf->codes, tf->codes + tf->ncodes);
  family.max_correction_bits = 2;
  tag36h11_destroy(tf);
  return family;
}

std::optional<int> CellsDisagreeingWithMarker(const ImageView8& image, const MarkerFamily& family,
                                              int id,
                                              const std::array<Eigen::Vector2d, 4>& corners_px,
                                              double min_contrast) {
  std::vector<double> values;
  if (!SampleCells(image, corners_px, family.cells, &values)) return std::nullopt;
  return CellsDisagreeing(values, MarkerCells(family, id), family.cells, min_contrast);
}

std::optional<DecodedMarker> ReadPlacedMarker(const ImageView8& image, const MarkerFamily& family,
                                              int id,
                                              const std::array<Eigen::Vector2d, 4>& predicted_px,
                                              double min_contrast) {
  std::optional<DecodedMarker> marker =
      ReadPredictedMarker(image, family, id, predicted_px, min_contrast);
  if (!marker ||
      !WithinCells(marker->corners_px, predicted_px, family.cells, kPlacedMarkerMaxMoveCells)) {
    return std::nullopt;
  }
  return marker;
}

MarkerScan ScanMarkers(const ImageView8& image, const MarkerFamily& family,
                       const MarkerDetectOptions& options, int enough_markers) {
  MarkerScan scan;
  if (image.width < options.min_marker_side_px || image.height < options.min_marker_side_px) {
    scan.reason = DetectReason::kBadImage;
    return scan;
  }
  const double noise_sigma = EstimateNoiseSigma(image);
  const int min_contrast =
      std::max(options.min_contrast,
               static_cast<int>(std::ceil(options.noise_contrast_factor * noise_sigma)));
  scan.min_contrast = min_contrast;
  int max_contrast = 0;
  // 1 where the pixel is darker than its local threshold.
  const Image8 dark = BinariseDark(image, min_contrast, &max_contrast);
  if (max_contrast < min_contrast) {
    scan.reason = DetectReason::kLowContrast;
    return scan;
  }
  QuadOptions quad_options;
  quad_options.min_side_px = options.min_marker_side_px;
  const auto read_quads = [&](const Image8& binary, const MarkerFamily& codes) {
    const ComponentLabels labels = LabelComponents(binary.view());
    for (const Quad& quad : FindQuads(labels, quad_options)) {
      if (scan.quads >= options.max_candidates) break;
      // A quad around a marker already read (in an earlier pass) is that marker again.
      Eigen::Vector2d centre = Eigen::Vector2d::Zero();
      for (const Eigen::Vector2d& c : quad.corners_px) centre += 0.25 * c;
      if (std::any_of(scan.markers.begin(), scan.markers.end(),
                      [&](const DecodedMarker& m) { return InsideQuad(m.corners_px, centre); })) {
        continue;
      }
      ++scan.quads;
      std::optional<DecodedMarker> marker = ReadQuad(image, quad, codes, min_contrast);
      if (marker.has_value()) scan.markers.push_back(*marker);
    }
  };
  const auto enough = [&] {
    return enough_markers > 0 && static_cast<int>(scan.markers.size()) >= enough_markers;
  };
  Image8 eroded;
  for (int erosion = 0; erosion <= options.max_erosion_px && !(erosion > 0 && enough());
       ++erosion) {
    if (erosion > 0) eroded = Erode(erosion == 1 ? dark : eroded);
    read_quads(erosion == 0 ? dark : eroded, family);
  }
  if (options.near_dark_fraction > 0.0 && !enough()) {
    int unused_max_contrast = 0;
    // Exact reads only: the lower threshold also turns texture and the insides of dark print
    // into quads (a black cell with the clutter behind its hole read as DICT_4X4_50 id 17
    // with one corrected bit on a round-hole board turned 50 degrees, which then refused the
    // board for another id on its page).
    MarkerFamily exact = family;
    exact.max_correction_bits = 0;
    read_quads(BinariseDark(image, min_contrast, &unused_max_contrast, options.near_dark_fraction),
               exact);
  }
  if (scan.markers.empty()) scan.reason = DetectReason::kNoCandidates;
  return scan;
}

namespace {

// Edge-located corners of dark squares carry one bias that a homography cannot take up: a
// gamma applied after the optics' blur (and, less, ink spread and the edge windows at small
// cells) moves every dark-to-light edge outwards or inwards by the same amount, so every
// marker grows or shrinks about its centre while the markers' pitch stays. Measured on
// renders: 0.7-0.8 px RMS at gamma 0.6 or 1.6 under blur 1.5 (0.15 px at gamma 1). The board
// fit takes it as one more unknown, the dilation: each corner k of a marker is observed at
// H (p_k + dilation * d_k), d_k its outward diagonal (+-1, +-1) in the board frame.
using BoardFit = DilatedHomographyFit;

// Markers needed to fit the dilation: with two, a marker's size and the pair's spacing are
// all there is to tell it from the homography's scale.
constexpr std::size_t kMinMarkersForDilation = 3;

// Markers whose black border is narrower than this (px) across their shortest side get their
// sides fitted to the page model (page_edge_fit.h). Below it the blur of the border's inner edge,
// and of what lies behind and beyond, reaches the edge's gradient centroid (ArUco at 4 px cells,
// blur 1: 0.2-0.3 px off); above it the centroids meet the bars at a tenth of the cost. The
// AprilTag grid's two-cell border is 8 px at docs/acceptance.md's smallest cells, so its 36 tags
// keep their centroids (docs/detectors.md).
constexpr double kPageFitMaxBorderPx = 5.0;

// The image of H at p and its 2 x 2 derivative there. O(1).
Eigen::Vector2d ApplyHomographyWithJacobian(const Eigen::Matrix3d& H, const Eigen::Vector2d& p,
                                            Eigen::Matrix2d* J) {
  const Eigen::Vector3d x = H * p.homogeneous();
  const double w = x.z();
  const Eigen::Vector2d uv = x.head<2>() / w;
  for (int r = 0; r < 2; ++r) J->row(r) = (H.block<1, 2>(r, 0) - uv(r) * H.block<1, 2>(2, 0)) / w;
  return uv;
}

// Fits the board homography and, with kMinMarkersForDilation markers or more, the dilation
// (BoardFit) to corners uv[i] of board points p[i] with outward diagonals d[i]: alternately
// the homography through the dilated points and the dilation by one Gauss-Newton step (they
// are nearly independent, so a few rounds converge). The residuals are those of the dilated
// points. O(n) per round.
std::optional<BoardFit> FitBoard(const std::vector<Eigen::Vector2d>& p,
                                 const std::vector<Eigen::Vector2d>& d,
                                 const std::vector<Eigen::Vector2d>& uv, std::size_t markers) {
  BoardFit board;
  std::vector<Eigen::Vector2d> dilated = p;
  const int rounds = markers >= kMinMarkersForDilation ? 4 : 0;
  for (int round = 0;; ++round) {
    std::optional<HomographyFit> fit = FitHomography(dilated, uv);
    if (!fit.has_value()) return std::nullopt;
    board.fit = *fit;
    if (round == rounds) return board;
    double num = 0.0;
    double den = 0.0;
    for (std::size_t i = 0; i < p.size(); ++i) {
      Eigen::Matrix2d J;
      const Eigen::Vector2d r = uv[i] - ApplyHomographyWithJacobian(board.fit.H, dilated[i], &J);
      const Eigen::Vector2d g = J * d[i];
      num += g.dot(r);
      den += g.squaredNorm();
    }
    if (!(den > 0.0)) return std::nullopt;
    board.dilation_m += num / den;
    for (std::size_t i = 0; i < p.size(); ++i) dilated[i] = p[i] + board.dilation_m * d[i];
  }
}

}  // namespace

std::optional<DilatedHomographyFit> FitDilatedHomography(
    const std::vector<Eigen::Vector2d>& p_board,
    const std::vector<Eigen::Vector2d>& outward_diagonal, const std::vector<Eigen::Vector2d>& uv_px,
    std::size_t markers) {
  if (p_board.size() != outward_diagonal.size() || p_board.size() != uv_px.size()) {
    return std::nullopt;
  }
  return FitBoard(p_board, outward_diagonal, uv_px, markers);
}

namespace {

// The outward diagonal (+-1, +-1) of each corner of a marker, board frame.
std::array<Eigen::Vector2d, 4> OutwardDiagonals(const std::vector<const BoardFeature*>& corners) {
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  for (const BoardFeature* f : corners) centre += 0.25 * f->p_board;
  std::array<Eigen::Vector2d, 4> d;
  for (int c = 0; c < 4; ++c) {
    const Eigen::Vector2d v = corners[c]->p_board - centre;
    d[c] = Eigen::Vector2d(v.x() > 0.0 ? 1.0 : -1.0, v.y() > 0.0 ? 1.0 : -1.0);
  }
  return d;
}

Detection Fail(DetectReason reason) {
  Detection d;
  d.found = false;
  d.reason = reason;
  return d;
}

using BoardMarkers = std::map<int, std::vector<const BoardFeature*>>;

// The board's model in the image, as the checks after the fit and the report need it.
struct BoardInImage {
  BoardToImage to_image;          // the paint checks' mapping
  Eigen::Matrix3d H_image_board;  // whole-board homography, for markers of other ids
  double px_per_m = 0.0;          // the board's scale in the image
  // A detected corner corrected to where the printed corner is (corner_px, p_board, the
  // corner's outward diagonal).
  std::function<Eigen::Vector2d(const Eigen::Vector2d&, const Eigen::Vector2d&,
                                const Eigen::Vector2d&)>
      printed;
};

// The checks every identified board passes, then the detection: no marker of another id on
// the board's page, the printed paint where the model puts it (and more the board's than a
// sibling's), and the corners of `on_board` as features, sorted by id. found = true only when
// every marker of the board is in `on_board`, else kPartial. Cost: the paint checks (under a
// millisecond) plus O(markers).
Detection CheckAndReport(const BoardInImage& model,
                         const std::vector<const DecodedMarker*>& on_board,
                         const BoardMarkers& board_markers,
                         const std::vector<const DecodedMarker*>& others, const Board& board,
                         const Board* sibling, const ImageView8& image,
                         const MarkerDetectOptions& options) {
  // A marker of another id on this board's page: another board that shares some ids. A
  // homography of a bent board is tens of pixels off at its rim, a small part of the margin.
  // Not one centred on a through hole: that is the board's own black square around the hole
  // with whatever is behind the board in it (the round-hole board's centre square, with a wall
  // above the floor's edge behind it, read as DICT_4X4_50 id 37 with one corrected bit), or
  // something seen through the hole; neither is print of another board.
  const Eigen::Matrix3d H_board_image = model.H_image_board.inverse();
  const Eigen::Vector2d half_page = 0.5 * board.page_size_m();
  for (const DecodedMarker* m : others) {
    Eigen::Vector2d centre = Eigen::Vector2d::Zero();
    for (const Eigen::Vector2d& c : m->corners_px) centre += 0.25 * c;
    const Eigen::Vector2d p = ApplyHomography(H_board_image, centre);
    if (std::abs(p.x()) < half_page.x() && std::abs(p.y()) < half_page.y() &&
        board.PaintAt(p) != Paint::kHole) {
      return Fail(DetectReason::kWrongBoard);
    }
  }
  // The markers read, as squares of the board frame: what the paint check may not take for
  // hidden.
  std::vector<Eigen::AlignedBox2d> read_squares;
  for (const DecodedMarker* m : on_board) {
    Eigen::AlignedBox2d square;
    for (const BoardFeature* f : board_markers.at(m->id)) square.extend(f->p_board);
    read_squares.push_back(square);
  }
  const BoardRegion read = [&read_squares](const Eigen::Vector2d& p) {
    return std::any_of(read_squares.begin(), read_squares.end(),
                       [&p](const Eigen::AlignedBox2d& b) { return b.contains(p); });
  };
  // The paint compared between nearby points under the same light (PaintAgrees), not on the
  // binarised image: that reads white paper at the dim end of a 4:1 gradient as dark and
  // refused every marker board so lit. The binarised check had been kept for a board of 4 px
  // cells that the grey one passed with a corner 1.7 px off; the quarter-cell residual limit
  // (max_residual_cells) refuses such boards now. Parts of the page hidden behind another
  // board or a post are left out (VisiblePaintAgrees): the board is found from what shows.
  if (!VisiblePaintAgrees(board, model.to_image, image, model.px_per_m, options.min_paint_agreement,
                          read)) {
    return Fail(DetectReason::kWrongBoard);
  }
  if (sibling != nullptr && !PaintContrastPrefers(board, *sibling, model.to_image, image,
                                                  model.px_per_m, options.min_paint_agreement)) {
    return Fail(PaintContrastPrefers(*sibling, board, model.to_image, image, model.px_per_m,
                                     options.min_paint_agreement)
                    ? DetectReason::kWrongBoard
                    : DetectReason::kAmbiguous);
  }
  Detection detection;
  detection.found = on_board.size() == board_markers.size();
  detection.reason = detection.found ? DetectReason::kNone : DetectReason::kPartial;
  for (const DecodedMarker* m : on_board) {
    const std::vector<const BoardFeature*>& f = board_markers.at(m->id);
    const std::array<Eigen::Vector2d, 4> d = OutwardDiagonals(f);
    for (int c = 0; c < 4; ++c) {
      DetectedFeature feature;
      feature.id = f[c]->id;
      feature.uv_px = model.printed(m->corners_px[c], f[c]->p_board, d[c]);
      feature.p_board = f[c]->p_board;
      feature.marker = m->id;
      detection.features.push_back(feature);
    }
  }
  std::sort(detection.features.begin(), detection.features.end(),
            [](const DetectedFeature& a, const DetectedFeature& b) { return a.id < b.id; });
  return detection;
}

// ---- Boards bent by a lens ----------------------------------------------------------------
//
// A real lens bends a board by tens of pixels over its width (a wide-angle front camera, a
// fisheye): its markers then fit no single homography within the residual bound, whose
// quarter of a cell is meant for misplaced corners. Such a board is judged locally instead.
// Each marker's own four corners give its homography: over one marker the bending is a small
// part of a pixel. A marker is the one its id says where its board neighbours' homographies,
// carried over one pitch, put its corners within kBentNeighbourFraction of its side: a misread
// id puts it whole pitches away, while the lens bends a pitch's carry by a few pixels, and at
// the rim of a 190-degree fisheye by up to a fifth of a side (11.5 px at 53 px sides, measured
// on the AprilGrid): half of the neighbours must agree, and the nearer ones do. Then the finer
// check (PairPrediction). Everything after (markers the scan missed, the paint, the report) uses
// the nearest marker's homography; the dilation of the dark print (BoardFit) is not taken out.

// How far a neighbour's homography may put a marker's corners, in the marker's sides.
constexpr double kBentNeighbourFraction = 0.2;
// Board neighbours: marker centres within this many pitches (the diagonal ones at sqrt(2)).
constexpr double kBentNeighbourPitches = 1.5;
// The paint is probed only this many pitches around a verified marker: beyond, a marker's
// homography carries the lens's bending (and a trimmed board's page is not there).
constexpr double kBentPaintPitches = 0.75;
// How far, in cells, the edges may move a placed marker's corner from where its neighbours put
// it: twice the unbent bound, for what is left of the bending at the board's rim.
constexpr double kBentPlacedMaxMoveCells = 0.5;

// One marker of a bent board with its own homography.
struct LocalMarker {
  DecodedMarker marker;
  Eigen::Vector2d centre_m;  // board frame
  Eigen::Matrix3d H_image_board;
  double side_px = 0.0;  // mean side in the image
};

// The homography through a marker's four corners; nullopt when they are degenerate. O(1).
std::optional<LocalMarker> MakeLocal(const DecodedMarker& m,
                                     const std::vector<const BoardFeature*>& f) {
  std::array<Eigen::Vector2d, 4> board_corners;
  LocalMarker local;
  local.marker = m;
  local.centre_m = Eigen::Vector2d::Zero();
  for (int c = 0; c < 4; ++c) {
    board_corners[c] = f[c]->p_board;
    local.centre_m += 0.25 * f[c]->p_board;
    local.side_px += 0.25 * (m.corners_px[(c + 1) % 4] - m.corners_px[c]).norm();
  }
  HomographyFitOptions exact;
  exact.refine = false;
  const std::optional<HomographyFit> fit =
      FitHomography(std::span<const Eigen::Vector2d>(board_corners),
                    std::span<const Eigen::Vector2d>(m.corners_px), exact);
  if (!fit.has_value()) return std::nullopt;
  local.H_image_board = fit->H;
  return local;
}

// Where H puts the corners of the board marker `f`. O(1).
std::array<Eigen::Vector2d, 4> CornersThrough(const Eigen::Matrix3d& H,
                                              const std::vector<const BoardFeature*>& f) {
  std::array<Eigen::Vector2d, 4> corners;
  for (int c = 0; c < 4; ++c) corners[c] = ApplyHomography(H, f[c]->p_board);
  return corners;
}

// The distance between markers' centres on the board nearest to each other. O(markers^2).
double MarkerPitchM(const BoardMarkers& board_markers) {
  std::vector<Eigen::Vector2d> centres;
  for (const auto& entry : board_markers) {
    Eigen::Vector2d c = Eigen::Vector2d::Zero();
    for (const BoardFeature* f : entry.second) c += 0.25 * f->p_board;
    centres.push_back(c);
  }
  double pitch = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < centres.size(); ++i) {
    for (std::size_t j = i + 1; j < centres.size(); ++j) {
      pitch = std::min(pitch, (centres[i] - centres[j]).norm());
    }
  }
  return pitch;
}

// Whether `m` is where its verified neighbours put it: of the markers of `locals` within
// kBentNeighbourPitches (other than m itself), at least half agree, and at least one. O(n).
enum class NeighbourVote { kAgree, kDisagree, kNoNeighbours };
NeighbourVote VoteOfNeighbours(const LocalMarker& m, const std::vector<LocalMarker>& locals,
                               const BoardMarkers& board_markers, double pitch_m) {
  int near = 0;
  int agree = 0;
  const std::vector<const BoardFeature*>& f = board_markers.at(m.marker.id);
  for (const LocalMarker& n : locals) {
    if (n.marker.id == m.marker.id ||
        (n.centre_m - m.centre_m).norm() > kBentNeighbourPitches * pitch_m) {
      continue;
    }
    ++near;
    const std::array<Eigen::Vector2d, 4> predicted = CornersThrough(n.H_image_board, f);
    double worst = 0.0;
    for (int c = 0; c < 4; ++c)
      worst = std::max(worst, (predicted[c] - m.marker.corners_px[c]).norm());
    agree += worst <= kBentNeighbourFraction * m.side_px ? 1 : 0;
  }
  if (near == 0) return NeighbourVote::kNoNeighbours;
  return 2 * agree >= near && agree > 0 ? NeighbourVote::kAgree : NeighbourVote::kDisagree;
}

// The corners of `m` as pairs of its neighbours in `locals` put them, with the lens's bending
// cancelled: a marker's homography carried k pitches is off by about a k^2 (the bending's
// second order, which the homography lacks), so of two markers in a row on one side of m, c1
// one pitch away and c2 two, 4/3 c1 - 1/3 c2 is free of it (Richardson's extrapolation). The
// mean over every such pair; nullopt when there is none. A marker shifted by part of a cell
// stands out against it, where a single carry's bending (up to a cell at a board's rim through
// a strong lens) would hide it. O(neighbours^2).
struct PairPredicted {
  std::array<Eigen::Vector2d, 4> corners;
  // The mean over the pairs of the largest corner distance between the one-pitch carry and
  // the prediction: the bending the prediction took out, px.
  double bending_px = 0.0;
};
std::optional<PairPredicted> PairPrediction(const LocalMarker& m,
                                            const std::vector<LocalMarker>& locals,
                                            const BoardMarkers& board_markers, double pitch_m) {
  const std::vector<const BoardFeature*>& f = board_markers.at(m.marker.id);
  // Offsets match within a twentieth of the pitch.
  const double tol = 0.05 * pitch_m;
  std::vector<const LocalMarker*> near;
  for (const LocalMarker& n : locals) {
    const double d = (n.centre_m - m.centre_m).norm();
    if (n.marker.id != m.marker.id && d <= 2.0 * kBentNeighbourPitches * pitch_m) {
      near.push_back(&n);
    }
  }
  PairPredicted out;
  out.corners.fill(Eigen::Vector2d::Zero());
  int pairs = 0;
  const auto add = [&](const LocalMarker& a, double wa, const LocalMarker& b, double wb) {
    const std::array<Eigen::Vector2d, 4> pa = CornersThrough(a.H_image_board, f);
    const std::array<Eigen::Vector2d, 4> pb = CornersThrough(b.H_image_board, f);
    double bending = 0.0;
    for (int c = 0; c < 4; ++c) {
      const Eigen::Vector2d p = wa * pa[c] + wb * pb[c];
      out.corners[c] += p;
      bending = std::max(bending, (pa[c] - p).norm());
    }
    out.bending_px += bending;
    ++pairs;
  };
  for (std::size_t i = 0; i < near.size(); ++i) {
    const Eigen::Vector2d oi = near[i]->centre_m - m.centre_m;
    if (oi.norm() > kBentNeighbourPitches * pitch_m) continue;
    for (std::size_t j = 0; j < near.size(); ++j) {
      const Eigen::Vector2d oj = near[j]->centre_m - m.centre_m;
      if ((oj - 2.0 * oi).norm() <= tol) add(*near[i], 4.0 / 3.0, *near[j], -1.0 / 3.0);
    }
  }
  if (pairs == 0) return std::nullopt;
  for (Eigen::Vector2d& c : out.corners) c /= pairs;
  out.bending_px /= pairs;
  return out;
}

struct BentBoardInputs {
  const std::vector<const DecodedMarker*>& on_board;  // decoded, ids of the board, each once
  const BoardMarkers& board_markers;
  const std::vector<const DecodedMarker*>& others;
  const Board& board;
  const MarkerFamily& family;
  const MarkerDetectOptions& options;
  const ImageView8& image;
  const Board* sibling;
  double px_per_m;
};

// Reads the board's markers the scan missed where their verified neighbours put them (the
// mean of the neighbours' predictions: bending from either side cancels), each kept when it
// reads as its id and moved at most kBentPlacedMaxMoveCells, and agrees with its neighbours.
// Appends them to *locals. O(missing * (neighbours + side)).
void PlaceMissingBentMarkers(const BentBoardInputs& in, double pitch_m,
                             std::vector<LocalMarker>* locals, int min_contrast) {
  for (const auto& entry : in.board_markers) {
    const int id = entry.first;
    const std::vector<const BoardFeature*>& f = entry.second;
    if (std::any_of(locals->begin(), locals->end(),
                    [id](const LocalMarker& m) { return m.marker.id == id; })) {
      continue;
    }
    Eigen::Vector2d centre_m = Eigen::Vector2d::Zero();
    for (const BoardFeature* x : f) centre_m += 0.25 * x->p_board;
    std::array<Eigen::Vector2d, 4> predicted;
    predicted.fill(Eigen::Vector2d::Zero());
    int neighbours = 0;
    for (const LocalMarker& n : *locals) {
      if ((n.centre_m - centre_m).norm() > kBentNeighbourPitches * pitch_m) continue;
      const std::array<Eigen::Vector2d, 4> p = CornersThrough(n.H_image_board, f);
      for (int c = 0; c < 4; ++c) predicted[c] += p[c];
      ++neighbours;
    }
    if (neighbours == 0) continue;
    for (Eigen::Vector2d& p : predicted) p /= neighbours;
    const std::optional<DecodedMarker> read =
        ReadPredictedMarker(in.image, in.family, id, predicted, min_contrast);
    if (!read.has_value() ||
        !WithinCells(read->corners_px, predicted, in.family.cells, kBentPlacedMaxMoveCells)) {
      continue;
    }
    const std::optional<LocalMarker> local = MakeLocal(*read, f);
    if (local.has_value() &&
        VoteOfNeighbours(*local, *locals, in.board_markers, pitch_m) == NeighbourVote::kAgree) {
      locals->push_back(*local);
    }
  }
}

// VerifyMarkerBoard for a board no single homography holds (see above). kVerificationFailed
// when a marker disagrees with its neighbours, or fewer than two markers have a neighbour;
// markers without any decoded neighbour are left out (nothing vouches for them).
Detection VerifyBentBoard(const BentBoardInputs& in, int min_contrast) {
  const double pitch_m = MarkerPitchM(in.board_markers);
  std::vector<LocalMarker> decoded;
  for (const DecodedMarker* m : in.on_board) {
    std::optional<LocalMarker> local = MakeLocal(*m, in.board_markers.at(m->id));
    if (!local.has_value()) return Fail(DetectReason::kVerificationFailed);
    decoded.push_back(*local);
  }
  std::vector<LocalMarker> locals;
  for (const LocalMarker& m : decoded) {
    switch (VoteOfNeighbours(m, decoded, in.board_markers, pitch_m)) {
      case NeighbourVote::kDisagree:
        return Fail(DetectReason::kVerificationFailed);
      case NeighbourVote::kAgree:
        locals.push_back(m);
        break;
      case NeighbourVote::kNoNeighbours:
        break;
    }
  }
  if (locals.size() < 2) return Fail(DetectReason::kVerificationFailed);
  // The fine check, the unbent board's residual bound (max_residual_cells) against the pairs'
  // prediction. Markers without a pair around them are left out.
  std::vector<LocalMarker> fine;
  for (const LocalMarker& m : locals) {
    const std::optional<PairPredicted> predicted =
        PairPrediction(m, locals, in.board_markers, pitch_m);
    if (!predicted.has_value()) continue;
    double worst = 0.0;
    for (int c = 0; c < 4; ++c) {
      worst = std::max(worst, (predicted->corners[c] - m.marker.corners_px[c]).norm());
    }
    const double bound = in.options.max_residual_cells * m.side_px / in.family.cells +
                         kBentRemainderFraction * predicted->bending_px;
    if (worst > bound) {
      return Fail(DetectReason::kVerificationFailed);
    }
    fine.push_back(m);
  }
  locals = std::move(fine);
  if (locals.size() < 2) return Fail(DetectReason::kVerificationFailed);
  PlaceMissingBentMarkers(in, pitch_m, &locals, min_contrast);
  // The corners again with curved sides (RefineQuadCorners); where that fails, the straight
  // sides' corners stay.
  for (LocalMarker& m : locals) {
    const std::vector<std::uint8_t> light = MarkerCells(in.family, m.marker.id);
    const int samples = std::clamp(static_cast<int>(m.side_px), 8, 80);
    std::array<Eigen::Vector2d, 4> corners = m.marker.corners_px;
    if (RefineQuadCorners(in.image, in.family, &light, samples, 0.25, &corners, true)) {
      m.marker.corners_px = corners;
    }
  }
  // The whole-board homography, for the markers of other ids on the page only.
  std::vector<Eigen::Vector2d> p_board;
  std::vector<Eigen::Vector2d> uv;
  for (const LocalMarker& m : locals) {
    const std::vector<const BoardFeature*>& f = in.board_markers.at(m.marker.id);
    for (int c = 0; c < 4; ++c) {
      p_board.push_back(f[c]->p_board);
      uv.push_back(m.marker.corners_px[c]);
    }
  }
  const std::optional<HomographyFit> whole = FitHomography(p_board, uv);
  if (!whole.has_value()) return Fail(DetectReason::kVerificationFailed);
  const double reach_m = kBentPaintPitches * pitch_m;
  BoardInImage model;
  model.to_image = [&locals, reach_m](const Eigen::Vector2d& p) -> std::optional<Eigen::Vector2d> {
    const LocalMarker* nearest = nullptr;
    double best = reach_m;
    for (const LocalMarker& m : locals) {
      const double d = (m.centre_m - p).lpNorm<Eigen::Infinity>();
      if (d <= best) {
        best = d;
        nearest = &m;
      }
    }
    if (nearest == nullptr) return std::nullopt;
    return ApplyHomography(nearest->H_image_board, p);
  };
  model.H_image_board = whole->H;
  model.px_per_m = in.px_per_m;
  model.printed = [](const Eigen::Vector2d& corner_px, const Eigen::Vector2d&,
                     const Eigen::Vector2d&) -> Eigen::Vector2d { return corner_px; };
  std::vector<const DecodedMarker*> markers;
  for (const LocalMarker& m : locals) markers.push_back(&m.marker);
  return CheckAndReport(model, markers, in.board_markers, in.others, in.board, in.sibling, in.image,
                        in.options);
}

// What VerifyMarkerBoard's steps share: the board, the scan's image and options, and the
// board's markers.
struct MarkerBoardContext {
  const Board& board;
  const MarkerFamily& family;
  const MarkerDetectOptions& options;
  const ImageView8& image;
  const BoardMarkers& board_markers;
  int min_contrast = 0;  // the scan's
};

// Needs a board; gives its markers: id -> its four corner features, in corner order (ids
// 4 k + c).
BoardMarkers MarkersOfBoard(const Board& board) {
  BoardMarkers board_markers;
  for (const BoardFeature& f : board.features()) {
    if (f.kind == FeatureKind::kMarkerCorner) board_markers[f.marker].push_back(&f);
  }
  return board_markers;
}

// The scan's markers split by the board's ids.
struct ScanSplit {
  std::vector<const DecodedMarker*> on_board;  // ids of the board, sorted, each once
  std::vector<const DecodedMarker*> others;
};

// Needs the scan, the board's markers and, per scan marker, whether it is taken for another
// board's print (an instance of a board id not chosen, VerifyMarkerBoard); gives the scan's
// markers split by the board's ids in *split, or the failure: no marker of the board
// (kWrongBoard with markers of other ids, else the scan's reason or kNoCandidates), an id seen
// twice (kAmbiguous), a single marker (kTooFewFeatures, or kWrongBoard with markers of other
// ids).
std::optional<Detection> SplitScan(const MarkerScan& scan, const BoardMarkers& board_markers,
                                   const std::vector<bool>& another_board, ScanSplit* split) {
  std::vector<const DecodedMarker*>& on_board = split->on_board;
  std::vector<const DecodedMarker*>& others = split->others;
  for (std::size_t i = 0; i < scan.markers.size(); ++i) {
    const DecodedMarker& m = scan.markers[i];
    (board_markers.count(m.id) != 0 && !another_board[i] ? on_board : others).push_back(&m);
  }
  if (on_board.empty()) {
    if (!others.empty()) return Fail(DetectReason::kWrongBoard);
    return Fail(scan.reason == DetectReason::kNone ? DetectReason::kNoCandidates : scan.reason);
  }
  std::sort(on_board.begin(), on_board.end(),
            [](const DecodedMarker* a, const DecodedMarker* b) { return a->id < b->id; });
  for (std::size_t i = 1; i < on_board.size(); ++i) {
    if (on_board[i]->id == on_board[i - 1]->id) return Fail(DetectReason::kAmbiguous);
  }
  if (on_board.size() < 2) {
    return Fail(others.empty() ? DetectReason::kTooFewFeatures : DetectReason::kWrongBoard);
  }
  return std::nullopt;
}

// Needs a marker of the board; places a small marker's sides on a model of the page around
// it (page_edge_fit.h): its edge-point corners are off by up to a quarter of a cell, which
// the board fit's residual test refuses. Where the page fit fails, or the marker's border is
// wider than kPageFitMaxBorderPx, the corners stay.
void FitSmallMarkerToPage(const MarkerBoardContext& ctx, DecodedMarker* m) {
  // The shortest side: a turned marker's border is narrowest across its foreshortened sides.
  double side = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 4; ++k)
    side = std::min(side, (m->corners_px[(k + 1) % 4] - m->corners_px[k]).norm());
  if (side * ctx.family.border_cells >= kPageFitMaxBorderPx * ctx.family.cells) return;
  const std::vector<const BoardFeature*>& f = ctx.board_markers.at(m->id);
  std::array<Eigen::Vector2d, 4> corners_board;
  for (int c = 0; c < 4; ++c) corners_board[c] = f[c]->p_board;
  FitMarkerSidesToPage(ctx.image, ctx.board, ctx.family.cells, corners_board, ctx.min_contrast,
                       &m->corners_px);
}

// The board fit's correspondences: board points, their outward diagonals and image corners.
struct Correspondences {
  std::vector<Eigen::Vector2d> p_board;
  std::vector<Eigen::Vector2d> diagonal;
  std::vector<Eigen::Vector2d> uv;

  // Appends the four corners of `m`, whose corner features are `f`.
  void Add(const std::vector<const BoardFeature*>& f, const DecodedMarker& m) {
    const std::array<Eigen::Vector2d, 4> d = OutwardDiagonals(f);
    for (int c = 0; c < 4; ++c) {
      p_board.push_back(f[c]->p_board);
      diagonal.push_back(d[c]);
      uv.push_back(m.corners_px[c]);
    }
  }
};

// The markers' mean side, in the image and on the board.
struct MeanSide {
  double px = 0.0;
  double m = 0.0;
};

// Needs the board's markers found (at least one); gives their mean side.
MeanSide MeanSideOf(const std::vector<const DecodedMarker*>& on_board,
                    const BoardMarkers& board_markers) {
  MeanSide side;
  for (const DecodedMarker* m : on_board) {
    const std::vector<const BoardFeature*>& f = board_markers.at(m->id);
    for (int c = 0; c < 4; ++c) {
      side.px += (m->corners_px[(c + 1) % 4] - m->corners_px[c]).norm();
      side.m += (f[(c + 1) % 4]->p_board - f[c]->p_board).norm();
    }
  }
  side.px /= 4.0 * on_board.size();
  side.m /= 4.0 * on_board.size();
  return side;
}

// Needs the checked board fit through the found markers' correspondences (*corr, *board_fit);
// reads the markers the scan missed where the fit puts them, again after each round that
// placed some (the fit through more of the board extrapolates less), appends those kept to
// *placed and their corners to *corr, and refits *board_fit. False when a refit exceeds
// max_residual_px. O(missing * (rounds + side)).
bool PlaceMissingMarkers(const MarkerBoardContext& ctx,
                         const std::vector<const DecodedMarker*>& on_board, double max_residual_px,
                         Correspondences* corr, std::optional<BoardFit>* board_fit,
                         std::vector<DecodedMarker>* placed) {
  std::vector<int> missing;
  for (const auto& entry : ctx.board_markers) {
    // Not a structured binding: clang 14 (the fuzz build) cannot capture one in a lambda.
    const int id = entry.first;
    if (std::none_of(on_board.begin(), on_board.end(),
                     [id](const DecodedMarker* m) { return m->id == id; })) {
      missing.push_back(id);
    }
  }
  for (std::size_t placed_before = 0; !missing.empty(); placed_before = placed->size()) {
    std::vector<int> still_missing;
    for (int id : missing) {
      const std::vector<const BoardFeature*>& f = ctx.board_markers.at(id);
      const std::array<Eigen::Vector2d, 4> d = OutwardDiagonals(f);
      std::array<Eigen::Vector2d, 4> corners;
      for (int c = 0; c < 4; ++c) {
        corners[c] =
            ApplyHomography((*board_fit)->fit.H, f[c]->p_board + (*board_fit)->dilation_m * d[c]);
      }
      std::optional<DecodedMarker> marker =
          ReadPredictedMarker(ctx.image, ctx.family, id, corners, ctx.min_contrast);
      if (marker.has_value()) FitSmallMarkerToPage(ctx, &*marker);
      // The board's homography through its other markers places a corner within a small part
      // of a cell (what is left is lens distortion over a marker pitch or two); edges that
      // pull a corner farther are not this marker's edges, or too blurred to place it. Small
      // markers are judged after their page fit: dark print within a cell of their border
      // (the round-hole board's black cells) pulls their edge-point corners by up to half a
      // cell.
      if (!marker.has_value() ||
          !WithinCells(marker->corners_px, corners, ctx.family.cells, kPlacedMarkerMaxMoveCells)) {
        still_missing.push_back(id);
        continue;
      }
      placed->push_back(*marker);
      corr->Add(f, *marker);
    }
    if (placed->size() == placed_before) break;
    *board_fit =
        FitBoard(corr->p_board, corr->diagonal, corr->uv, on_board.size() + placed->size());
    if (!board_fit->has_value() || (*board_fit)->fit.max_residual > max_residual_px) return false;
    missing = std::move(still_missing);
  }
  return true;
}

// Needs the final board fit, the board's scale in the image and every marker of the board
// found or placed; gives the detection (CheckAndReport) with the fit's homography as the
// board's model and its dilation taken out of the corners.
Detection ReportFittedBoard(const MarkerBoardContext& ctx, const BoardFit& fitted, double px_per_m,
                            const std::vector<const DecodedMarker*>& on_board,
                            const std::vector<const DecodedMarker*>& others, const Board* sibling) {
  BoardInImage model;
  model.to_image = [&fitted](const Eigen::Vector2d& p) -> std::optional<Eigen::Vector2d> {
    return ApplyHomography(fitted.fit.H, p);
  };
  model.H_image_board = fitted.fit.H;
  model.px_per_m = px_per_m;
  // The corner as printed: the dilation taken out where the fit places it.
  model.printed = [&fitted](const Eigen::Vector2d& corner_px, const Eigen::Vector2d& p_board,
                            const Eigen::Vector2d& diagonal) -> Eigen::Vector2d {
    const Eigen::Vector2d dilated_board = p_board + fitted.dilation_m * diagonal;
    const Eigen::Vector2d dilated_px = ApplyHomography(fitted.fit.H, dilated_board);
    const Eigen::Vector2d printed_px = ApplyHomography(fitted.fit.H, p_board);
    Eigen::Vector2d corrected = corner_px;
    corrected += printed_px - dilated_px;
    return corrected;
  };
  return CheckAndReport(model, on_board, ctx.board_markers, others, ctx.board, sibling, ctx.image,
                        ctx.options);
}

// Needs the board's markers and one choice of `scan`'s markers (another_board as SplitScan
// takes it); gives VerifyMarkerBoard's result for that choice.
Detection VerifyChosenMarkers(const MarkerScan& scan, const BoardMarkers& board_markers,
                              const std::vector<bool>& another_board, const Board& board,
                              const MarkerFamily& family, const MarkerDetectOptions& options,
                              const ImageView8& image, const Board* sibling) {
  ScanSplit split;
  if (std::optional<Detection> failure = SplitScan(scan, board_markers, another_board, &split))
    return *failure;
  std::vector<const DecodedMarker*>& on_board = split.on_board;
  const MarkerBoardContext ctx{board, family, options, image, board_markers, scan.min_contrast};
  // Small markers' sides placed on the page before any board fit (FitSmallMarkerToPage).
  std::vector<DecodedMarker> read;
  read.reserve(on_board.size());
  for (const DecodedMarker*& m : on_board) {
    read.push_back(*m);
    FitSmallMarkerToPage(ctx, &read.back());
    m = &read.back();
  }
  Correspondences corr;
  for (const DecodedMarker* m : on_board) corr.Add(board_markers.at(m->id), *m);
  const MeanSide side = MeanSideOf(on_board, board_markers);
  const double max_residual_px = std::min(options.max_residual_fraction * side.px,
                                          options.max_residual_cells * side.px / family.cells);
  std::optional<BoardFit> board_fit =
      FitBoard(corr.p_board, corr.diagonal, corr.uv, on_board.size());
  if (!board_fit.has_value() || board_fit->fit.max_residual > max_residual_px) {
    // No one homography holds the markers: a wrong board, or the board bent by a lens.
    const BentBoardInputs bent{on_board, board_markers, split.others, board,           family,
                               options,  image,         sibling,      side.px / side.m};
    return VerifyBentBoard(bent, scan.min_contrast);
  }
  // The markers the scan missed, where the checked board fit puts them.
  std::vector<DecodedMarker> placed;
  placed.reserve(board_markers.size() - on_board.size());
  if (!PlaceMissingMarkers(ctx, on_board, max_residual_px, &corr, &board_fit, &placed))
    return Fail(DetectReason::kVerificationFailed);
  for (const DecodedMarker& m : placed) on_board.push_back(&m);
  return ReportFittedBoard(ctx, *board_fit, side.px / side.m, on_board, split.others, sibling);
}

// Bounds the choices VerifyMarkerBoard tries when board ids are seen more than once: two
// boards of the same ids whole in one image (2^4 choices for a four-marker board), each
// choice one verification (about 0.2 ms, more on a bent board).
constexpr int kMaxIdChoices = 16;

// Needs the scan and the board's markers; gives every choice of one instance per board id the
// scan saw, each as SplitScan's another_board (the instances not chosen set), or an empty list
// when there are more than kMaxIdChoices. One choice, marking nothing, when no id is seen
// twice.
std::vector<std::vector<bool>> IdChoices(const MarkerScan& scan,
                                         const BoardMarkers& board_markers) {
  std::map<int, std::vector<std::size_t>> instances;  // board id -> its scan markers
  for (std::size_t i = 0; i < scan.markers.size(); ++i) {
    if (board_markers.count(scan.markers[i].id) != 0) instances[scan.markers[i].id].push_back(i);
  }
  std::vector<std::vector<bool>> choices = {std::vector<bool>(scan.markers.size(), false)};
  for (const auto& [id, at] : instances) {
    if (at.size() == 1) continue;
    if (choices.size() * at.size() > static_cast<std::size_t>(kMaxIdChoices)) return {};
    std::vector<std::vector<bool>> grown;
    for (const std::vector<bool>& c : choices) {
      for (std::size_t keep : at) {
        std::vector<bool>& g = grown.emplace_back(c);
        for (std::size_t i : at) g[i] = i != keep;
      }
    }
    choices = std::move(grown);
  }
  return choices;
}
}  // namespace

Detection VerifyMarkerBoard(const MarkerScan& scan, const Board& board, const MarkerFamily& family,
                            const MarkerDetectOptions& options, const ImageView8& image,
                            const Board* sibling) {
  const BoardMarkers board_markers = MarkersOfBoard(board);
  const std::vector<std::vector<bool>> choices = IdChoices(scan, board_markers);
  if (choices.size() == 1) {
    return VerifyChosenMarkers(scan, board_markers, choices[0], board, family, options, image,
                               sibling);
  }
  // An id seen twice: another board printing the same markers shows some of them (the
  // station's round-hole boards share ids 0..15; a board view's margin can hold a marker of
  // the next one). The board is the one choice of instances that verifies: found whole, else
  // partial; two such choices of the same kind cannot be told apart.
  std::optional<Detection> found, partial;
  int founds = 0, partials = 0;
  for (const std::vector<bool>& c : choices) {
    Detection d =
        VerifyChosenMarkers(scan, board_markers, c, board, family, options, image, sibling);
    if (d.found) {
      ++founds;
      found = std::move(d);
    } else if (d.reason == DetectReason::kPartial) {
      ++partials;
      partial = std::move(d);
    }
  }
  if (founds == 1) return *found;
  if (founds == 0 && partials == 1) return *partial;
  return Fail(DetectReason::kAmbiguous);
}

Detection DetectMarkerBoard(const ImageView8& image, const Board& board, const MarkerFamily& family,
                            const MarkerDetectOptions& options, const Board* sibling,
                            int enough_markers) {
  // Levels halved once and twice, each still holding a marker of the smallest side the
  // options allow twice over; the coarsest first.
  std::vector<Image8> levels = HalvingPyramid(image, 2 * options.min_marker_side_px);
  if (levels.size() > 2) levels.resize(2);
  for (int level = static_cast<int>(levels.size()); level >= 1; --level) {
    MarkerScan scan = ScanMarkers(levels[level - 1].view(), family, options, enough_markers);
    std::vector<DecodedMarker> refined;
    refined.reserve(scan.markers.size());
    for (DecodedMarker m : scan.markers) {
      for (int k = 0; k < 4; ++k) m.corners_px[k] = LevelToImage(m.corners_px[k], level);
      double side = 0.0;
      for (int k = 0; k < 4; ++k)
        side += 0.25 * (m.corners_px[(k + 1) % 4] - m.corners_px[k]).norm();
      const int samples = std::clamp(static_cast<int>(side), 8, 80);
      // The corners are in the canonical order (clockwise in the image from the marker's
      // top-left), so the cells are the marker's own. The reduced corners are within a
      // reduced pixel or so; the second pass re-centres the edge windows.
      const std::vector<std::uint8_t> light = MarkerCells(family, m.id);
      if (!RefineQuadCorners(image, family, &light, samples, 0.5, &m.corners_px) ||
          !RefineQuadCorners(image, family, &light, samples, 0.34, &m.corners_px)) {
        continue;
      }
      refined.push_back(m);
    }
    scan.markers = std::move(refined);
    Detection coarse = VerifyMarkerBoard(scan, board, family, options, image, sibling);
    if (coarse.found) return coarse;
  }
  return VerifyMarkerBoard(ScanMarkers(image, family, options, enough_markers), board, family,
                           options, image, sibling);
}

}  // namespace linecal

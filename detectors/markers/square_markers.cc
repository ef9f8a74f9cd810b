#include "detectors/markers/square_markers.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <map>
#include <span>

#include <apriltag/tag36h11.h>

#include "detectors/boards/aruco_dict_4x4_50.h"
#include "detectors/common/contours.h"
#include "detectors/common/homography.h"

namespace linecal {
namespace {

// Binarisation tiles: 4 x 4 pixels, the smallest marker cell of acceptance.md, so that a
// 3 x 3 tile window (12 px) always spans a dark and a light cell of the smallest markers.
constexpr int kTile = 4;
// Low-contrast tiles take the mean threshold of their known neighbours, repeatedly: this
// many passes reach 64 px into a flat area, the half-width of the largest black cell of a
// board filling 80% of a 2448 px image (ArUco border cell: 71 px wide).
constexpr int kThresholdPropagationPasses = 16;

// Bilinear grey level of an 8-bit view at (u, v), pixel-centre convention; the caller keeps
// (u, v) at least one pixel inside the image.
double Bilinear(const ImageView8& image, double u, double v) {
  const int x = static_cast<int>(u);
  const int y = static_cast<int>(v);
  const double fx = u - x;
  const double fy = v - y;
  const std::uint8_t* r0 = image.Row(y) + x;
  const std::uint8_t* r1 = image.Row(y + 1) + x;
  const double top = r0[0] + fx * (r0[1] - r0[0]);
  const double bottom = r1[0] + fx * (r1[1] - r1[0]);
  return top + fy * (bottom - top);
}

bool InsideForSampling(const ImageView8& image, const Eigen::Vector2d& p) {
  return p.x() >= 0.0 && p.y() >= 0.0 && p.x() < image.width - 1.0 &&
         p.y() < image.height - 1.0;
}

// Immerkaer's noise estimate made robust to edges: the median absolute response of the
// Laplacian-difference kernel [1 -2 1; -2 4 -2; 1 -2 1] (std 6 sigma on white noise) over a
// sparse grid of pixels, divided by 0.6745 (the median of |N(0, 1)|) and 6. O(W * H / 8).
double EstimateNoiseSigma(const ImageView8& image) {
  if (image.width < 3 || image.height < 3) return 0.0;
  std::vector<int> histogram(4 * 255 * 4 + 1, 0);
  long count = 0;
  // Every 4th row and 2nd column: ample samples for a median, an eighth of the cost.
  for (int y = 1; y + 1 < image.height; y += 4) {
    const std::uint8_t* a = image.Row(y - 1);
    const std::uint8_t* b = image.Row(y);
    const std::uint8_t* c = image.Row(y + 1);
    for (int x = 1; x + 1 < image.width; x += 2) {
      const int r = a[x - 1] - 2 * a[x] + a[x + 1] - 2 * (b[x - 1] - 2 * b[x] + b[x + 1]) +
                    c[x - 1] - 2 * c[x] + c[x + 1];
      ++histogram[std::abs(r)];
      ++count;
    }
  }
  long seen = 0;
  for (int v = 0; v < static_cast<int>(histogram.size()); ++v) {
    seen += histogram[v];
    if (2 * seen >= count) return v / (0.6745 * 6.0);
  }
  return 0.0;
}

// 1 where a pixel is darker than halfway between the local minimum and maximum (over the
// 3 x 3 tiles around its tile); 0 elsewhere, including areas without printed contrast that
// no threshold reaches. *max_contrast: the largest local max - min seen.
Image8 BinariseDark(const ImageView8& image, int min_contrast, int* max_contrast) {
  const int tw = (image.width + kTile - 1) / kTile;
  const int th = (image.height + kTile - 1) / kTile;
  std::vector<std::uint8_t> tmin(static_cast<std::size_t>(tw) * th, 255);
  std::vector<std::uint8_t> tmax(static_cast<std::size_t>(tw) * th, 0);
  // The extremes are taken over 2 x 2 pixel means, which halve the noise (a 4 px cell still
  // holds nine such means entirely inside it). Plain loops over rows, which vectorise.
  const int w = image.width;
  std::vector<std::uint16_t> pairs_a(static_cast<std::size_t>(w));
  std::vector<std::uint16_t> pairs_b(static_cast<std::size_t>(w));
  std::vector<std::uint8_t> means(static_cast<std::size_t>(tw) * kTile, 0);
  auto horizontal_pairs = [w](const std::uint8_t* row, std::uint16_t* out) {
    for (int x = 0; x + 1 < w; ++x) out[x] = static_cast<std::uint16_t>(row[x] + row[x + 1]);
    out[w - 1] = static_cast<std::uint16_t>(2 * row[w - 1]);
  };
  horizontal_pairs(image.Row(0), pairs_a.data());
  for (int y = 0; y < image.height; ++y) {
    horizontal_pairs(image.Row(std::min(y + 1, image.height - 1)), pairs_b.data());
    for (int x = 0; x < w; ++x) {
      means[x] = static_cast<std::uint8_t>((pairs_a[x] + pairs_b[x] + 2) >> 2);
    }
    // The padding of the last tile repeats its last mean, which changes no extreme.
    for (int x = w; x < tw * kTile; ++x) means[x] = means[w - 1];
    std::uint8_t* mn = &tmin[static_cast<std::size_t>(y / kTile) * tw];
    std::uint8_t* mx = &tmax[static_cast<std::size_t>(y / kTile) * tw];
    for (int tx = 0; tx < tw; ++tx) {
      const std::uint8_t* m = &means[static_cast<std::size_t>(tx) * kTile];
      const std::uint8_t lo = std::min(std::min(m[0], m[1]), std::min(m[2], m[3]));
      const std::uint8_t hi = std::max(std::max(m[0], m[1]), std::max(m[2], m[3]));
      mn[tx] = std::min(mn[tx], lo);
      mx[tx] = std::max(mx[tx], hi);
    }
    pairs_a.swap(pairs_b);
  }
  // Twice the threshold per tile, or -1 where the tile has no contrast of its own.
  std::vector<int> thr2(static_cast<std::size_t>(tw) * th, -1);
  *max_contrast = 0;
  for (int ty = 0; ty < th; ++ty) {
    for (int tx = 0; tx < tw; ++tx) {
      int lo = 255;
      int hi = 0;
      for (int dy = -1; dy <= 1; ++dy) {
        const int yy = ty + dy;
        if (yy < 0 || yy >= th) continue;
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = tx + dx;
          if (xx < 0 || xx >= tw) continue;
          lo = std::min<int>(lo, tmin[static_cast<std::size_t>(yy) * tw + xx]);
          hi = std::max<int>(hi, tmax[static_cast<std::size_t>(yy) * tw + xx]);
        }
      }
      *max_contrast = std::max(*max_contrast, hi - lo);
      if (hi - lo >= min_contrast) thr2[static_cast<std::size_t>(ty) * tw + tx] = lo + hi;
    }
  }
  // Breadth-first, one ring of tiles per pass: each unknown tile next to known ones takes
  // their mean, so the cost is the number of tiles reached, not passes x tiles.
  std::vector<std::uint8_t> queued(thr2.size(), 0);
  std::vector<int> frontier;
  auto push_unknown_neighbours = [&](int i, std::vector<int>* out) {
    const int tx = i % tw;
    const int ty = i / tw;
    const std::array<int, 4> nb = {tx > 0 ? i - 1 : -1, tx + 1 < tw ? i + 1 : -1,
                                   ty > 0 ? i - tw : -1, ty + 1 < th ? i + tw : -1};
    for (int j : nb) {
      if (j >= 0 && thr2[j] < 0 && queued[j] == 0) {
        queued[j] = 1;
        out->push_back(j);
      }
    }
  };
  for (int i = 0; i < tw * th; ++i) {
    if (thr2[i] >= 0) push_unknown_neighbours(i, &frontier);
  }
  std::vector<int> values;
  std::vector<int> next;
  for (int pass = 0; pass < kThresholdPropagationPasses && !frontier.empty(); ++pass) {
    values.assign(frontier.size(), -1);
    for (std::size_t f = 0; f < frontier.size(); ++f) {
      const int i = frontier[f];
      const int tx = i % tw;
      const int ty = i / tw;
      int sum = 0;
      int n = 0;
      const std::array<int, 4> nb = {tx > 0 ? i - 1 : -1, tx + 1 < tw ? i + 1 : -1,
                                     ty > 0 ? i - tw : -1, ty + 1 < th ? i + tw : -1};
      for (int j : nb) {
        if (j >= 0 && thr2[j] >= 0) {
          sum += thr2[j];
          ++n;
        }
      }
      values[f] = sum / n;  // n >= 1: the tile was queued next to a known one
    }
    for (std::size_t f = 0; f < frontier.size(); ++f) thr2[frontier[f]] = values[f];
    next.clear();
    for (int i : frontier) push_unknown_neighbours(i, &next);
    frontier.swap(next);
  }
  Image8 dark(image.width, image.height, 0);
  // Per tile row, the doubled threshold of every pixel column (0 where unknown: 2 v < 0
  // never holds), so that the per-pixel loop is a plain comparison.
  std::vector<std::int16_t> column_thr2(static_cast<std::size_t>(tw) * kTile);
  for (int y = 0; y < image.height; ++y) {
    if (y % kTile == 0) {
      const int* t = &thr2[static_cast<std::size_t>(y / kTile) * tw];
      for (int x = 0; x < tw * kTile; ++x) {
        column_thr2[x] = static_cast<std::int16_t>(std::max(t[x / kTile], 0));
      }
    }
    const std::uint8_t* row = image.Row(y);
    std::uint8_t* out = &dark.pixels[static_cast<std::size_t>(y) * image.width];
    for (int x = 0; x < w; ++x) {
      out[x] = static_cast<std::uint8_t>(2 * static_cast<std::int16_t>(row[x]) < column_thr2[x]);
    }
  }
  return dark;
}

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
// Returns false when a side has too few edge points or a corner moves more than
// max_move_cells cells.
bool RefineQuadCorners(const ImageView8& image, const MarkerFamily& family,
                       const std::vector<std::uint8_t>* light, int samples,
                       double max_move_cells, std::array<Eigen::Vector2d, 4>* corners) {
  const int cells = family.cells;
  const int border = family.border_cells;
  std::array<Eigen::Vector2d, 4> point;
  std::array<Eigen::Vector2d, 4> dir;
  const double step = 0.5;  // profile step, px: finer gains nothing after bilinear sampling
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d a = (*corners)[k];
    const Eigen::Vector2d b = (*corners)[(k + 1) % 4];
    const double len = (b - a).norm();
    if (len < 2.0) return false;
    const Eigen::Vector2d d = (b - a) / len;
    // The cell size across this side: the mean length of the two neighbouring sides.
    const double across_px = 0.5 * (((*corners)[(k + 2) % 4] - b).norm() +
                                     (a - (*corners)[(k + 3) % 4]).norm()) / cells;
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
          case 0: r = border, c = along; break;
          case 1: r = along, c = cells - 1 - border; break;
          case 2: r = cells - 1 - border, c = cells - 1 - along; break;
          default: r = cells - 1 - along, c = border; break;
        }
        if ((*light)[static_cast<std::size_t>(r) * cells + c] == 0) band[i] = border + 1;
        widest = std::max(widest, band[i]);
      }
      // The wide points alone must still fix the line's direction: at least four of them,
      // spread over half the side. Otherwise use all.
      int first_wide = samples;
      int last_wide = -1;
      int wide_count = 0;
      for (int i = 0; i < samples; ++i) {
        if (band[i] != widest) continue;
        first_wide = std::min(first_wide, i);
        last_wide = i;
        ++wide_count;
      }
      if (wide_count < 4 || 2 * (last_wide - first_wide + 1) < samples) widest = border;
    }
    std::vector<Eigen::Vector2d> pts;
    std::vector<double> weights;
    pts.reserve(samples);
    weights.reserve(samples);
    for (int i = 0; i < samples; ++i) {
      if (band[i] < widest) continue;
      const double half_window_px = std::clamp(0.5 * band[i] * across_px, 1.0, 4.0);
      const double t = (border + (cells - 2.0 * border) * (i + 0.5) / samples) / cells;
      const Eigen::Vector2d q = a + t * (b - a);
      if (!InsideForSampling(image, q + (half_window_px + 1.0) * n) ||
          !InsideForSampling(image, q - (half_window_px + 1.0) * n)) {
        continue;
      }
      double g_max = 0.0;
      std::array<double, 24> g;
      std::array<double, 24> s;
      int m = 0;
      for (double o = -half_window_px; o <= half_window_px + 1e-9 && m < 24; o += step, ++m) {
        const Eigen::Vector2d p1 = q + (o + 0.5 * step) * n;
        const Eigen::Vector2d p0 = q + (o - 0.5 * step) * n;
        g[m] = Bilinear(image, p1.x(), p1.y()) - Bilinear(image, p0.x(), p0.y());
        s[m] = o;
        g_max = std::max(g_max, g[m]);
      }
      if (g_max <= 0.0) continue;
      // Gradients under a quarter of the peak are noise or the tail of another edge.
      const double floor = 0.25 * g_max;
      double sw = 0.0;
      double sws = 0.0;
      for (int j = 0; j < m; ++j) {
        if (g[j] <= floor) continue;
        sw += g[j] - floor;
        sws += (g[j] - floor) * s[j];
      }
      if (sw <= 0.0) continue;
      pts.push_back(q + (sws / sw) * n);
      weights.push_back(g_max);
    }
    // Two points define a line; four make a fit that averages noise.
    if (pts.size() < 4) return false;
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    double wsum = 0.0;
    for (std::size_t i = 0; i < pts.size(); ++i) {
      mean += weights[i] * pts[i];
      wsum += weights[i];
    }
    mean /= wsum;
    Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const Eigen::Vector2d r = pts[i] - mean;
      cov += weights[i] * r * r.transpose();
    }
    // The principal axis of a 2 x 2 covariance, in closed form.
    const double angle = 0.5 * std::atan2(2.0 * cov(0, 1), cov(0, 0) - cov(1, 1));
    Eigen::Vector2d axis(std::cos(angle), std::sin(angle));
    if (axis.dot(d) < 0.0) axis = -axis;
    point[k] = mean;
    dir[k] = axis;
  }
  std::array<Eigen::Vector2d, 4> out;
  for (int k = 0; k < 4; ++k) {
    // Corner k starts side k and ends side k - 1.
    const int j = (k + 3) % 4;
    const double denom = dir[j].x() * dir[k].y() - dir[j].y() * dir[k].x();
    // Sides within ~3 degrees of parallel do not define a corner.
    if (std::abs(denom) < 0.05) return false;
    const Eigen::Vector2d w = point[k] - point[j];
    const double t = (w.x() * dir[k].y() - w.y() * dir[k].x()) / denom;
    out[k] = point[j] + t * dir[j];
    const double cell_px =
        0.5 * (((*corners)[(k + 1) % 4] - (*corners)[k]).norm() +
               ((*corners)[k] - (*corners)[j]).norm()) / cells;
    if ((out[k] - (*corners)[k]).norm() > max_move_cells * cell_px) return false;
  }
  *corners = out;
  return true;
}

// Grey level of each cell (row-major, cells x cells) of the quad, from a 3 x 3 grid of
// bilinear samples over the middle half of the cell (clear of blurred cell edges).
// False when the homography fails or a sample leaves the image.
bool SampleCells(const ImageView8& image, const std::array<Eigen::Vector2d, 4>& corners,
                 int cells, std::vector<double>* values) {
  const std::array<Eigen::Vector2d, 4> src = {
      Eigen::Vector2d(0, 0), Eigen::Vector2d(cells, 0), Eigen::Vector2d(cells, cells),
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
          if (!InsideForSampling(image, p)) return false;
          sum += Bilinear(image, p.x(), p.y());
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
  int rotation = 0;  // the observed corner that is the marker's top-left
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
  result.marker.dark_level = dark;
  result.marker.light_level = light;
  for (int c = 0; c < 4; ++c) result.marker.corners_px[c] = corners[(decode.rotation + c) % 4];
  return result;
}

// Refines, reads and decodes one candidate quad. A coarse pass (8 edge points per side)
// for every candidate, since the contour corners may be a cell off on blurred, small quads;
// the fine pass (an edge point per pixel of side, up to 80) only for decoded markers,
// twice: the second re-centres the edge windows on the refined lines, within a third of a
// cell.
std::optional<DecodedMarker> ReadQuad(const ImageView8& image, const Quad& quad,
                                      const MarkerFamily& family, double min_contrast) {
  std::array<Eigen::Vector2d, 4> corners = quad.corners_px;
  double side = 0.0;
  for (int k = 0; k < 4; ++k) side += 0.25 * (corners[(k + 1) % 4] - corners[k]).norm();
  if (!RefineQuadCorners(image, family, nullptr, 8, 1.0, &corners)) return std::nullopt;
  std::optional<ReadResult> marker = ReadMarker(image, corners, family, min_contrast);
  if (!marker.has_value()) return std::nullopt;
  const int fine_samples = std::clamp(static_cast<int>(side), 8, 80);
  for (int pass = 0; pass < 2; ++pass) {
    if (!RefineQuadCorners(image, family, &marker->light, fine_samples, 0.34, &corners)) {
      return std::nullopt;
    }
  }
  for (int c = 0; c < 4; ++c) marker->marker.corners_px[c] = corners[(marker->rotation + c) % 4];
  return marker->marker;
}

// The binary image eroded by one pixel (a set pixel stays set only when its four neighbours
// are set; off-image counts as unset). Breaks one-pixel bridges between shapes that touch
// at a corner. O(W * H).
Image8 Erode(const Image8& in) {
  Image8 out(in.width, in.height, 0);
  for (int y = 1; y + 1 < in.height; ++y) {
    const std::uint8_t* up = &in.pixels[static_cast<std::size_t>(y - 1) * in.width];
    const std::uint8_t* mid = up + in.width;
    const std::uint8_t* down = mid + in.width;
    std::uint8_t* o = &out.pixels[static_cast<std::size_t>(y) * in.width];
    for (int x = 1; x + 1 < in.width; ++x) {
      o[x] = static_cast<std::uint8_t>(mid[x] & mid[x - 1] & mid[x + 1] & up[x] & down[x]);
    }
  }
  return out;
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
  if (!(max_residual_fraction > 0.0 && max_residual_fraction <= 1.0)) {
    return "max_residual_fraction";
  }
  if (!(min_paint_agreement >= 0.0 && min_paint_agreement <= 1.0)) return "min_paint_agreement";
  return {};
}

MarkerFamily Aruco4x4_50Family() {
  MarkerFamily family;
  family.cells = kAruco4x4MarkerCells;
  family.border_cells = 1;
  for (int i = 0; i < kAruco4x4DataBits * kAruco4x4DataBits; ++i) {
    family.bit_cells.push_back({1 + i / kAruco4x4DataBits, 1 + i % kAruco4x4DataBits});
  }
  family.codes.assign(kAruco4x4_50Codes.begin(), kAruco4x4_50Codes.end());
  family.max_correction_bits = kAruco4x4_50MaxCorrectionBits;
  return family;
}

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

MarkerScan ScanMarkers(const ImageView8& image, const MarkerFamily& family,
                       const MarkerDetectOptions& options, int enough_markers) {
  MarkerScan scan;
  if (image.width < options.min_marker_side_px || image.height < options.min_marker_side_px) {
    scan.reason = DetectReason::kBadImage;
    return scan;
  }
  const double noise_sigma = EstimateNoiseSigma(image);
  const int min_contrast = std::max(
      options.min_contrast,
      static_cast<int>(std::ceil(options.noise_contrast_factor * noise_sigma)));
  int max_contrast = 0;
  scan.dark = BinariseDark(image, min_contrast, &max_contrast);
  if (max_contrast < min_contrast) {
    scan.reason = DetectReason::kLowContrast;
    return scan;
  }
  QuadOptions quad_options;
  quad_options.min_side_px = options.min_marker_side_px;
  Image8 eroded;
  for (int erosion = 0; erosion <= options.max_erosion_px; ++erosion) {
    if (erosion > 0 && enough_markers > 0 &&
        static_cast<int>(scan.markers.size()) >= enough_markers) {
      break;
    }
    if (erosion > 0) eroded = Erode(erosion == 1 ? scan.dark : eroded);
    const ComponentLabels labels = LabelComponents((erosion == 0 ? scan.dark : eroded).view());
    for (const Quad& quad : FindQuads(labels, quad_options)) {
      if (scan.quads >= options.max_candidates) break;
      // A quad around a marker already read (at a smaller erosion) is that marker again.
      Eigen::Vector2d centre = Eigen::Vector2d::Zero();
      for (const Eigen::Vector2d& c : quad.corners_px) centre += 0.25 * c;
      if (std::any_of(scan.markers.begin(), scan.markers.end(),
                      [&](const DecodedMarker& m) { return InsideQuad(m.corners_px, centre); })) {
        continue;
      }
      ++scan.quads;
      std::optional<DecodedMarker> marker = ReadQuad(image, quad, family, min_contrast);
      if (marker.has_value()) scan.markers.push_back(*marker);
    }
  }
  if (scan.markers.empty()) scan.reason = DetectReason::kNoCandidates;
  return scan;
}

namespace {

// Probes per side of the board's page for the paint check: a 1100 mm board gets a probe
// every 34 mm, several per printed area of any of the marker boards.
constexpr int kPaintProbesPerSide = 32;
// A paint probe is used only when the board is uniform this many pixels around it (blur of
// up to 1.5 px, plus the homography's error, must not reach an edge).
constexpr double kPaintProbeClearancePx = 3.0;
// Fewer probes of a paint than this say nothing about it.
constexpr int kMinPaintProbes = 8;

// True when the image agrees with the board's printed paint: of the probes on the page that
// are clear of edges and inside the image, at least min_agreement of the black ones are dark
// in `dark` and of the white ones light (each paint checked only with kMinPaintProbes).
bool PaintAgrees(const Board& board, const Eigen::Matrix3d& H_image_board, const Image8& dark,
                 double px_per_m, double min_agreement) {
  const Eigen::Vector2d page = board.page_size_m();
  const double clearance_m = kPaintProbeClearancePx / px_per_m;
  std::array<int, 2> total = {0, 0};  // white, black
  std::array<int, 2> agree = {0, 0};
  for (int iy = 0; iy < kPaintProbesPerSide; ++iy) {
    for (int ix = 0; ix < kPaintProbesPerSide; ++ix) {
      const Eigen::Vector2d p(page.x() * ((ix + 0.5) / kPaintProbesPerSide - 0.5),
                              page.y() * ((iy + 0.5) / kPaintProbesPerSide - 0.5));
      const Paint paint = board.PaintAt(p);
      if (paint != Paint::kWhite && paint != Paint::kBlack) continue;
      bool uniform = true;
      for (int k = 0; k < 4 && uniform; ++k) {
        const Eigen::Vector2d q(p.x() + ((k & 1) ? clearance_m : -clearance_m),
                                p.y() + ((k & 2) ? clearance_m : -clearance_m));
        uniform = board.PaintAt(q) == paint;
      }
      if (!uniform) continue;
      const Eigen::Vector2d uv = ApplyHomography(H_image_board, p);
      if (!(uv.x() >= 0.0 && uv.y() >= 0.0 && uv.x() <= dark.width - 1.0 &&
            uv.y() <= dark.height - 1.0)) {
        continue;
      }
      const bool is_dark = dark.at(static_cast<int>(std::lround(uv.x())),
                                   static_cast<int>(std::lround(uv.y()))) != 0;
      const int k = paint == Paint::kBlack ? 1 : 0;
      ++total[k];
      if (is_dark == (k == 1)) ++agree[k];
    }
  }
  for (int k = 0; k < 2; ++k) {
    if (total[k] >= kMinPaintProbes && agree[k] < min_agreement * total[k]) return false;
  }
  return total[0] + total[1] >= kMinPaintProbes;
}

Detection Fail(DetectReason reason) {
  Detection d;
  d.found = false;
  d.reason = reason;
  return d;
}

}  // namespace

Detection VerifyMarkerBoard(const MarkerScan& scan, const Board& board,
                            const MarkerDetectOptions& options) {
  // The board's markers: id -> its four corner features, in corner order (ids 4 k + c).
  std::map<int, std::vector<const BoardFeature*>> board_markers;
  for (const BoardFeature& f : board.features()) {
    if (f.kind == FeatureKind::kMarkerCorner) board_markers[f.marker].push_back(&f);
  }
  std::vector<const DecodedMarker*> on_board;
  std::vector<const DecodedMarker*> others;
  for (const DecodedMarker& m : scan.markers) {
    (board_markers.count(m.id) != 0 ? on_board : others).push_back(&m);
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
  std::vector<Eigen::Vector2d> p_board;
  std::vector<Eigen::Vector2d> uv;
  double side_px = 0.0;
  double side_m = 0.0;
  for (const DecodedMarker* m : on_board) {
    const std::vector<const BoardFeature*>& f = board_markers.at(m->id);
    for (int c = 0; c < 4; ++c) {
      p_board.push_back(f[c]->p_board);
      uv.push_back(m->corners_px[c]);
      side_px += (m->corners_px[(c + 1) % 4] - m->corners_px[c]).norm();
      side_m += (f[(c + 1) % 4]->p_board - f[c]->p_board).norm();
    }
  }
  side_px /= 4.0 * on_board.size();
  side_m /= 4.0 * on_board.size();
  const std::optional<HomographyFit> fit = FitHomography(p_board, uv);
  if (!fit.has_value() || fit->max_residual > options.max_residual_fraction * side_px) {
    return Fail(DetectReason::kVerificationFailed);
  }
  // A marker of another id on this board's page: another board that shares some ids.
  const Eigen::Matrix3d H_board_image = fit->H.inverse();
  const Eigen::Vector2d half_page = 0.5 * board.page_size_m();
  for (const DecodedMarker* m : others) {
    Eigen::Vector2d centre = Eigen::Vector2d::Zero();
    for (const Eigen::Vector2d& c : m->corners_px) centre += 0.25 * c;
    const Eigen::Vector2d p = ApplyHomography(H_board_image, centre);
    if (std::abs(p.x()) < half_page.x() && std::abs(p.y()) < half_page.y()) {
      return Fail(DetectReason::kWrongBoard);
    }
  }
  if (!PaintAgrees(board, fit->H, scan.dark, side_px / side_m, options.min_paint_agreement)) {
    return Fail(DetectReason::kWrongBoard);
  }
  Detection detection;
  detection.found = on_board.size() == board_markers.size();
  detection.reason = detection.found ? DetectReason::kNone : DetectReason::kPartial;
  for (const DecodedMarker* m : on_board) {
    const std::vector<const BoardFeature*>& f = board_markers.at(m->id);
    for (int c = 0; c < 4; ++c) {
      DetectedFeature feature;
      feature.id = f[c]->id;
      feature.uv_px = m->corners_px[c];
      feature.p_board = f[c]->p_board;
      feature.marker = m->id;
      detection.features.push_back(feature);
    }
  }
  std::sort(detection.features.begin(), detection.features.end(),
            [](const DetectedFeature& a, const DetectedFeature& b) { return a.id < b.id; });
  return detection;
}

}  // namespace linecal

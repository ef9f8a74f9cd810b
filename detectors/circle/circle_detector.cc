#include "detectors/circle/circle_detector.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <optional>
#include <span>
#include <utility>
#include <vector>

#include "detectors/common/contours.h"
#include "detectors/common/ellipse.h"
#include "detectors/common/homography.h"
#include "detectors/common/image_filters.h"

namespace linecal {
namespace {

constexpr double kPi = std::numbers::pi;


// The candidate stage's image is reduced while it keeps at least this many pixels (a
// 1280 x 720 image stays at factor 2, 640 x 360; 2448 x 2048 starts at factor 4): about
// 50 px per circle of a board over a third of the image, plenty for the blob stage.
constexpr double kMinCandidatePixels = 2e5;
// The most a thresholded blob's edge moves from the printed circle's, full-resolution
// pixels: blur 1.5 px, gamma 0.6-1.6 and noise 6 of docs/acceptance.md's hardest renders moved
// the 12 px circles' dark blobs by up to 1.8 px.
constexpr double kMaxEdgeShiftPx = 2.0;

// ---- The board model --------------------------------------------------------------------

// What the detector needs to know about the circle board, derived from Board (so a scaled
// board works unchanged).
struct CircleBoardModel {
  std::vector<Eigen::Vector2d> p_board;  // circle centres by feature id, metres
  std::vector<bool> light;               // true: a white circle on black
  double radius_m = 0.0;
  std::array<int, 2> pair = {-1, -1};  // the black pair, left then right
  Eigen::Vector2d pair_mid = Eigen::Vector2d::Zero();
  std::vector<int> rotated;                   // the id at the 180-degree image of each circle
  std::vector<int> growth_order;              // ids other than the pair, nearest to pair_mid first
  std::vector<Eigen::Vector2d> dark_points;   // printed black; their 180-degree images white
  std::vector<Eigen::Vector2d> light_points;  // the 180-degree images of dark_points
  Eigen::Vector2d black_reference = Eigen::Vector2d::Zero();  // black between circles
};

Eigen::Vector2d Rotate180(const Eigen::Vector2d& p, const Eigen::Vector2d& centre) {
  return 2.0 * centre - p;
}

std::optional<CircleBoardModel> MakeModel(const Board& board) {
  CircleBoardModel m;
  for (const BoardShape& shape : board.shapes()) {
    if (shape.geometry == ShapeGeometry::kCircle) {
      m.radius_m = shape.radius_m();
      break;
    }
  }
  std::vector<int> dark;
  for (const BoardFeature& f : board.features()) {
    m.p_board.push_back(f.p_board);
    const bool light = board.PaintAt(f.p_board) == Paint::kWhite;
    m.light.push_back(light);
    if (!light) dark.push_back(f.id);
  }
  if (dark.size() != 2 || !(m.radius_m > 0.0)) return std::nullopt;
  if (m.p_board[dark[0]].x() > m.p_board[dark[1]].x()) std::swap(dark[0], dark[1]);
  m.pair = {dark[0], dark[1]};
  m.pair_mid = 0.5 * (m.p_board[dark[0]] + m.p_board[dark[1]]);
  const int n = static_cast<int>(m.p_board.size());
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d image = Rotate180(m.p_board[i], m.pair_mid);
    int best = 0;
    for (int j = 1; j < n; ++j) {
      if ((m.p_board[j] - image).norm() < (m.p_board[best] - image).norm()) best = j;
    }
    m.rotated.push_back(best);
    if (i != m.pair[0] && i != m.pair[1]) m.growth_order.push_back(i);
  }
  std::stable_sort(m.growth_order.begin(), m.growth_order.end(), [&](int a, int b) {
    return (m.p_board[a] - m.pair_mid).norm() < (m.p_board[b] - m.pair_mid).norm();
  });
  // docs/boards.md: the black areas span PDF y 50..550 while the rows of circles span 100..380,
  // so PDF y 455 (75 mm below the last row's centres, 50 mm clear of its circles) is black
  // in every strip, and its image under the grid's 180-degree symmetry, PDF y 25, lies in
  // the middle of the white top margin. Board frame: PDF (x, y) -> (x - 450, 300 - y) mm.
  const double mm = 1e-3 * board.params().scale;
  for (const double x_pdf : {100.0, 300.0, 450.0, 600.0, 800.0}) {
    const Eigen::Vector2d p = mm * Eigen::Vector2d(x_pdf - 450.0, 300.0 - 455.0);
    m.dark_points.push_back(p);
    m.light_points.push_back(Rotate180(p, m.pair_mid));
  }
  // PDF (350, 135): black, 61 mm from the nearest circle centres; symmetric to PDF
  // (550, 345), also black.
  m.black_reference = mm * Eigen::Vector2d(350.0 - 450.0, 300.0 - 135.0);
  return m;
}

// ---- 1. Candidates ----------------------------------------------------------------------

// Tiles of the half image over which the local statistics are taken: 4 half pixels (8 full
// pixels) keep the tile grid small while the window spans many tiles.
constexpr int kTile = 4;

// The image averaged over factor x factor blocks (pixel (x, y) is centred on
// full-resolution factor * (x, y) + (factor - 1) / 2), with the sum, minimum and maximum of
// each kTile x kTile tile.
struct Reduced {
  int factor = 2;
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> pixels;
  int tiles_x = 0;
  int tiles_y = 0;
  std::vector<int> tile_sum;
  std::vector<int> tile_count;
  std::vector<std::uint8_t> tile_min;
  std::vector<std::uint8_t> tile_max;
  int min = 255;
  int max = 0;
};

Reduced Downsample(const ImageView8& image, int factor) {
  Reduced half;
  half.factor = factor;
  half.width = image.width / factor;
  half.height = image.height / factor;
  half.pixels.resize(static_cast<std::size_t>(half.width) * half.height);
  half.tiles_x = (half.width + kTile - 1) / kTile;
  half.tiles_y = (half.height + kTile - 1) / kTile;
  const std::size_t tiles = static_cast<std::size_t>(half.tiles_x) * half.tiles_y;
  half.tile_sum.resize(tiles);
  half.tile_count.resize(tiles);
  half.tile_min.resize(tiles);
  half.tile_max.resize(tiles);
  std::vector<int> block(half.width);
  const int area = factor * factor;
  // Loop bounds in a register: a byte store may alias `half`, which would keep the
  // compiler from vectorising loops bounded by half.width.
  const int width = half.width;
  const int full_width = image.width;
  std::vector<std::uint16_t> column(full_width);
  std::vector<int> col_sum(width, 0);
  std::vector<std::uint8_t> col_min(width, 255);
  std::vector<std::uint8_t> col_max(width, 0);
  for (int y = 0; y < half.height; ++y) {
    std::uint8_t* out = half.pixels.data() + static_cast<std::size_t>(y) * half.width;
    if (factor == 2) {
      const std::uint8_t* r0 = image.Row(2 * y);
      const std::uint8_t* r1 = image.Row(2 * y + 1);
      for (int x = 0; x < width; ++x) {
        out[x] = static_cast<std::uint8_t>(
            (r0[2 * x] + r0[2 * x + 1] + r1[2 * x] + r1[2 * x + 1] + 2) >> 2);
      }
    } else {
      // Columns summed over the block's rows (a straight vector loop), then each block's
      // columns; 16-bit sums hold factor * 255 for any factor up to 256.
      std::fill(column.begin(), column.end(), std::uint16_t{0});
      for (int dy = 0; dy < factor; ++dy) {
        const std::uint8_t* row = image.Row(factor * y + dy);
        for (int x = 0; x < full_width; ++x)
          column[x] = static_cast<std::uint16_t>(column[x] + row[x]);
      }
      for (int x = 0; x < width; ++x) {
        int sum = area / 2;  // rounds the mean to nearest
        for (int dx = 0; dx < factor; ++dx) sum += column[factor * x + dx];
        block[x] = sum;
      }
      for (int x = 0; x < width; ++x) out[x] = static_cast<std::uint8_t>(block[x] / area);
    }
    // Column statistics over the tile row's pixel rows (straight vector loops), reduced to
    // tiles at the tile row's last pixel row.
    for (int x = 0; x < width; ++x) {
      col_sum[x] += out[x];
      col_min[x] = std::min(col_min[x], out[x]);
      col_max[x] = std::max(col_max[x], out[x]);
    }
    if (y % kTile != kTile - 1 && y != half.height - 1) continue;
    const int rows = y % kTile + 1;
    const std::size_t t_row = static_cast<std::size_t>(y / kTile) * half.tiles_x;
    for (int tx = 0; tx < half.tiles_x; ++tx) {
      const int x_end = std::min(width, (tx + 1) * kTile);
      int sum = 0;
      int lo = 255;
      int hi = 0;
      for (int x = tx * kTile; x < x_end; ++x) {
        sum += col_sum[x];
        lo = std::min<int>(lo, col_min[x]);
        hi = std::max<int>(hi, col_max[x]);
      }
      const std::size_t t = t_row + tx;
      half.tile_sum[t] = sum;
      half.tile_count[t] = (x_end - tx * kTile) * rows;
      half.tile_min[t] = static_cast<std::uint8_t>(lo);
      half.tile_max[t] = static_cast<std::uint8_t>(hi);
      half.min = std::min(half.min, lo);
      half.max = std::max(half.max, hi);
    }
    std::fill(col_sum.begin(), col_sum.end(), 0);
    std::fill(col_min.begin(), col_min.end(), std::uint8_t{255});
    std::fill(col_max.begin(), col_max.end(), std::uint8_t{0});
  }
  return half;
}

// The light and dark masks (255 = set) of the half image: a pixel is light when it is above
// its neighbourhood's mean by more than a fraction of the neighbourhood's range, dark when
// below by as much; neighbourhoods with less range than min_contrast are left unset.
void Classify(const Reduced& half, int min_contrast, std::vector<std::uint8_t>* light,
              std::vector<std::uint8_t>* dark) {
  const int tw = half.tiles_x;
  const int th = half.tiles_y;
  // The window: about a fifth of the smaller image side, so that it holds a whole circle
  // and the black around it at the largest board size (80% of the image width), while it
  // follows illumination gradients across the board.
  const int k = std::max(2, std::min(half.width, half.height) / (10 * kTile));
  // Box mean by a summed-area table over tiles.
  const std::size_t sat_w = static_cast<std::size_t>(tw) + 1;
  std::vector<double> sat(sat_w * (th + 1), 0.0);
  std::vector<double> sat_n(sat.size(), 0.0);
  for (int ty = 0; ty < th; ++ty) {
    for (int tx = 0; tx < tw; ++tx) {
      const std::size_t t = static_cast<std::size_t>(ty) * tw + tx;
      const std::size_t s = (ty + 1) * sat_w + tx + 1;
      sat[s] = half.tile_sum[t] + sat[s - 1] + sat[s - sat_w] - sat[s - sat_w - 1];
      sat_n[s] = half.tile_count[t] + sat_n[s - 1] + sat_n[s - sat_w] - sat_n[s - sat_w - 1];
    }
  }
  // Range: separable sliding minimum and maximum over the same window.
  std::vector<std::uint8_t> row_lo(half.tile_min.size());
  std::vector<std::uint8_t> row_hi(half.tile_max.size());
  for (int ty = 0; ty < th; ++ty) {
    const std::size_t t_row = static_cast<std::size_t>(ty) * tw;
    for (int tx = 0; tx < tw; ++tx) {
      std::uint8_t a = 255;
      std::uint8_t b = 0;
      for (int x = std::max(0, tx - k); x <= std::min(tw - 1, tx + k); ++x) {
        a = std::min(a, half.tile_min[t_row + x]);
        b = std::max(b, half.tile_max[t_row + x]);
      }
      row_lo[t_row + tx] = a;
      row_hi[t_row + tx] = b;
    }
  }
  // Per tile, the grey levels below which a pixel is dark and above which it is light; a
  // tile without contrast gets bounds no pixel passes.
  std::vector<int> dark_below(half.tile_sum.size());
  std::vector<int> light_above(half.tile_sum.size());
  for (int ty = 0; ty < th; ++ty) {
    const int y0 = std::max(0, ty - k);
    const int y1 = std::min(th, ty + k + 1);
    for (int tx = 0; tx < tw; ++tx) {
      const int x0 = std::max(0, tx - k);
      const int x1 = std::min(tw, tx + k + 1);
      auto box = [&](const std::vector<double>& s) {
        return s[y1 * sat_w + x1] - s[y0 * sat_w + x1] - s[y1 * sat_w + x0] + s[y0 * sat_w + x0];
      };
      int a = 255;
      int b = 0;
      for (int y = y0; y < y1; ++y) {
        a = std::min<int>(a, row_lo[static_cast<std::size_t>(y) * tw + tx]);
        b = std::max<int>(b, row_hi[static_cast<std::size_t>(y) * tw + tx]);
      }
      const std::size_t t = static_cast<std::size_t>(ty) * tw + tx;
      if (b - a < min_contrast) {
        dark_below[t] = 0;
        light_above[t] = 255;
        continue;
      }
      const double mean = box(sat) / box(sat_n);
      // A white circle stands about 0.7 of the range above the mean of its black
      // surroundings and the black pair about 0.3 below the mean around the bar; 0.15 of
      // the range separates both from the mean with margin and keeps blurred rims out.
      const double offset = 0.15 * (b - a);
      dark_below[t] = static_cast<int>(std::ceil(mean - offset));
      light_above[t] = static_cast<int>(std::floor(mean + offset));
    }
  }
  light->resize(half.pixels.size());
  dark->resize(half.pixels.size());
  const int width = half.width;
  // The tile bounds spread over a row of pixels (shared by the kTile rows of a tile row),
  // so that the per-pixel comparison is one straight loop.
  std::vector<std::uint8_t> lo_row(half.width);
  std::vector<std::uint8_t> hi_row(half.width);
  for (int y = 0; y < half.height; ++y) {
    if (y % kTile == 0) {
      const std::size_t t_row = static_cast<std::size_t>(y / kTile) * tw;
      for (int x = 0; x < half.width; ++x) {
        lo_row[x] = static_cast<std::uint8_t>(std::clamp(dark_below[t_row + x / kTile], 0, 255));
        hi_row[x] = static_cast<std::uint8_t>(std::clamp(light_above[t_row + x / kTile], 0, 255));
      }
    }
    const std::size_t i_row = static_cast<std::size_t>(y) * half.width;
    const std::uint8_t* in = half.pixels.data() + i_row;
    std::uint8_t* l = light->data() + i_row;
    std::uint8_t* d = dark->data() + i_row;
    const std::uint8_t* lo = lo_row.data();
    const std::uint8_t* hi = hi_row.data();
    // Two straight loops over a bound held in a register (a byte store may alias `half`),
    // which the compiler turns into vector compares.
    for (int x = 0; x < width; ++x) l[x] = in[x] > hi[x] ? 255 : 0;
    for (int x = 0; x < width; ++x) d[x] = in[x] < lo[x] ? 255 : 0;
  }
}

struct Blob {
  Ellipse ellipse;  // full-resolution pixels, from the blob's moments
  bool light = true;
  double radius_px = 0.0;  // sqrt(semi_major * semi_minor)
  // The ellipse's shape matrix S: x is inside when (x - c)^T S^-1 (x - c) <= 1; px^2.
  Eigen::Matrix2d shape = Eigen::Matrix2d::Identity();
};

// Appends the components of `mask` (half image) that look like filled ellipses.
void CollectBlobs(const std::vector<std::uint8_t>& mask, const Reduced& half, bool light,
                  std::vector<Blob>* blobs) {
  const ImageView8 view{mask.data(), half.width, half.height, half.width};
  const ComponentLabels labels = LabelComponents(view);
  const std::size_t n = labels.components.size();
  // Components worth the moments: 5 reduced pixels is, at factor 2, a circle 6 px across at
  // full resolution seen at 50 degrees; a sixteenth of the image is far more than the
  // largest circle (a board over 80% of the width has circles of 4.4% of the width).
  const int min_area = 5;
  const int max_area = half.width * half.height / 16;
  for (std::size_t i = 0; i < n; ++i) {
    const Component& c = labels.components[i];
    if (c.area_px < min_area || c.area_px > max_area || c.min_x == 0 || c.min_y == 0 ||
        c.max_x == half.width - 1 || c.max_y == half.height - 1) {
      continue;
    }
    // A filled ellipse covers at least 0.37 of its bounding box (a 4:1 ellipse at 45
    // degrees); sparser components are not worth their moments.
    const int box_area = (c.max_x - c.min_x + 1) * (c.max_y - c.min_y + 1);
    if (c.area_px < 0.3 * box_area) continue;
    // Moments over the component's bounding box only: the few plausible components cost
    // far less than a pass over the whole label image.
    const std::int32_t label = static_cast<std::int32_t>(i) + 1;
    std::array<double, 5> m = {0, 0, 0, 0, 0};
    for (int y = c.min_y; y <= c.max_y; ++y) {
      const std::int32_t* row = labels.labels.data() + static_cast<std::size_t>(y) * half.width;
      double sx = 0.0;
      double sxx = 0.0;
      int count = 0;
      for (int x = c.min_x; x <= c.max_x; ++x) {
        if (row[x] != label) continue;
        sx += x;
        sxx += static_cast<double>(x) * x;
        ++count;
      }
      m[0] += sx;
      m[1] += static_cast<double>(y) * count;
      m[2] += sxx;
      m[3] += y * sx;
      m[4] += static_cast<double>(y) * y * count;
    }
    const double area = c.area_px;
    const Eigen::Vector2d centroid(m[0] / area, m[1] / area);
    Eigen::Matrix2d cov;
    cov(0, 0) = m[2] / area - centroid.x() * centroid.x();
    cov(0, 1) = m[3] / area - centroid.x() * centroid.y();
    cov(1, 1) = m[4] / area - centroid.y() * centroid.y();
    cov(1, 0) = cov(0, 1);
    // Pixel centres miss the spread of each pixel's own area: 1/12 px^2 per axis.
    cov += Eigen::Matrix2d::Identity() / 12.0;
    const double det = cov.determinant();
    if (!(det > 0.0)) continue;
    // A filled ellipse has area 4 pi sqrt(det cov) and a bounding box 4 sqrt(cov_xx) by
    // 4 sqrt(cov_yy). The tolerances absorb the pixel steps of blobs a few pixels across;
    // squares and bars fail the box test (a square's box is 0.87 or 1.22 of its moment
    // ellipse's), rings and clusters the area test.
    const double fill = area / (4.0 * kPi * std::sqrt(det));
    if (fill < 0.8 || fill > 1.2) continue;
    const double box_x = (c.max_x - c.min_x + 1) / (4.0 * std::sqrt(cov(0, 0)));
    const double box_y = (c.max_y - c.min_y + 1) / (4.0 * std::sqrt(cov(1, 1)));
    if (box_x < 0.75 || box_x > 1.3 || box_y < 0.75 || box_y > 1.3) continue;
    const double f = half.factor;
    const std::optional<Ellipse> e =
        EllipseFromMoments(f * centroid + Eigen::Vector2d::Constant(0.5 * (f - 1.0)), f * f * cov);
    // Circles seen 50 degrees off-axis in both directions keep about 0.4 of their width
    // (cos 50 squared); narrower blobs are lines or text.
    if (!e || e->semi_minor < 0.25 * e->semi_major) continue;
    Blob b;
    b.ellipse = *e;
    b.light = light;
    b.radius_px = std::sqrt(e->semi_major * e->semi_minor);
    b.shape = 4.0 * f * f * cov;
    blobs->push_back(b);
  }
}

// ---- 2. Identification ------------------------------------------------------------------

double GreyAt(const ImageView8& image, const Eigen::Vector2d& uv) {
  if (!uv.allFinite()) return std::numeric_limits<double>::quiet_NaN();
  // Clamped before the conversion, which far-off points would overflow.
  const int x = static_cast<int>(std::lround(std::clamp(uv.x(), 0.0, image.width - 1.0)));
  const int y = static_cast<int>(std::lround(std::clamp(uv.y(), 0.0, image.height - 1.0)));
  return image.At(x, y);
}

// The mean grey of the 3 x 3 pixels around uv (clamped to the image): a noise-robust sample
// for the coarse tests of paint.
double BoxGrey(const ImageView8& image, const Eigen::Vector2d& uv) {
  double sum = 0.0;
  for (int dy = -1; dy <= 1; ++dy) {
    for (int dx = -1; dx <= 1; ++dx) sum += GreyAt(image, uv + Eigen::Vector2d(dx, dy));
  }
  return sum / 9.0;
}

// The homography of the affine map that takes the black pair's board positions to the
// blobs `left` and `right`: the board x axis from the pair, the y axis from the metric of
// their ellipses (an ellipse is the image of a circle: S = R^2 A A^T for the local affine
// map A, so A is S^1/2 / R times a rotation, and the print seen from the front fixes the
// reflection).
//
// undo_edge_shift: the blobs' threshold moves their edges by about the same number of
// pixels all round (blur with gamma: 2-3 px on dark circles of 12 px at 50 degrees), which
// changes a foreshortened ellipse's aspect: its minor axis loses a larger part. Along a_x
// the printed circle reaches exactly radius |a_x| (the image of its point (radius, 0)), so
// the blobs' reach there gives that shift, and each semi-axis gets it back. The estimate
// can also mislead (two hard renders of the smallest circles pitched 50 degrees lost their
// grid with it: CircleDetectorTest.SmallestCirclesUnderTheHardEffects), so the search
// seeds with the blobs as they are first.
Eigen::Matrix3d PairAffine(const CircleBoardModel& m, const Blob& left, const Blob& right,
                           bool undo_edge_shift) {
  const Eigen::Vector2d a_x = (right.ellipse.centre - left.ellipse.centre) /
                              (m.p_board[m.pair[1]] - m.p_board[m.pair[0]]).norm();
  Eigen::Matrix2d shape = 0.5 * (left.shape + right.shape);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> axes(shape);
  if (undo_edge_shift && axes.info() == Eigen::Success && axes.eigenvalues().minCoeff() > 0.0) {
    const Eigen::Vector2d u = a_x.normalized();
    const double reach_px = 1.0 / std::sqrt(u.dot(shape.inverse() * u));
    const double shift_px = m.radius_m * a_x.norm() - reach_px;
    const Eigen::Vector2d semi = (axes.eigenvalues().cwiseSqrt().array() + shift_px).matrix();
    if (semi.minCoeff() > 0.0) {
      shape = axes.eigenvectors() * semi.cwiseAbs2().asDiagonal() * axes.eigenvectors().transpose();
    }
  }
  const Eigen::Matrix2d s = shape / (m.radius_m * m.radius_m);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(s);
  const Eigen::Matrix2d root = eig.operatorSqrt();
  const Eigen::Matrix2d root_inverse = eig.operatorInverseSqrt();
  const Eigen::Vector2d q1 = (root_inverse * a_x).normalized();
  Eigen::Vector2d a_y = root * Eigen::Vector2d(-q1.y(), q1.x());
  a_y *= a_x.norm() / (root * q1).norm();
  // Board x right and y up appear, in the image (v down), with a negative cross product.
  if (a_x.x() * a_y.y() - a_x.y() * a_y.x() > 0.0) a_y = -a_y;
  Eigen::Matrix3d h = Eigen::Matrix3d::Identity();
  h.block<2, 1>(0, 0) = a_x;
  h.block<2, 1>(0, 1) = a_y;
  const Eigen::Vector2d mid_px = 0.5 * (left.ellipse.centre + right.ellipse.centre);
  h.block<2, 1>(0, 2) = mid_px - a_x * m.pair_mid.x() - a_y * m.pair_mid.y();
  return h;
}

// The image radius of a board circle at p_board under H: the mean of the images of its
// radii along board x and y. Pixels.
double ImageRadius(const Eigen::Matrix3d& H, const Eigen::Vector2d& p_board, double radius_m) {
  const Eigen::Vector2d c = ApplyHomography(H, p_board);
  const double rx = (ApplyHomography(H, p_board + Eigen::Vector2d(radius_m, 0.0)) - c).norm();
  const double ry = (ApplyHomography(H, p_board + Eigen::Vector2d(0.0, radius_m)) - c).norm();
  return 0.5 * (rx + ry);
}

// Fewer blob matches than this do not make a grid worth measuring: a homography over 12 of
// the 30 circles spread across the board predicts the rest within a fraction of a radius,
// and the 4 circles next to the bar may merge with it under blur at the smallest sizes.
constexpr int kMinMatchedBlobs = 12;

struct Grid {
  Eigen::Matrix3d H = Eigen::Matrix3d::Identity();  // board metres -> image pixels
  std::vector<int> blob;                            // per id, a blob index or -1
};

// Grows the grid from the pair (blobs `left`, `right`) outwards, seeded by PairAffine with
// undo_edge_shift; nullopt when fewer than kMinMatchedBlobs circles match.
std::optional<Grid> GrowGrid(const CircleBoardModel& m, const std::vector<Blob>& blobs, int left,
                             int right, bool undo_edge_shift) {
  Grid g;
  g.blob.assign(m.p_board.size(), -1);
  g.blob[m.pair[0]] = left;
  g.blob[m.pair[1]] = right;
  std::vector<bool> used(blobs.size(), false);
  used[left] = used[right] = true;
  Eigen::Matrix3d H = PairAffine(m, blobs[left], blobs[right], undo_edge_shift);
  std::vector<Eigen::Vector2d> src = {m.p_board[m.pair[0]], m.p_board[m.pair[1]]};
  std::vector<Eigen::Vector2d> dst = {blobs[left].ellipse.centre, blobs[right].ellipse.centre};
  HomographyFitOptions fast;
  fast.refine = false;
  for (const int id : m.growth_order) {
    const Eigen::Vector2d predicted = ApplyHomography(H, m.p_board[id]);
    const double radius = ImageRadius(H, m.p_board[id], m.radius_m);
    if (!predicted.allFinite() || !(radius > 0.0)) return std::nullopt;
    // Neighbouring circles are 2.8 radii apart or more: a blob within 0.6 radii of the
    // prediction is this circle, and the tolerance absorbs the affine seed's error.
    double best_distance = 0.6 * radius;
    int best = -1;
    for (std::size_t b = 0; b < blobs.size(); ++b) {
      if (used[b] || blobs[b].light != m.light[id]) continue;
      // Blob sizes follow the threshold under blur: a factor of 2 either way.
      if (blobs[b].radius_px < 0.5 * radius || blobs[b].radius_px > 2.0 * radius) continue;
      const double d = (blobs[b].ellipse.centre - predicted).norm();
      if (d < best_distance) {
        best_distance = d;
        best = static_cast<int>(b);
      }
    }
    if (best < 0) continue;
    g.blob[id] = best;
    used[best] = true;
    src.push_back(m.p_board[id]);
    dst.push_back(blobs[best].ellipse.centre);
    // Five points spread over two rows or more determine a homography (four would fit any
    // four points exactly, leaving no check).
    if (src.size() >= 5) {
      if (const std::optional<HomographyFit> fit = FitHomography(src, dst, fast)) H = fit->H;
    }
  }
  if (static_cast<int>(src.size()) < kMinMatchedBlobs) return std::nullopt;
  const std::optional<HomographyFit> fit = FitHomography(src, dst);
  if (!fit) return std::nullopt;
  // Blob centroids are the thresholded regions' (biased by blur and perspective by a small
  // fraction of the radius): half a radius separates a consistent grid from a wrong one.
  for (std::size_t i = 0; i < src.size(); ++i) {
    const double radius = ImageRadius(fit->H, src[i], m.radius_m);
    if ((ApplyHomography(fit->H, src[i]) - dst[i]).norm() > 0.5 * radius) return std::nullopt;
  }
  g.H = fit->H;
  return g;
}

// ---- 3. Sub-pixel ellipses --------------------------------------------------------------

// A part of the image as floats, for bilinear sampling in image coordinates.
struct Patch {
  ImageF image;
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();  // image coordinates of its pixel (0, 0)

  float At(const Eigen::Vector2d& uv) const {
    return SampleBilinear(image, uv.x() - origin.x(), uv.y() - origin.y());
  }
};

// The pixels that the edge search around `ellipse` can reach, as floats: its bounding box,
// widened by the first pass's window (0.35 of the radius, below half the semi-major axis)
// and the profile's end samples (a few pixels).
Patch MakePatch(const ImageView8& image, const Ellipse& ellipse) {
  const double reach = 1.5 * ellipse.semi_major + 4.0;
  // Clamped in floating point before the conversion, which a degenerate ellipse (one near
  // the board's vanishing line) would overflow.
  auto clamp_to = [](double v, int lo, int hi) {
    return static_cast<int>(std::clamp(v, static_cast<double>(lo), static_cast<double>(hi)));
  };
  const int x0 = clamp_to(std::floor(ellipse.centre.x() - reach), 0, image.width - 1);
  const int y0 = clamp_to(std::floor(ellipse.centre.y() - reach), 0, image.height - 1);
  const int x1 = clamp_to(std::ceil(ellipse.centre.x() + reach), x0, image.width - 1);
  const int y1 = clamp_to(std::ceil(ellipse.centre.y() + reach), y0, image.height - 1);
  const ImageView8 crop{image.Row(y0) + x0, x1 - x0 + 1, y1 - y0 + 1, image.stride_bytes};
  return Patch{GaussianBlur(crop, 0.0), Eigen::Vector2d(x0, y0)};
}

// How one pass searches for the edge along each ray.
struct EdgeSearch {
  double window_fraction = 0.35;  // of the seed's radius along the ray, on either side
  double max_window_px = 0.0;     // 0: no limit
  int samples_per_side = 0;       // profile samples per side at most; 0: every 0.5 px
};

// The finest profile step, pixels: fine enough to locate the derivative's peak of an edge
// blurred by 0.5 px with a parabola.
constexpr double kProfileStepPx = 0.5;

// One pass of edge points along rays from seed's centre and an ellipse fit to them, with
// the outliers (neighbouring edges, occlusion) removed.
std::optional<Ellipse> FitCircleEdge(const Patch& patch, const Ellipse& seed, bool light,
                                     std::span<const Eigen::Vector2d> directions,
                                     const EdgeSearch& search, int min_contrast) {
  const int rays = static_cast<int>(directions.size());
  std::vector<Eigen::Vector2d> points;
  points.reserve(rays);
  std::vector<float> profile;
  const double sign = light ? 1.0 : -1.0;  // light: grey falls outwards
  const double axis_cos = std::cos(seed.angle_rad);
  const double axis_sin = std::sin(seed.angle_rad);
  for (int k = 0; k < rays; ++k) {
    const Eigen::Vector2d& u = directions[k];
    // The ray in the seed's axes: cos and sin of (theta - angle).
    const double c = (u.x() * axis_cos + u.y() * axis_sin) / seed.semi_major;
    const double s = (u.y() * axis_cos - u.x() * axis_sin) / seed.semi_minor;
    const double rho = 1.0 / std::sqrt(c * c + s * s);
    // At least 1.5 px: the seed's error for the smallest circles.
    double window = std::max(1.5, search.window_fraction * rho);
    if (search.max_window_px > 0.0) window = std::min(window, search.max_window_px);
    const double step = search.samples_per_side > 0
                            ? std::max(kProfileStepPx, window / search.samples_per_side)
                            : kProfileStepPx;
    const int n = static_cast<int>(std::ceil(window / step));
    profile.resize(2 * n + 3);
    for (int j = -n - 1; j <= n + 1; ++j)
      profile[j + n + 1] = patch.At(seed.centre + (rho + j * step) * u);
    auto derivative = [&](int j) {
      return sign * (profile[j + n] - profile[j + n + 2]);  // P(j - 1) - P(j + 1)
    };
    int best = -n;
    for (int j = -n + 1; j <= n; ++j) {
      if (derivative(j) > derivative(best)) best = j;
    }
    // The derivative peak of a printed edge (at least min_contrast over a blur of a couple
    // of pixels) exceeds a quarter of min_contrast per pixel; weaker peaks are noise.
    if (best == -n || best == n || derivative(best) < 0.25 * min_contrast * 2.0 * step) continue;
    const double d0 = derivative(best - 1);
    const double d1 = derivative(best);
    const double d2 = derivative(best + 1);
    const double curvature = d0 - 2.0 * d1 + d2;
    if (!(curvature < 0.0)) continue;
    const double delta = 0.5 * (d0 - d2) / curvature;
    points.push_back(seed.centre + (rho + (best + delta) * step) * u);
  }
  // Half the rays: a circle half hidden or half on a neighbour is not measured.
  if (static_cast<int>(points.size()) < rays / 2) return std::nullopt;
  std::optional<Ellipse> fit = FitEllipse(points);
  if (!fit) return std::nullopt;
  const Eigen::Matrix3d conic = fit->Conic();
  std::vector<double> residuals(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) residuals[i] = SampsonDistance(conic, points[i]);
  std::vector<double> sorted = residuals;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  // 3 robust sigmas (1.4826 median absolute residual), and never below 0.2 px, the noise
  // of a single edge point at sigma 4.
  const double limit = std::max(0.2, 3.0 * 1.4826 * sorted[sorted.size() / 2]);
  std::vector<double> weights(points.size());
  int kept = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    weights[i] = residuals[i] <= limit ? 1.0 : 0.0;
    kept += residuals[i] <= limit;
  }
  if (kept < rays / 2) return std::nullopt;
  if (kept < static_cast<int>(points.size())) fit = FitEllipse(points, weights);
  return fit;
}

// Unit ray directions, evenly spaced: the seeding pass uses half as many rays as the final
// one (it only has to bring the edge windows onto the edge).
struct RayDirections {
  std::vector<Eigen::Vector2d> coarse;
  std::vector<Eigen::Vector2d> fine;

  explicit RayDirections(int rays) {
    for (int k = 0; k < rays; ++k) {
      const double theta = 2.0 * kPi * k / rays;
      fine.emplace_back(std::cos(theta), std::sin(theta));
      if (k % 2 == 0) coarse.push_back(fine.back());
    }
  }
};

// The ellipse of a circle, measured from the image in two passes seeded by `predicted`;
// nullopt when the edge is not found or the result strays from the prediction.
std::optional<Ellipse> MeasureCircle(const Patch& patch, const Ellipse& predicted, bool light,
                                     const RayDirections& rays, int min_contrast) {
  // First pass: 0.35 of the radius covers the seed's error (under half a radius, checked by
  // GrowGrid) while it stays short of the white bar, the nearest other edge (0.4 radius
  // from the circles next to it); 8 samples a side locate the edge to a fraction of a pixel.
  const std::optional<Ellipse> first =
      FitCircleEdge(patch, predicted, light, rays.coarse, {0.35, 0.0, 8}, min_contrast);
  if (!first) return std::nullopt;
  // Second pass: centred on the first fit, every 0.5 px over +-3 px, which holds an edge
  // blurred by sigma 1.5 and the first pass's error.
  std::optional<Ellipse> second =
      FitCircleEdge(patch, *first, light, rays.fine, {0.35, 3.0, 0}, min_contrast);
  if (!second) return std::nullopt;
  const double r_pred = std::sqrt(predicted.semi_major * predicted.semi_minor);
  const double r_meas = std::sqrt(second->semi_major * second->semi_minor);
  // Blur moves the edge by a fraction of its sigma; a third of the radius or more means
  // another edge was measured.
  if ((second->centre - predicted.centre).norm() > 0.5 * r_pred ||
      std::abs(r_meas - r_pred) > 0.33 * r_pred + 1.0) {
    return std::nullopt;
  }
  return second;
}

// ---- 4./5. Perspective, verification, orientation ---------------------------------------

struct Measured {
  std::vector<Eigen::Vector2d> uv;  // per id
};

enum class Outcome { kFound, kFailed };

Outcome MeasureBoard(const ImageView8& image, const CircleBoardModel& m, const Grid& grid,
                     const CircleOptions& options, Measured* out) {
  const std::size_t n = m.p_board.size();
  const RayDirections rays(options.edge_rays);
  std::vector<Eigen::Vector2d> centres(n);
  std::vector<double> radii(n);
  // Measures circle `id` seeded by the ellipse that H predicts.
  auto measure = [&](const Eigen::Matrix3d& H, std::size_t id) {
    const std::optional<Ellipse> predicted =
        EllipseFromConic(ImageOfCircle(H, m.p_board[id], m.radius_m));
    if (!predicted) return false;
    const std::optional<Ellipse> e = MeasureCircle(MakePatch(image, *predicted), *predicted,
                                                   m.light[id], rays, options.min_contrast);
    if (!e) return false;
    centres[id] = e->centre;
    radii[id] = std::sqrt(e->semi_major * e->semi_minor);
    return true;
  };
  for (std::size_t id = 0; id < n; ++id) {
    if (!measure(grid.H, id)) return Outcome::kFailed;
  }
  std::vector<Eigen::Vector2d> corrected = centres;
  std::optional<HomographyFit> fit;
  // Fits H to the centres, corrected for perspective when asked. The offset changes by
  // (change of H) x (offset / radius), tiny after the first round; three rounds leave it
  // below 1e-4 px.
  auto correct = [&]() {
    corrected = centres;
    fit = FitHomography(m.p_board, corrected);
    if (!options.correct_perspective) return fit.has_value();
    for (int round = 0; round < 3 && fit; ++round) {
      for (std::size_t id = 0; id < n; ++id) {
        const std::optional<Ellipse> image_ellipse =
            EllipseFromConic(ImageOfCircle(fit->H, m.p_board[id], m.radius_m));
        if (!image_ellipse) return false;
        corrected[id] =
            centres[id] - (image_ellipse->centre - ApplyHomography(fit->H, m.p_board[id]));
      }
      fit = FitHomography(m.p_board, corrected);
    }
    return fit.has_value();
  };
  if (!correct()) return Outcome::kFailed;
  std::vector<double> residuals;
  HomographyResiduals(fit->H, m.p_board, corrected, &residuals);
  // A circle far off the board's homography was measured from a poor seed (the blob grid's
  // H): measure it again from the far better seed of the measured board, and refit. Far
  // off: 4 times the median residual and over half a pixel (noise of sigma 6 moves a
  // centre by about 0.2 px).
  std::vector<double> sorted = residuals;
  std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
  const double outlier_px = std::max(0.5, 4.0 * sorted[n / 2]);
  const Eigen::Matrix3d seed_H = fit->H;
  bool remeasured = false;
  for (std::size_t id = 0; id < n; ++id) {
    if (residuals[id] <= outlier_px) continue;
    if (!measure(seed_H, id)) return Outcome::kFailed;
    remeasured = true;
  }
  if (remeasured) {
    if (!correct()) return Outcome::kFailed;
    HomographyResiduals(fit->H, m.p_board, corrected, &residuals);
  }
  for (std::size_t id = 0; id < n; ++id) {
    if (!(residuals[id] <= options.max_residual_radius_fraction * radii[id])) {
      return Outcome::kFailed;
    }
  }
  // Orientation (header, step 5), against the contrast of the bar and the black near it.
  auto grey = [&](const Eigen::Vector2d& p_board) {
    const Eigen::Vector2d uv = ApplyHomography(fit->H, p_board);
    return BoxGrey(image, uv);
  };
  const double contrast = grey(m.pair_mid) - grey(m.black_reference);
  if (!(contrast >= options.min_contrast)) return Outcome::kFailed;
  double score = 0.0;
  for (std::size_t i = 0; i < m.dark_points.size(); ++i) {
    score += grey(m.light_points[i]) - grey(m.dark_points[i]);
  }
  score /= static_cast<double>(m.dark_points.size());
  // A quarter of the contrast: the margin and the strips' ends lie at the board's top and
  // bottom, where a 4:1 illumination gradient along the board can halve the white.
  const double min_score = 0.25 * contrast;
  out->uv.assign(n, Eigen::Vector2d::Zero());
  if (score >= min_score) {
    out->uv = corrected;
  } else if (score <= -min_score) {
    for (std::size_t id = 0; id < n; ++id) out->uv[id] = corrected[m.rotated[id]];
  } else {
    return Outcome::kFailed;
  }
  return Outcome::kFound;
}

Detection NotFound(DetectReason reason) {
  Detection d;
  d.found = false;
  d.reason = reason;
  return d;
}

// One search at a candidate resolution: found (or ambiguous), or nullopt with *reason.
std::optional<Detection> SearchAtFactor(const ImageView8& image, const Board& board,
                                        const CircleBoardModel& m, const CircleOptions& options,
                                        int factor, DetectReason* reason) {
  const Reduced half = Downsample(image, factor);
  if (half.max - half.min < options.min_contrast) {
    *reason = DetectReason::kLowContrast;
    return std::nullopt;
  }
  std::vector<std::uint8_t> light_mask;
  std::vector<std::uint8_t> dark_mask;
  Classify(half, options.min_contrast, &light_mask, &dark_mask);
  std::vector<Blob> blobs;
  CollectBlobs(light_mask, half, true, &blobs);
  CollectBlobs(dark_mask, half, false, &blobs);
  if (blobs.empty()) {
    *reason = DetectReason::kNoCandidates;
    return std::nullopt;
  }
  const double expected_pair_distance =
      (m.p_board[m.pair[1]] - m.p_board[m.pair[0]]).norm() / m.radius_m;
  std::vector<bool> claimed(blobs.size(), false);
  *reason = DetectReason::kTooFewFeatures;
  std::optional<Measured> found;
  for (std::size_t i = 0; i < blobs.size(); ++i) {
    if (blobs[i].light) continue;
    for (std::size_t j = i + 1; j < blobs.size(); ++j) {
      if (blobs[j].light || claimed[i] || claimed[j]) continue;
      const Blob& a = blobs[i];
      const Blob& b = blobs[j];
      // Neighbours differ in size by a few percent under perspective, and the threshold
      // changes small blurred blobs by up to about a quarter.
      if (std::max(a.radius_px, b.radius_px) > 1.6 * std::min(a.radius_px, b.radius_px)) {
        continue;
      }
      const Eigen::Vector2d d = b.ellipse.centre - a.ellipse.centre;
      const Eigen::Matrix2d s_inverse = (0.5 * (a.shape + b.shape)).inverse();
      // The pair's distance in radii, measured in the ellipses' own metric (which removes
      // the local perspective): 4 on the printed board; the blob sizes' threshold bias
      // widens the band. That bias is a shift of the blobs' edges, about the same number of
      // pixels whatever their size, so small blobs get more room: dark circles of 12 px
      // under blur 1.5 and gamma 1.6 come out 1.8 px smaller in radius (ratio 1.41).
      const double ratio = std::sqrt(d.dot(s_inverse * d)) / expected_pair_distance;
      const double radius = 0.5 * (a.radius_px + b.radius_px);
      if (ratio < 0.7 || ratio > 1.4 * (radius + kMaxEdgeShiftPx) / radius) continue;
      const Eigen::Vector2d mid = 0.5 * (a.ellipse.centre + b.ellipse.centre);
      if (!(GreyAt(image, mid) -
                std::max(GreyAt(image, a.ellipse.centre), GreyAt(image, b.ellipse.centre)) >=
            options.min_contrast)) {
        continue;
      }
      // The left circle of the pair is either blob: the orientation test settles it.
      // A pair of blobs shrunk by the threshold seeds the rows next to it a radius off
      // unless their edge shift is undone (PairAffine); seen as they are first, so that
      // blobs that are not shrunk ellipses keep the seed that finds them.
      std::optional<Grid> grid =
          GrowGrid(m, blobs, static_cast<int>(i), static_cast<int>(j), false);
      if (!grid) grid = GrowGrid(m, blobs, static_cast<int>(i), static_cast<int>(j), true);
      if (!grid) continue;
      Measured measured;
      if (MeasureBoard(image, m, *grid, options, &measured) != Outcome::kFound) {
        *reason = DetectReason::kVerificationFailed;
        continue;
      }
      if (found) return NotFound(DetectReason::kAmbiguous);
      found = measured;
      for (const int blob : grid->blob) {
        if (blob >= 0) claimed[blob] = true;
      }
    }
  }
  if (!found) return std::nullopt;
  Detection detection;
  detection.found = true;
  detection.reason = DetectReason::kNone;
  for (std::size_t id = 0; id < found->uv.size(); ++id) {
    DetectedFeature f;
    f.id = static_cast<int>(id);
    f.uv_px = found->uv[id];
    f.p_board = board.features()[id].p_board;
    detection.features.push_back(f);
  }
  return detection;
}

}  // namespace

std::string_view CircleOptions::Validate() const {
  if (min_contrast < 4 || min_contrast > 200) return "min_contrast";
  if (edge_rays < 16 || edge_rays > 256) return "edge_rays";
  if (!(max_residual_radius_fraction > 0.0 && max_residual_radius_fraction <= 1.0)) {
    return "max_residual_radius_fraction";
  }
  return {};
}

Detection DetectCircleBoard(const ImageView8& image, const Board& board,
                            const CircleOptions& options) {
  if (const DetectReason r = CheckDetectorInput(image, board, BoardType::kCircle, options.Validate().empty());
      r != DetectReason::kNone) {
    return NotFound(r);
  }
  const std::optional<CircleBoardModel> model = MakeModel(board);
  if (!model) return NotFound(DetectReason::kWrongBoard);
  // Coarse to fine: the candidate stage starts at the coarsest factor (a power of 2) whose
  // image still has kMinCandidatePixels, so that a large image costs little more than a
  // small one when its board is large, and ends at factor 2, which holds the smallest
  // circles (12 px).
  int factor = 2;
  while (static_cast<double>(image.width / (2 * factor)) * (image.height / (2 * factor)) >=
         kMinCandidatePixels) {
    factor *= 2;
  }
  DetectReason reason = DetectReason::kNoCandidates;
  for (; factor >= 2; factor /= 2) {
    if (std::optional<Detection> d =
            SearchAtFactor(image, board, *model, options, factor, &reason)) {
      return *std::move(d);
    }
  }
  return NotFound(reason);
}

}  // namespace linecal

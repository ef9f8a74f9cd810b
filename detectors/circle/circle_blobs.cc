#include "detectors/circle/circle_blobs.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <optional>

#include "detectors/common/contours.h"

namespace linecal {
namespace {

constexpr double kPi = std::numbers::pi;

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
  // Range: separable sliding minimum and maximum over the same window. Each pass takes the
  // window's offsets in turn over a whole row of tiles (straight loops, which vectorise).
  std::vector<std::uint8_t> row_lo(half.tile_min.size(), 255);
  std::vector<std::uint8_t> row_hi(half.tile_max.size(), 0);
  for (int ty = 0; ty < th; ++ty) {
    const std::size_t t_row = static_cast<std::size_t>(ty) * tw;
    std::uint8_t* lo = row_lo.data() + t_row;
    std::uint8_t* hi = row_hi.data() + t_row;
    for (int d = -k; d <= k; ++d) {
      // The tiles tx whose neighbour tx + d lies on the row.
      const int tx0 = std::max(0, -d), tx1 = std::min(tw, tw - d);
      const std::uint8_t* in_lo = half.tile_min.data() + t_row;
      const std::uint8_t* in_hi = half.tile_max.data() + t_row;
      for (int tx = tx0; tx < tx1; ++tx) lo[tx] = std::min(lo[tx], in_lo[tx + d]);
      for (int tx = tx0; tx < tx1; ++tx) hi[tx] = std::max(hi[tx], in_hi[tx + d]);
    }
  }
  // Per tile, the grey levels below which a pixel is dark and above which it is light; a
  // tile without contrast gets bounds no pixel passes.
  std::vector<int> dark_below(half.tile_sum.size());
  std::vector<int> light_above(half.tile_sum.size());
  std::vector<std::uint8_t> column_lo(tw);
  std::vector<std::uint8_t> column_hi(tw);
  for (int ty = 0; ty < th; ++ty) {
    const int y0 = std::max(0, ty - k);
    const int y1 = std::min(th, ty + k + 1);
    // The window's extremes down each column of tiles, a row of the window at a time.
    std::fill(column_lo.begin(), column_lo.end(), std::uint8_t{255});
    std::fill(column_hi.begin(), column_hi.end(), std::uint8_t{0});
    for (int y = y0; y < y1; ++y) {
      const std::uint8_t* in_lo = row_lo.data() + static_cast<std::size_t>(y) * tw;
      const std::uint8_t* in_hi = row_hi.data() + static_cast<std::size_t>(y) * tw;
      for (int tx = 0; tx < tw; ++tx) column_lo[tx] = std::min(column_lo[tx], in_lo[tx]);
      for (int tx = 0; tx < tw; ++tx) column_hi[tx] = std::max(column_hi[tx], in_hi[tx]);
    }
    for (int tx = 0; tx < tw; ++tx) {
      const int x0 = std::max(0, tx - k);
      const int x1 = std::min(tw, tx + k + 1);
      auto box = [&](const std::vector<double>& s) {
        return s[y1 * sat_w + x1] - s[y0 * sat_w + x1] - s[y1 * sat_w + x0] + s[y0 * sat_w + x0];
      };
      const int a = column_lo[tx];
      const int b = column_hi[tx];
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

// Appends the components of `mask` (half image) that look like filled ellipses.
void CollectBlobs(const std::vector<std::uint8_t>& mask, const Reduced& half, bool light,
                  std::vector<CircleBlob>* blobs) {
  const ImageView8 view{mask.data(), half.width, half.height, half.width};
  // The components' runs rather than a label image: the moments are sums over the runs.
  const ComponentLabels labels = LabelComponents(view, /*label_image=*/false);
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
    // Moments over the component's runs (in raster order), row by row. Every sum is of
    // integers far below 2^53, exact in doubles whatever the order.
    std::array<double, 5> m = {0, 0, 0, 0, 0};
    const int r_end = labels.run_begin[i + 1];
    for (int r = labels.run_begin[i]; r < r_end;) {
      const int y = labels.runs[r].y;
      double sx = 0.0;
      double sxx = 0.0;
      int count = 0;
      for (; r < r_end && labels.runs[r].y == y; ++r) {
        for (int x = labels.runs[r].x0; x < labels.runs[r].x1; ++x) {
          sx += x;
          sxx += static_cast<double>(x) * x;
          ++count;
        }
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
    CircleBlob b;
    b.ellipse = *e;
    b.light = light;
    b.radius_px = std::sqrt(e->semi_major * e->semi_minor);
    b.shape = 4.0 * f * f * cov;
    blobs->push_back(b);
  }
}

}  // namespace

CircleBlobSearch FindCircleBlobs(const ImageView8& image, int factor, int min_contrast, bool light,
                                 bool dark) {
  CircleBlobSearch search;
  const Reduced half = Downsample(image, factor);
  if (half.max - half.min < min_contrast) {
    search.low_contrast = true;
    return search;
  }
  std::vector<std::uint8_t> light_mask;
  std::vector<std::uint8_t> dark_mask;
  Classify(half, min_contrast, &light_mask, &dark_mask);
  if (light) CollectBlobs(light_mask, half, true, &search.blobs);
  if (dark) CollectBlobs(dark_mask, half, false, &search.blobs);
  return search;
}

int CoarsestCircleBlobFactor(const ImageView8& image) {
  int factor = 2;
  while (static_cast<double>(image.width / (2 * factor)) * (image.height / (2 * factor)) >=
         kMinCandidatePixels) {
    factor *= 2;
  }
  return factor;
}

}  // namespace linecal

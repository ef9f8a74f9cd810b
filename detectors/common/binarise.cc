#include "detectors/common/binarise.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

namespace linecal {
namespace {

// Binarisation tiles: 4 x 4 pixels, the smallest marker cell of docs/acceptance.md, so that a
// 3 x 3 tile window (12 px) always spans a dark and a light cell of the smallest markers.
constexpr int kTile = 4;
// Low-contrast tiles take the mean threshold of their known neighbours, repeatedly: this
// many passes reach 64 px into a flat area, the half-width of the largest black cell of a
// board filling 80% of a 2448 px image (ArUco border cell: 71 px wide).
constexpr int kThresholdPropagationPasses = 16;

// Per tile of kTile x kTile pixels, the darkest and brightest of its 2 x 2 pixel means.
struct TileExtremes {
  int tw = 0;  // tiles across
  int th = 0;  // tiles down
  std::vector<std::uint8_t> tmin;
  std::vector<std::uint8_t> tmax;
};

// Needs an image; gives its tiles' extremes, taken over 2 x 2 pixel means, which halve the
// noise (a 4 px cell still holds nine such means entirely inside it). Plain loops over rows,
// which vectorise. O(W * H).
TileExtremes ComputeTileExtremes(const ImageView8& image) {
  TileExtremes t;
  t.tw = (image.width + kTile - 1) / kTile;
  t.th = (image.height + kTile - 1) / kTile;
  const int tw = t.tw;
  t.tmin.assign(static_cast<std::size_t>(tw) * t.th, 255);
  t.tmax.assign(static_cast<std::size_t>(tw) * t.th, 0);
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
    std::uint8_t* mn = &t.tmin[static_cast<std::size_t>(y / kTile) * tw];
    std::uint8_t* mx = &t.tmax[static_cast<std::size_t>(y / kTile) * tw];
    for (int tx = 0; tx < tw; ++tx) {
      const std::uint8_t* m = &means[static_cast<std::size_t>(tx) * kTile];
      const std::uint8_t lo = std::min(std::min(m[0], m[1]), std::min(m[2], m[3]));
      const std::uint8_t hi = std::max(std::max(m[0], m[1]), std::max(m[2], m[3]));
      mn[tx] = std::min(mn[tx], lo);
      mx[tx] = std::max(mx[tx], hi);
    }
    pairs_a.swap(pairs_b);
  }
  return t;
}

// Needs the tiles' extremes; gives twice the threshold per tile (the minimum plus
// dark_fraction of the range over the 3 x 3 tiles around it), or -1 where that range is under
// min_contrast. *max_contrast: the largest range seen. The 3 x 3 extremes are taken in two
// passes (rows of three, then columns of three), and the rounded fraction of each of the 256
// possible ranges comes from a table: O(tiles).
std::vector<int> TileThresholds(const TileExtremes& t, int min_contrast, double dark_fraction,
                                int* max_contrast) {
  const int tw = t.tw;
  const int th = t.th;
  std::array<int, 256> offset2;
  for (int r = 0; r < 256; ++r) offset2[r] = static_cast<int>(std::lround(2.0 * dark_fraction * r));
  // Per tile, the extremes of itself and its left and right neighbours (inside the image);
  // the inner tiles in a loop without clamps, which vectorises.
  std::vector<std::uint8_t> row_min(t.tmin.size());
  std::vector<std::uint8_t> row_max(t.tmax.size());
  const auto extremes_of_three = [tw](const std::uint8_t* in, std::uint8_t* out, auto pick) {
    for (int tx : {0, tw - 1}) {
      out[tx] = pick(pick(in[std::max(tx - 1, 0)], in[tx]), in[std::min(tx + 1, tw - 1)]);
    }
    for (int tx = 1; tx + 1 < tw; ++tx) out[tx] = pick(pick(in[tx - 1], in[tx]), in[tx + 1]);
  };
  const auto min8 = [](std::uint8_t a, std::uint8_t b) { return std::min(a, b); };
  const auto max8 = [](std::uint8_t a, std::uint8_t b) { return std::max(a, b); };
  for (int ty = 0; ty < th; ++ty) {
    const std::size_t row = static_cast<std::size_t>(ty) * tw;
    extremes_of_three(&t.tmin[row], &row_min[row], min8);
    extremes_of_three(&t.tmax[row], &row_max[row], max8);
  }
  std::vector<int> thr2(static_cast<std::size_t>(tw) * th, -1);
  std::vector<std::uint8_t> lo(static_cast<std::size_t>(tw));
  std::vector<std::uint8_t> hi(static_cast<std::size_t>(tw));
  *max_contrast = 0;
  for (int ty = 0; ty < th; ++ty) {
    const auto row = [tw](const std::vector<std::uint8_t>& v, int y) {
      return &v[static_cast<std::size_t>(y) * tw];
    };
    const int up = std::max(ty - 1, 0), down = std::min(ty + 1, th - 1);
    const std::uint8_t *mn_up = row(row_min, up), *mn = row(row_min, ty);
    const std::uint8_t *mn_down = row(row_min, down), *mx_up = row(row_max, up);
    const std::uint8_t *mx = row(row_max, ty), *mx_down = row(row_max, down);
    for (int tx = 0; tx < tw; ++tx) {
      lo[tx] = std::min(std::min(mn_up[tx], mn[tx]), mn_down[tx]);
      hi[tx] = std::max(std::max(mx_up[tx], mx[tx]), mx_down[tx]);
    }
    int* out = &thr2[static_cast<std::size_t>(ty) * tw];
    for (int tx = 0; tx < tw; ++tx) {
      const int range = hi[tx] - lo[tx];
      *max_contrast = std::max(*max_contrast, range);
      if (range >= min_contrast) out[tx] = 2 * lo[tx] + offset2[range];
    }
  }
  return thr2;
}

// Needs the doubled thresholds of tw x th tiles (-1 unknown); gives unknown tiles the mean of
// their known 4-neighbours, kThresholdPropagationPasses rings of tiles deep. Breadth-first,
// one ring of tiles per pass, so the cost is the number of tiles reached, not passes x tiles.
// The tiles are held with a border of one tile, marked as queued, so that a tile's
// neighbours are found without bounds checks or divisions.
void PropagateThresholds(int tw, int th, std::vector<int>* thresholds) {
  std::vector<int>& thr2 = *thresholds;
  // Per tile: its doubled threshold when known, kUnknown, or kQueued (unknown, in a frontier,
  // or the border, which is never queued).
  constexpr int kUnknown = -1;
  constexpr int kQueued = -2;
  const int pw = tw + 2;
  const std::size_t padded_size = static_cast<std::size_t>(pw) * (th + 2);
  std::vector<int> padded(padded_size, kQueued);
  for (int ty = 0; ty < th; ++ty) {
    std::copy_n(&thr2[static_cast<std::size_t>(ty) * tw], tw,
                &padded[static_cast<std::size_t>(ty + 1) * pw + 1]);
  }
  const std::array<int, 4> offsets = {-1, 1, -pw, pw};
  // Each tile is queued once: a frontier holds at most every tile. The appends are
  // branch-free (whether a tile joins is as good as random in a cluttered image).
  std::vector<int> frontier(padded_size);
  std::vector<int> next(padded_size);
  std::size_t frontier_size = 0;
  auto push_unknown_neighbours = [&](int i, std::vector<int>* out, std::size_t* size) {
    for (int o : offsets) {
      const int j = i + o;
      const bool join = padded[j] == kUnknown;
      (*out)[*size] = j;
      *size += join;
      padded[j] = join ? kQueued : padded[j];
    }
  };
  for (int i = 0; i < static_cast<int>(padded_size); ++i) {
    if (padded[i] >= 0) push_unknown_neighbours(i, &frontier, &frontier_size);
  }
  std::vector<int> values(padded_size);
  for (int pass = 0; pass < kThresholdPropagationPasses && frontier_size > 0; ++pass) {
    for (std::size_t f = 0; f < frontier_size; ++f) {
      int sum = 0;
      int n = 0;
      for (int o : offsets) {
        const int v = padded[frontier[f] + o];
        sum += std::max(v, 0);
        n += v >= 0;
      }
      // n >= 1 (the tile was queued next to a known one); sum >= 0, so the shifts divide by
      // 1, 2 and 4.
      values[f] = n == 3 ? sum / 3 : sum >> (n >> 1);
    }
    for (std::size_t f = 0; f < frontier_size; ++f) padded[frontier[f]] = values[f];
    std::size_t next_size = 0;
    for (std::size_t f = 0; f < frontier_size; ++f) {
      push_unknown_neighbours(frontier[f], &next, &next_size);
    }
    frontier.swap(next);
    frontier_size = next_size;
  }
  // Tiles queued for a pass beyond the last are unknown.
  for (int ty = 0; ty < th; ++ty) {
    const int* p = &padded[static_cast<std::size_t>(ty + 1) * pw + 1];
    int* out = &thr2[static_cast<std::size_t>(ty) * tw];
    for (int tx = 0; tx < tw; ++tx) out[tx] = std::max(p[tx], kUnknown);
  }
}

// Needs the image and the doubled thresholds of its tw tiles across; gives 1 where a pixel is
// below its tile's threshold, 0 elsewhere and where the threshold is unknown. O(W * H).
Image8 ApplyThresholds(const ImageView8& image, const std::vector<int>& thr2, int tw) {
  const int w = image.width;
  Image8 dark(image.width, image.height, 0);
  // Per tile row, the threshold of every pixel column as a byte: 2 v < t2 holds exactly when
  // v < (t2 + 1) / 2 (0 where unknown: v < 0 never holds; t2 <= 2 x 255), so that the
  // per-pixel loop is a comparison of bytes, 16 or 32 to an instruction.
  std::vector<std::uint8_t> column_thr(static_cast<std::size_t>(tw) * kTile);
  for (int y = 0; y < image.height; ++y) {
    if (y % kTile == 0) {
      const int* t = &thr2[static_cast<std::size_t>(y / kTile) * tw];
      for (int tx = 0; tx < tw; ++tx) {
        const auto threshold = static_cast<std::uint8_t>((std::max(t[tx], 0) + 1) >> 1);
        std::fill_n(&column_thr[static_cast<std::size_t>(tx) * kTile], kTile, threshold);
      }
    }
    const std::uint8_t* row = image.Row(y);
    std::uint8_t* out = &dark.pixels[static_cast<std::size_t>(y) * image.width];
    for (int x = 0; x < w; ++x) out[x] = static_cast<std::uint8_t>(row[x] < column_thr[x]);
  }
  return dark;
}
}  // namespace

// Immerkaer's noise estimate made robust to edges: the median absolute response of the
// Laplacian-difference kernel [1 -2 1; -2 4 -2; 1 -2 1] (std 6 sigma on white noise) over a
// sparse grid of pixels, divided by 0.6745 (the median of |N(0, 1)|) and 6. O(W * H / 8).
double EstimateNoiseSigma(const ImageView8& image) {
  if (image.width < 3 || image.height < 3) return 0.0;
  // |response| <= 16 x 255: a 16-bit integer. Four histograms, one per sample in turn, so
  // that the increments of a flat area's equal responses do not wait on one another.
  constexpr int kMaxResponse = 4 * 255 * 4;
  std::vector<std::array<int, 4>> histograms(kMaxResponse + 1, {0, 0, 0, 0});
  std::vector<std::int16_t> response(static_cast<std::size_t>(image.width));
  long count = 0;
  // Every 4th row and 2nd column: ample samples for a median, an eighth of the cost. The
  // responses of a row are taken at every column (a loop that vectorises), then read at
  // every other.
  for (int y = 1; y + 1 < image.height; y += 4) {
    const std::uint8_t* a = image.Row(y - 1);
    const std::uint8_t* b = image.Row(y);
    const std::uint8_t* c = image.Row(y + 1);
    for (int x = 1; x + 1 < image.width; ++x) {
      const int r = a[x - 1] - 2 * a[x] + a[x + 1] - 2 * (b[x - 1] - 2 * b[x] + b[x + 1]) +
                    c[x - 1] - 2 * c[x] + c[x + 1];
      response[x] = static_cast<std::int16_t>(std::abs(r));
    }
    int k = 0;
    for (int x = 1; x + 1 < image.width; x += 2) {
      ++histograms[response[x]][k];
      k = (k + 1) & 3;
      ++count;
    }
  }
  long seen = 0;
  for (int v = 0; v <= kMaxResponse; ++v) {
    const std::array<int, 4>& h = histograms[v];
    seen += h[0] + h[1] + h[2] + h[3];
    if (2 * seen >= count) return v / (0.6745 * 6.0);
  }
  return 0.0;
}

// 1 where a pixel is darker than the local minimum plus dark_fraction of the local range (over
// the 3 x 3 tiles around its tile); 0 elsewhere, including areas without printed contrast
// that no threshold reaches. *max_contrast: the largest local max - min seen.
Image8 BinariseDark(const ImageView8& image, int min_contrast, int* max_contrast,
                    double dark_fraction) {
  const TileExtremes tiles = ComputeTileExtremes(image);
  std::vector<int> thr2 = TileThresholds(tiles, min_contrast, dark_fraction, max_contrast);
  PropagateThresholds(tiles.tw, tiles.th, &thr2);
  return ApplyThresholds(image, thr2, tiles.tw);
}

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

}  // namespace linecal

#include "detectors/common/image_filters.h"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace linecal {
namespace {

// Normalised Gaussian taps w[0..r] (w[k] for offsets +-k), r = ceil(3 sigma): beyond
// 3 sigma the weights are below 1.1 % of the centre tap and hold 0.3 % of the total.
std::vector<float> GaussianTaps(double sigma_px) {
  const int radius = std::max(1, static_cast<int>(std::ceil(3.0 * sigma_px)));
  std::vector<float> taps(radius + 1);
  double sum = 0.0;
  for (int k = 0; k <= radius; ++k) {
    const double w = std::exp(-0.5 * k * k / (sigma_px * sigma_px));
    taps[k] = static_cast<float>(w);
    sum += (k == 0 ? 1.0 : 2.0) * w;
  }
  for (float& t : taps) t = static_cast<float>(t / sum);
  return taps;
}

// Four floats, one SSE register: GCC's and clang's vector extension, so that the filter
// below keeps its sums in registers, which the auto-vectoriser did not (it split a block of
// eight into 4 + 2 + 1 + 1).
using Float4 = float __attribute__((vector_size(16)));

Float4 Load4(const float* p) {
  Float4 v;
  std::memcpy(&v, p, sizeof(v));
  return v;
}

void Store4(float* p, Float4 v) { std::memcpy(p, &v, sizeof(v)); }

// Needs taps[0..r] (r = taps.size() - 1) and rows centre, before[k], after[k] (k = 1..r; the
// pixels k before and after, index 0 unused) of w floats each; gives
//   dst[x] = taps[0] centre[x] + taps[1] (before[1][x] + after[1][x]) + ... + taps[r] (...),
// summed in this order for every x, so the result does not depend on the blocking. Eight
// pixels at a time held in registers through all taps: the former tap-outer loops read and
// wrote every output once per tap, and that memory traffic bounded the blur.
void SymmetricFilterRow(const std::vector<float>& taps, const float* centre,
                        const float* const* before, const float* const* after, int w,
                        float* __restrict dst) {
  const int r = static_cast<int>(taps.size()) - 1;
  int x = 0;
  for (; x + 8 <= w; x += 8) {
    Float4 lo = taps[0] * Load4(centre + x);
    Float4 hi = taps[0] * Load4(centre + x + 4);
    for (int k = 1; k <= r; ++k) {
      const float* b = before[k] + x;
      const float* a = after[k] + x;
      lo += taps[k] * (Load4(b) + Load4(a));
      hi += taps[k] * (Load4(b + 4) + Load4(a + 4));
    }
    Store4(dst + x, lo);
    Store4(dst + x + 4, hi);
  }
  for (; x < w; ++x) {
    float sum = taps[0] * centre[x];
    for (int k = 1; k <= r; ++k) sum += taps[k] * (before[k][x] + after[k][x]);
    dst[x] = sum;
  }
}

}  // namespace

int GreyRange(const ImageView8& image) {
  std::uint8_t lo = 255, hi = 0;
  for (int y = 0; y < image.height; ++y) {
    const std::uint8_t* row = image.Row(y);
    for (int x = 0; x < image.width; ++x) {
      lo = std::min(lo, row[x]);
      hi = std::max(hi, row[x]);
    }
  }
  return hi >= lo ? hi - lo : 0;
}

ImageF GaussianBlur(const ImageView8& image, double sigma_px) {
  const int w = image.width;
  const int h = image.height;
  ImageF out(w, h);
  if (!(sigma_px > 0.0)) {
    for (int y = 0; y < h; ++y) {
      const std::uint8_t* src = image.Row(y);
      float* dst = out.Row(y);
      for (int x = 0; x < w; ++x) dst[x] = src[x];
    }
    return out;
  }
  const std::vector<float> taps = GaussianTaps(sigma_px);
  const int r = static_cast<int>(taps.size()) - 1;
  // Horizontal pass into a ring of 2r + 1 rows (a row buffer padded by r on each side, edge
  // replicated), then the vertical pass from the ring: no image-sized intermediate, whose
  // fresh pages would cost more than the arithmetic.
  const int ring_rows = 2 * r + 1;
  std::vector<float> padded(w + 2 * r);
  std::vector<float> ring(static_cast<std::size_t>(ring_rows) * w);
  std::vector<const float*> before(r + 1), after(r + 1);
  auto ring_row = [&](int y) { return ring.data() + static_cast<std::size_t>(y % ring_rows) * w; };
  auto filter_row = [&](int y) {
    const std::uint8_t* src = image.Row(y);
    // Borders apart from the middle: the middle's plain conversion loop vectorises, a
    // clamped index in it did not (a quarter of the blur's time).
    float* __restrict pad = padded.data();
    for (int x = 0; x < r; ++x) pad[x] = src[0];
    for (int x = 0; x < w; ++x) pad[r + x] = src[x];
    for (int x = 0; x < r; ++x) pad[r + w + x] = src[w - 1];
    const float* c = padded.data() + r;
    for (int k = 1; k <= r; ++k) {
      before[k] = c - k;
      after[k] = c + k;
    }
    SymmetricFilterRow(taps, c, before.data(), after.data(), w, ring_row(y));
  };
  int filtered = 0;  // rows [0, filtered) have been filtered
  for (int y = 0; y < h; ++y) {
    while (filtered < h && filtered <= y + r) filter_row(filtered++);
    for (int k = 1; k <= r; ++k) {
      before[k] = ring_row(std::max(y - k, 0));
      after[k] = ring_row(std::min(y + k, h - 1));
    }
    SymmetricFilterRow(taps, ring_row(y), before.data(), after.data(), w, out.Row(y));
  }
  return out;
}

Image8 HalveImage(const ImageView8& image) {
  const int w = image.width / 2;
  const int h = image.height / 2;
  Image8 out(w, h);
  for (int y = 0; y < h; ++y) {
    const std::uint8_t* __restrict r0 = image.Row(2 * y);
    const std::uint8_t* __restrict r1 = image.Row(2 * y + 1);
    std::uint8_t* __restrict dst = out.pixels.data() + static_cast<std::size_t>(y) * w;
    // +2 rounds the mean of four to nearest; the sum fits 10 bits.
    for (int x = 0; x < w; ++x) {
      dst[x] = static_cast<std::uint8_t>(
          (r0[2 * x] + r0[2 * x + 1] + r1[2 * x] + r1[2 * x + 1] + 2) >> 2);
    }
  }
  return out;
}

std::vector<Image8> HalvingPyramid(const ImageView8& image, int min_short_side_px) {
  std::vector<Image8> levels;
  ImageView8 source = image;
  while (std::min(source.width, source.height) / 2 >= std::max(1, min_short_side_px)) {
    levels.push_back(HalveImage(source));
    source = levels.back().view();
  }
  return levels;
}

Eigen::Vector2d LevelToImage(const Eigen::Vector2d& uv_level, int level) {
  const double scale = static_cast<double>(1 << level);
  return scale * uv_level + Eigen::Vector2d::Constant(0.5 * (scale - 1.0));
}

}  // namespace linecal

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <thread>
#include <vector>

#include "station/sim/camera_render_internal.h"

namespace linecal::camera_render_internal {
namespace {

// ------------------------------------------------------------------------------------------
// The camera response.

// Runs fn(begin, end) over [0, n) split into `threads` contiguous ranges.
template <typename Fn>
void ParallelFor(int n, int threads, const Fn& fn) {
  threads = std::max(1, std::min(threads, n));
  std::vector<std::thread> pool;
  const auto begin = [&](int i) {
    return static_cast<int>(static_cast<long long>(n) * i / threads);
  };
  for (int i = 1; i < threads; ++i) pool.emplace_back([&, i] { fn(begin(i), begin(i + 1)); });
  fn(0, begin(1));
  for (std::thread& t : pool) t.join();
}

// The JPEG luminance quantisation table (ITU-T T.81 Annex K, Table K.1), row-major.
constexpr std::array<int, 64> kJpegLuminance = {
    16, 11, 10, 16, 24,  40,  51,  61,  12, 12, 14, 19, 26,  58,  60,  55,
    14, 13, 16, 24, 40,  57,  69,  56,  14, 17, 22, 29, 51,  87,  80,  62,
    18, 22, 37, 56, 68,  109, 103, 77,  24, 35, 55, 64, 81,  104, 113, 92,
    49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99};

// Encodes and decodes `grey` (8-bit scale, row-major) as a JPEG's 8 x 8 luminance blocks
// would be at `quality`: level shift, DCT, quantisation with the IJG-scaled table, inverse.
// Partial blocks at the right and bottom are padded by repeating the edge.
void JpegQuantise(int width, int height, int quality, int threads, std::vector<float>* grey) {
  std::array<double, 64> q;
  const int scale = quality < 50 ? 5000 / quality : 200 - 2 * quality;  // IJG's mapping
  for (int i = 0; i < 64; ++i) q[i] = std::clamp((kJpegLuminance[i] * scale + 50) / 100, 1, 255);
  // Orthonormal DCT-II basis: c[k][x] = a(k) cos((2x + 1) k pi / 16).
  std::array<std::array<double, 8>, 8> c;
  for (int k = 0; k < 8; ++k) {
    for (int x = 0; x < 8; ++x) {
      c[k][x] =
          (k == 0 ? std::sqrt(0.125) : 0.5) * std::cos((2 * x + 1) * k * std::numbers::pi / 16);
    }
  }
  const int block_rows = (height + 7) / 8, block_cols = (width + 7) / 8;
  ParallelFor(block_rows, threads, [&](int b0, int b1) {
    for (int by = b0; by < b1; ++by) {
      for (int bx = 0; bx < block_cols; ++bx) {
        std::array<std::array<double, 8>, 8> f, g;
        for (int y = 0; y < 8; ++y) {
          const int yy = std::min(by * 8 + y, height - 1);
          for (int x = 0; x < 8; ++x) {
            const int xx = std::min(bx * 8 + x, width - 1);
            f[y][x] = (*grey)[static_cast<std::size_t>(yy) * width + xx] - 128.0;
          }
        }
        // Rows, then columns: g = C f C^T, quantised; then f = C^T g C.
        for (int y = 0; y < 8; ++y) {
          for (int k = 0; k < 8; ++k) {
            double s = 0.0;
            for (int x = 0; x < 8; ++x) s += c[k][x] * f[y][x];
            g[y][k] = s;
          }
        }
        for (int k = 0; k < 8; ++k) {
          for (int l = 0; l < 8; ++l) {
            double s = 0.0;
            for (int y = 0; y < 8; ++y) s += c[l][y] * g[y][k];
            f[l][k] = std::round(s / q[l * 8 + k]) * q[l * 8 + k];
          }
        }
        for (int l = 0; l < 8; ++l) {
          for (int x = 0; x < 8; ++x) {
            double s = 0.0;
            for (int k = 0; k < 8; ++k) s += c[k][x] * f[l][k];
            g[l][x] = s;
          }
        }
        for (int y = 0; y < 8 && by * 8 + y < height; ++y) {
          for (int x = 0; x < 8 && bx * 8 + x < width; ++x) {
            double s = 0.0;
            for (int l = 0; l < 8; ++l) s += c[l][y] * g[l][x];
            (*grey)[static_cast<std::size_t>(by * 8 + y) * width + bx * 8 + x] =
                static_cast<float>(s + 128.0);
          }
        }
      }
    }
  });
}

}  // namespace

// Illumination x gradient x vignetting, per pixel.
void Illuminate(const CameraModel& camera, const CameraRenderOptions& o,
                std::vector<float>* image) {
  const int width = camera.intrinsics().width, height = camera.intrinsics().height;
  const double angle = o.illumination_gradient_direction_deg * std::numbers::pi / 180.0;
  const Eigen::Vector2d dir(std::cos(angle), std::sin(angle));
  // The gradient runs between the extreme pixel centres along dir, so that the brightest
  // and the darkest pixel differ by exactly the ratio.
  double lo = kInf, hi = -kInf;
  for (const Eigen::Vector2d& corner :
       {Eigen::Vector2d(0, 0), Eigen::Vector2d(width - 1, 0), Eigen::Vector2d(0, height - 1),
        Eigen::Vector2d(width - 1, height - 1)}) {
    lo = std::min(lo, corner.dot(dir));
    hi = std::max(hi, corner.dot(dir));
  }
  // exp(log_ratio (s - 0.5)) with s linear in (u, v) factors into a column and a row term.
  const double log_ratio = std::log(o.illumination_gradient_ratio);
  const double scale = hi > lo ? log_ratio / (hi - lo) : 0.0;
  std::vector<double> column_gain(width), row_gain(height);
  for (int x = 0; x < width; ++x) column_gain[x] = std::exp(scale * x * dir.x());
  for (int y = 0; y < height; ++y) {
    row_gain[y] = o.illumination * std::exp(scale * (y * dir.y() - lo) - 0.5 * log_ratio);
  }
  const Eigen::Vector2d principal(camera.intrinsics().cx, camera.intrinsics().cy);
  double r2_max = 0.0;
  for (const Eigen::Vector2d& corner :
       {Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(width - 0.5, -0.5),
        Eigen::Vector2d(-0.5, height - 0.5), Eigen::Vector2d(width - 0.5, height - 0.5)}) {
    r2_max = std::max(r2_max, (corner - principal).squaredNorm());
  }
  ParallelFor(height, o.threads, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y) {
      float* row = image->data() + static_cast<std::size_t>(y) * width;
      const double dy2 = (y - principal.y()) * (y - principal.y());
      for (int x = 0; x < width; ++x) {
        const double r2 = (x - principal.x()) * (x - principal.x()) + dy2;
        const double vignette = 1.0 - o.vignetting * r2 / r2_max;
        row[x] = static_cast<float>(row[x] * row_gain[y] * column_gain[x] * vignette);
      }
    }
  });
}

// Separable Gaussian blur, the kernel integrated over each pixel (so that any sigma,
// however small, keeps the total and the symmetry), clamped at the borders.
void Blur(int width, int height, double sigma, int threads, std::vector<float>* image) {
  // 4 sigma: the tails beyond hold 6e-5 of the weight, below a 16-bit grey step.
  const int radius = std::max(1, static_cast<int>(std::ceil(4.0 * sigma)));
  std::vector<double> kernel(2 * radius + 1);
  double total = 0.0;
  for (int k = -radius; k <= radius; ++k) {
    const double w = 0.5 * (std::erf((k + 0.5) / (std::sqrt(2.0) * sigma)) -
                            std::erf((k - 0.5) / (std::sqrt(2.0) * sigma)));
    kernel[k + radius] = w;
    total += w;
  }
  for (double& w : kernel) w /= total;
  std::vector<float> tmp(image->size());
  // Along rows, then across them whole rows at a time (cache-friendly).
  ParallelFor(height, threads, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y) {
      const float* src = image->data() + static_cast<std::size_t>(y) * width;
      float* dst = tmp.data() + static_cast<std::size_t>(y) * width;
      for (int x = 0; x < width; ++x) {
        double sum = 0.0;
        for (int k = -radius; k <= radius; ++k) {
          sum += kernel[k + radius] * src[std::clamp(x + k, 0, width - 1)];
        }
        dst[x] = static_cast<float>(sum);
      }
    }
  });
  ParallelFor(height, threads, [&](int y0, int y1) {
    std::vector<double> sum(width);
    for (int y = y0; y < y1; ++y) {
      std::fill(sum.begin(), sum.end(), 0.0);
      for (int k = -radius; k <= radius; ++k) {
        const float* src =
            tmp.data() + static_cast<std::size_t>(std::clamp(y + k, 0, height - 1)) * width;
        const double w = kernel[k + radius];
        for (int x = 0; x < width; ++x) sum[x] += w * src[x];
      }
      float* dst = image->data() + static_cast<std::size_t>(y) * width;
      for (int x = 0; x < width; ++x) dst[x] = static_cast<float>(sum[x]);
    }
  });
}

// Linear light to grey levels: gamma, then noise, then JPEG, then rounding.
void Encode(int width, int height, const CameraRenderOptions& o, std::uint64_t seed,
            std::vector<float>* image, CameraFrame* frame) {
  constexpr double kFullScale8 = 255.0;
  const double inverse_gamma = 1.0 / o.gamma;
  ParallelFor(height, o.threads, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y) {
      // One stream per row: the same numbers whichever thread draws them.
      std::mt19937_64 rng(Mix(Mix(seed, kNoiseStream), static_cast<std::uint64_t>(y)));
      std::normal_distribution<double> normal;
      float* row = image->data() + static_cast<std::size_t>(y) * width;
      for (int x = 0; x < width; ++x) {
        const double linear = std::clamp(static_cast<double>(row[x]), 0.0, 1.0);
        double grey = kFullScale8 * (o.gamma == 1.0 ? linear : std::pow(linear, inverse_gamma));
        if (o.noise_sigma > 0.0) grey += o.noise_sigma * normal(rng);
        row[x] = static_cast<float>(grey);
      }
    }
  });
  if (o.jpeg_quality > 0) JpegQuantise(width, height, o.jpeg_quality, o.threads, image);
  frame->bit_depth = o.bit_depth;
  if (o.bit_depth == 8) {
    frame->image8 = Image8(width, height);
    for (std::size_t i = 0; i < image->size(); ++i) {
      frame->image8.pixels[i] =
          static_cast<std::uint8_t>(std::lround(std::clamp((*image)[i], 0.0f, 255.0f)));
    }
  } else {
    // 16-bit full scale is 257 x the 8-bit one (255 * 257 = 65535).
    constexpr double kEightToSixteen = 257.0;
    frame->image16 = Image16(width, height);
    for (std::size_t i = 0; i < image->size(); ++i) {
      frame->image16.pixels[i] = static_cast<std::uint16_t>(
          std::lround(std::clamp(kEightToSixteen * (*image)[i], 0.0, 65535.0)));
    }
  }
}

}  // namespace linecal::camera_render_internal

#include "detectors/common/corner_refine.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>

namespace linecal {

std::optional<Eigen::Vector2d> RefineSaddle(const ImageF& blurred, const Eigen::Vector2d& start_px,
                                            const SaddleFitOptions& options) {
  const int w = options.half_window;
  if (w < 1 || blurred.width < 2 * w + 3 || blurred.height < 2 * w + 3) return std::nullopt;
  // Least squares on the symmetric grid of offsets -w..w decouples: d, e and b come from
  // one moment each, and a, c, g from a 3 x 3 system of the even moments S2 = sum x^2,
  // S4 = sum x^4, S22 = sum x^2 y^2 and N (sums over the whole window).
  const int side = 2 * w + 1;
  constexpr int kMaxSide = 2 * 15 + 1;  // SaddleFitOptions::half_window <= 15
  if (side > kMaxSide) return std::nullopt;
  double s2_1d = 0.0, s4_1d = 0.0;
  for (int i = -w; i <= w; ++i) {
    s2_1d += i * i;
    s4_1d += static_cast<double>(i) * i * i * i;
  }
  const double n = static_cast<double>(side) * side;
  const double s2 = s2_1d * side;
  const double s4 = s4_1d * side;
  const double s22 = s2_1d * s2_1d;
  Eigen::Matrix3d even;
  even << s4, s22, s2, s22, s4, s2, s2, s2, n;
  const Eigen::Matrix3d even_inverse = even.inverse();

  Eigen::Vector2d p = start_px;
  for (int it = 0; it < options.max_iterations; ++it) {
    // Keep the whole window on real pixels: clamped samples would break the symmetry.
    if (!(p.x() >= w && p.y() >= w && p.x() <= blurred.width - 2 - w &&
          p.y() <= blurred.height - 2 - w)) {
      return std::nullopt;
    }
    // Every sample has the same fractional offset, so one set of bilinear weights serves
    // the whole window.
    const int x0 = static_cast<int>(std::floor(p.x()));
    const int y0 = static_cast<int>(std::floor(p.y()));
    const double fx = p.x() - x0;
    const double fy = p.y() - y0;
    const double w00 = (1 - fx) * (1 - fy), w10 = fx * (1 - fy), w01 = (1 - fx) * fy, w11 = fx * fy;
    double m_x = 0, m_y = 0, m_xy = 0, m_xx = 0, m_yy = 0, m_1 = 0;
    for (int j = -w; j <= w; ++j) {
      const float* r0 = blurred.Row(y0 + j) + x0 - w;
      const float* r1 = blurred.Row(y0 + j + 1) + x0 - w;
      // The row's samples first, in a loop of their own that vectorises; the moments below
      // add them in the same order as before (sums that depend on the previous one).
      std::array<double, kMaxSide> row;
      for (int k = 0; k < side; ++k) {
        row[k] = w00 * r0[k] + w10 * r0[k + 1] + w01 * r1[k] + w11 * r1[k + 1];
      }
      for (int i = -w; i <= w; ++i) {
        const double f = row[i + w];
        m_x += i * f;
        m_y += j * f;
        m_xy += i * j * f;
        m_xx += i * i * f;
        m_yy += j * j * f;
        m_1 += f;
      }
    }
    const double d = m_x / s2;
    const double e = m_y / s2;
    const double b = m_xy / s22;
    const Eigen::Vector3d acg = even_inverse * Eigen::Vector3d(m_xx, m_yy, m_1);
    const double a = acg[0];
    const double cc = acg[1];
    // Hessian [2a b; b 2c]: a saddle has a negative determinant.
    const double det = 4.0 * a * cc - b * b;
    if (!(det < 0.0)) return std::nullopt;
    const Eigen::Vector2d step((-2.0 * cc * d + b * e) / det, (b * d - 2.0 * a * e) / det);
    p += step;
    if (!p.allFinite() || (p - start_px).norm() > w) return std::nullopt;
    if (step.norm() < options.converged_px) return p;
  }
  return p;
}

std::optional<Eigen::Vector2d> RefineXCornerOnPatch(const ImageView8& image,
                                                    const Eigen::Vector2d& start_px, double side_px,
                                                    double blur_sigma_px) {
  SaddleFitOptions saddle;
  // Clamped as a double: a huge side would overflow the cast.
  saddle.half_window = static_cast<int>(std::clamp(side_px / 3.0, 2.0, 7.0));
  // The patch holds the window, a pixel of movement and the blur kernel (3 sigma) clear of
  // its clamped border, plus two pixels for the saddle fit's own border rule.
  const int radius = saddle.half_window + 1 + static_cast<int>(std::ceil(3.0 * blur_sigma_px)) + 2;
  // Also keeps the casts below defined: a start far off the image would overflow them.
  if (!start_px.allFinite() || start_px.x() < 0.0 || start_px.y() < 0.0 ||
      start_px.x() >= image.width || start_px.y() >= image.height) {
    return std::nullopt;
  }
  const int x0 = static_cast<int>(std::floor(start_px.x())) - radius;
  const int y0 = static_cast<int>(std::floor(start_px.y())) - radius;
  const int size = 2 * radius + 2;
  if (x0 < 0 || y0 < 0 || x0 + size > image.width || y0 + size > image.height) {
    return std::nullopt;
  }
  ImageView8 patch;
  patch.data = image.Row(y0) + x0;
  patch.width = size;
  patch.height = size;
  patch.stride_bytes = image.stride_bytes;
  const ImageF blurred = GaussianBlur(patch, blur_sigma_px);
  const Eigen::Vector2d offset(x0, y0);
  const std::optional<Eigen::Vector2d> refined = RefineSaddle(blurred, start_px - offset, saddle);
  if (!refined || (*refined + offset - start_px).norm() > 1.0) return std::nullopt;
  return *refined + offset;
}

}  // namespace linecal

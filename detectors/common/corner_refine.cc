#include "detectors/common/corner_refine.h"

#include <cmath>
#include <vector>

#include <Eigen/Dense>

namespace linecal {

std::optional<Eigen::Vector2d> RefineSaddle(const ImageF& blurred, const Eigen::Vector2d& start_px,
                                            const SaddleFitOptions& options) {
  const int w = options.half_window;
  if (w < 1 || blurred.width < 2 * w + 3 || blurred.height < 2 * w + 3) return std::nullopt;
  // The least-squares solution is a fixed linear map of the samples, because the sample
  // offsets are the same at every iteration: coefficients = (A^T A)^-1 A^T * samples.
  const int side = 2 * w + 1;
  const int n = side * side;
  Eigen::MatrixXd A(n, 6);
  for (int j = 0, k = 0; j < side; ++j) {
    for (int i = 0; i < side; ++i, ++k) {
      const double x = i - w;
      const double y = j - w;
      A.row(k) << x * x, x * y, y * y, x, y, 1.0;
    }
  }
  const Eigen::MatrixXd solver = (A.transpose() * A).ldlt().solve(A.transpose());
  Eigen::VectorXd samples(n);
  Eigen::Vector2d p = start_px;
  for (int it = 0; it < options.max_iterations; ++it) {
    // Keep the whole window on real pixels: clamped samples would break the symmetry.
    if (p.x() < w || p.y() < w || p.x() > blurred.width - 1 - w ||
        p.y() > blurred.height - 1 - w) {
      return std::nullopt;
    }
    for (int j = 0, k = 0; j < side; ++j) {
      for (int i = 0; i < side; ++i, ++k) {
        samples[k] = SampleBilinear(blurred, p.x() + (i - w), p.y() + (j - w));
      }
    }
    const Eigen::Matrix<double, 6, 1> c = solver * samples;
    const double a = c[0], b = c[1], cc = c[2], d = c[3], e = c[4];
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

}  // namespace linecal

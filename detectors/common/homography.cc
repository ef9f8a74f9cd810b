#include "detectors/common/homography.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>

namespace linecal {
namespace {

// A similarity that moves the points' centroid to the origin and scales their mean distance
// from it to sqrt(2) (Hartley's normalisation, which makes the DLT well conditioned).
// Returns nullopt when all points coincide.
std::optional<Eigen::Matrix3d> NormalisingTransform(std::span<const Eigen::Vector2d> points) {
  Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
  for (const Eigen::Vector2d& p : points) centroid += p;
  centroid /= static_cast<double>(points.size());
  double mean_distance = 0.0;
  for (const Eigen::Vector2d& p : points) mean_distance += (p - centroid).norm();
  mean_distance /= static_cast<double>(points.size());
  // Below this relative spread the points are one point at double precision.
  constexpr double kMinRelativeSpread = 1e-12;
  if (!(mean_distance > kMinRelativeSpread * (1.0 + centroid.norm()))) return std::nullopt;
  const double s = std::sqrt(2.0) / mean_distance;
  Eigen::Matrix3d T;
  T << s, 0.0, -s * centroid.x(), 0.0, s, -s * centroid.y(), 0.0, 0.0, 1.0;
  return T;
}

Eigen::Vector2d Transform(const Eigen::Matrix3d& T, const Eigen::Vector2d& p) {
  return (T * p.homogeneous()).hnormalized();
}

// Sum of squared one-sided residuals of Hn (h22 fixed to 1) over normalised points.
double Cost(const Eigen::Matrix3d& Hn, const std::vector<Eigen::Vector2d>& xs,
            const std::vector<Eigen::Vector2d>& ys) {
  double cost = 0.0;
  for (std::size_t i = 0; i < xs.size(); ++i) {
    const Eigen::Vector3d q = Hn * xs[i].homogeneous();
    if (q.z() == 0.0) return std::numeric_limits<double>::infinity();
    cost += (q.head<2>() / q.z() - ys[i]).squaredNorm();
  }
  return cost;
}

// Levenberg-Marquardt on the 8 entries of Hn other than Hn(2, 2) = 1. xs, ys are the
// normalised source and destination points; the destination normalisation is a similarity,
// so its error is the pixel error times a constant and the minimiser is the same.
void RefineNormalised(const std::vector<Eigen::Vector2d>& xs,
                      const std::vector<Eigen::Vector2d>& ys, int max_iterations,
                      Eigen::Matrix3d* Hn) {
  double cost = Cost(*Hn, xs, ys);
  // Marquardt's damping: start small (the DLT start is near the minimum), grow by 10 on a
  // rejected step, shrink by 10 on an accepted one.
  double lambda = 1e-3;
  // Stop when a step improves the cost by less than this fraction: the parameters are then
  // at the minimum to well below the precision any caller uses.
  constexpr double kRelativeImprovement = 1e-10;
  for (int it = 0; it < max_iterations; ++it) {
    Eigen::Matrix<double, 8, 8> JtJ = Eigen::Matrix<double, 8, 8>::Zero();
    Eigen::Matrix<double, 8, 1> Jtr = Eigen::Matrix<double, 8, 1>::Zero();
    for (std::size_t i = 0; i < xs.size(); ++i) {
      const double x = xs[i].x();
      const double y = xs[i].y();
      const Eigen::Vector3d q = *Hn * xs[i].homogeneous();
      const double inv_w = 1.0 / q.z();
      const double u = q.x() * inv_w;
      const double v = q.y() * inv_w;
      Eigen::Matrix<double, 2, 8> J;
      J << x * inv_w, y * inv_w, inv_w, 0.0, 0.0, 0.0, -u * x * inv_w, -u * y * inv_w,  //
          0.0, 0.0, 0.0, x * inv_w, y * inv_w, inv_w, -v * x * inv_w, -v * y * inv_w;
      const Eigen::Vector2d r(u - ys[i].x(), v - ys[i].y());
      JtJ.noalias() += J.transpose() * J;
      Jtr.noalias() += J.transpose() * r;
    }
    bool accepted = false;
    // Ten rejections in a row (lambda grown 10^10) means no descent direction is left.
    constexpr int kMaxRejections = 10;
    for (int attempt = 0; attempt < kMaxRejections && !accepted; ++attempt) {
      Eigen::Matrix<double, 8, 8> A = JtJ;
      A.diagonal() += lambda * JtJ.diagonal();
      const Eigen::Matrix<double, 8, 1> step = A.ldlt().solve(-Jtr);
      if (!step.allFinite()) {
        lambda *= 10.0;
        continue;
      }
      Eigen::Matrix3d candidate = *Hn;
      for (int k = 0; k < 8; ++k) candidate(k / 3, k % 3) += step[k];
      const double new_cost = Cost(candidate, xs, ys);
      if (new_cost < cost) {
        const double improvement = cost - new_cost;
        *Hn = candidate;
        cost = new_cost;
        lambda *= 0.1;
        accepted = true;
        if (improvement <= kRelativeImprovement * cost) return;
      } else {
        lambda *= 10.0;
      }
    }
    if (!accepted) return;
  }
}

}  // namespace

std::optional<HomographyFit> FitHomography(std::span<const Eigen::Vector2d> src,
                                           std::span<const Eigen::Vector2d> dst,
                                           const HomographyFitOptions& options) {
  if (src.size() != dst.size() || src.size() < 4) return std::nullopt;
  for (std::size_t i = 0; i < src.size(); ++i) {
    if (!src[i].allFinite() || !dst[i].allFinite()) return std::nullopt;
  }
  const std::optional<Eigen::Matrix3d> T_src = NormalisingTransform(src);
  const std::optional<Eigen::Matrix3d> T_dst = NormalisingTransform(dst);
  if (!T_src || !T_dst) return std::nullopt;

  const std::size_t n = src.size();
  std::vector<Eigen::Vector2d> xs(n);
  std::vector<Eigen::Vector2d> ys(n);
  Eigen::Matrix<double, 9, 9> AtA = Eigen::Matrix<double, 9, 9>::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    xs[i] = Transform(*T_src, src[i]);
    ys[i] = Transform(*T_dst, dst[i]);
    const double x = xs[i].x();
    const double y = xs[i].y();
    const double u = ys[i].x();
    const double v = ys[i].y();
    Eigen::Matrix<double, 2, 9> rows;
    rows << -x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u,  //
        0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v;
    // A lazy (coefficient-wise) product: 9 + 9 + 2 dimensions are past Eigen's threshold for
    // the blocked matrix-product kernel, whose packing costs more than this small product.
    // The same sums either way (each coefficient a product of the two rows' terms added).
    AtA.noalias() += rows.transpose().lazyProduct(rows);
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> eig(AtA);
  if (eig.info() != Eigen::Success) return std::nullopt;
  // Eigenvalues ascend. A second (near) zero eigenvalue means a family of exact solutions:
  // the points do not determine H. 1e-10 of the largest is far below what noise on
  // normalised coordinates (order 1) produces and far above rounding (1e-16).
  constexpr double kDegenerateEigenRatio = 1e-10;
  if (!(eig.eigenvalues()[1] > kDegenerateEigenRatio * eig.eigenvalues()[8])) {
    return std::nullopt;
  }
  const Eigen::Matrix<double, 9, 1> h = eig.eigenvectors().col(0);
  Eigen::Matrix3d Hn;
  Hn << h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8];
  // A rank-deficient H maps the plane onto a line or a point: not a view of a plane. The
  // ratio bound is the same "zero at double precision with margin" as above.
  const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3d>(Hn).singularValues();
  if (!(sv[2] > kDegenerateEigenRatio * sv[0])) return std::nullopt;

  // Hn(2, 2) is w at the source centroid. It is far from zero whenever the centroid maps to
  // a finite point (always so for a board in front of a camera), which lets refinement fix
  // it to 1; 1e-6 of |Hn| (unit norm) is "at infinity" for any real view.
  constexpr double kMinCentroidW = 1e-6;
  if (options.refine && std::abs(Hn(2, 2)) > kMinCentroidW) {
    Hn /= Hn(2, 2);
    RefineNormalised(xs, ys, options.max_iterations, &Hn);
  }

  HomographyFit fit;
  fit.H = T_dst->inverse() * Hn * *T_src;
  fit.H /= fit.H.norm();
  if (fit.H(2, 2) < 0.0) fit.H = -fit.H;
  std::vector<double> residuals;
  fit.rms_residual = HomographyResiduals(fit.H, src, dst, &residuals);
  if (!std::isfinite(fit.rms_residual)) return std::nullopt;
  for (double r : residuals) fit.max_residual = std::max(fit.max_residual, r);
  return fit;
}

Eigen::Vector2d ApplyHomography(const Eigen::Matrix3d& H, const Eigen::Vector2d& p) {
  const Eigen::Vector3d q = H * p.homogeneous();
  // w this small relative to the terms that make it is zero up to rounding: the point is on
  // the line at infinity of the destination plane.
  // Compared squared: the same test without two square roots (the detectors map thousands
  // of points per frame).
  constexpr double kRelativeZeroW = 1e-12;
  if (!(q.z() * q.z() >
        kRelativeZeroW * kRelativeZeroW * H.row(2).squaredNorm() * p.homogeneous().squaredNorm())) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    return Eigen::Vector2d(nan, nan);
  }
  return q.head<2>() / q.z();
}

double HomographyResiduals(const Eigen::Matrix3d& H, std::span<const Eigen::Vector2d> src,
                           std::span<const Eigen::Vector2d> dst, std::vector<double>* residuals) {
  residuals->assign(src.size(), 0.0);
  if (src.empty()) return 0.0;
  double sum_sq = 0.0;
  for (std::size_t i = 0; i < src.size(); ++i) {
    const Eigen::Vector2d q = ApplyHomography(H, src[i]);
    const double r = q.allFinite() ? (q - dst[i]).norm() : std::numeric_limits<double>::infinity();
    (*residuals)[i] = r;
    sum_sq += r * r;
  }
  return std::sqrt(sum_sq / static_cast<double>(src.size()));
}

double LocalSquareSide(const Eigen::Matrix3d& H, const Eigen::Vector2d& p_src, double side_src) {
  const Eigen::Vector2d p = ApplyHomography(H, p_src);
  const Eigen::Vector2d dx = ApplyHomography(H, p_src + Eigen::Vector2d(side_src, 0.0)) - p;
  const Eigen::Vector2d dy = ApplyHomography(H, p_src + Eigen::Vector2d(0.0, side_src)) - p;
  return std::sqrt(std::abs(dx.x() * dy.y() - dx.y() * dy.x()));
}

}  // namespace linecal

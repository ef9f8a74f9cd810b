#include "detectors/common/ellipse.h"

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <numbers>
#include <utility>

namespace linecal {

Eigen::Matrix3d Ellipse::Conic() const {
  const double c = std::cos(angle_rad);
  const double s = std::sin(angle_rad);
  // In the ellipse's own axes: x'^2 / a^2 + y'^2 / b^2 - 1, with x' = R^T (x - centre).
  Eigen::Matrix2d r;
  r << c, -s, s, c;
  const Eigen::Matrix2d m =
      r *
      Eigen::Vector2d(1.0 / (semi_major * semi_major), 1.0 / (semi_minor * semi_minor))
          .asDiagonal() *
      r.transpose();
  Eigen::Matrix3d conic;
  conic.topLeftCorner<2, 2>() = m;
  const Eigen::Vector2d mc = -m * centre;
  conic.topRightCorner<2, 1>() = mc;
  conic.bottomLeftCorner<1, 2>() = mc.transpose();
  conic(2, 2) = centre.dot(m * centre) - 1.0;
  return conic;
}

Eigen::Vector2d Ellipse::PointAt(double t) const {
  const double c = std::cos(angle_rad);
  const double s = std::sin(angle_rad);
  const double x = semi_major * std::cos(t);
  const double y = semi_minor * std::sin(t);
  return centre + Eigen::Vector2d(c * x - s * y, s * x + c * y);
}

std::optional<Ellipse> EllipseFromConic(const Eigen::Matrix3d& conic_in) {
  if (!conic_in.allFinite()) return std::nullopt;
  const Eigen::Matrix3d conic = 0.5 * (conic_in + conic_in.transpose());
  const Eigen::Matrix2d m = conic.topLeftCorner<2, 2>();
  const double det = m.determinant();
  // An ellipse needs a definite quadratic part; the relative bound rejects parabolas whose
  // determinant is zero up to rounding.
  if (!(det > 1e-14 * m.squaredNorm())) return std::nullopt;
  const Eigen::Vector2d centre = m.inverse() * (-conic.topRightCorner<2, 1>());
  // The form at the centre: q(centre + y) = y^T m y + k.
  const double k = conic(2, 2) + conic.topRightCorner<2, 1>().dot(centre);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(m);
  const Eigen::Vector2d lambda = eig.eigenvalues();  // ascending
  // Real ellipse: -k has the sign of both eigenvalues (same sign since det > 0).
  if (!(-k / lambda(0) > 0.0) || !(-k / lambda(1) > 0.0)) return std::nullopt;
  Ellipse e;
  e.centre = centre;
  e.semi_major = std::sqrt(-k / lambda(0));  // smallest |eigenvalue| gives the longest axis
  e.semi_minor = std::sqrt(-k / lambda(1));
  if (lambda(0) < 0.0) std::swap(e.semi_major, e.semi_minor);
  const Eigen::Vector2d axis = eig.eigenvectors().col(lambda(0) < 0.0 ? 1 : 0);
  double angle = std::atan2(axis.y(), axis.x());
  if (angle <= -std::numbers::pi / 2) angle += std::numbers::pi;
  if (angle > std::numbers::pi / 2) angle -= std::numbers::pi;
  e.angle_rad = angle;
  if (!std::isfinite(e.semi_major) || !std::isfinite(e.semi_minor) || !centre.allFinite()) {
    return std::nullopt;
  }
  return e;
}

std::optional<Ellipse> FitEllipse(std::span<const Eigen::Vector2d> points,
                                  std::span<const double> weights) {
  const std::size_t n = points.size();
  // Five points determine a conic; fewer leave the fit undetermined.
  if (n < 5) return std::nullopt;
  if (!weights.empty() && weights.size() != n) return std::nullopt;
  auto weight = [&](std::size_t i) { return weights.empty() ? 1.0 : weights[i]; };

  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  double weight_sum = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!points[i].allFinite() || !(weight(i) >= 0.0) || !std::isfinite(weight(i))) {
      return std::nullopt;
    }
    mean += weight(i) * points[i];
    weight_sum += weight(i);
  }
  if (!(weight_sum > 0.0)) return std::nullopt;
  mean /= weight_sum;
  double spread = 0.0;
  for (std::size_t i = 0; i < n; ++i) spread += weight(i) * (points[i] - mean).squaredNorm();
  spread = std::sqrt(spread / weight_sum);
  if (!(spread > 0.0)) return std::nullopt;
  // Unit RMS distance from the centroid keeps the scatter matrices well conditioned.
  const double scale = 1.0 / spread;

  // Scatter matrices of the quadratic (x^2, xy, y^2) and linear (x, y, 1) parts.
  Eigen::Matrix3d s1 = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d s2 = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d s3 = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d p = scale * (points[i] - mean);
    const Eigen::Vector3d d1(p.x() * p.x(), p.x() * p.y(), p.y() * p.y());
    const Eigen::Vector3d d2(p.x(), p.y(), 1.0);
    const double w2 = weight(i) * weight(i);
    s1.noalias() += w2 * d1 * d1.transpose();
    s2.noalias() += w2 * d1 * d2.transpose();
    s3.noalias() += w2 * d2 * d2.transpose();
  }
  const Eigen::FullPivLU<Eigen::Matrix3d> s3_lu(s3);
  // Points on one line (or fewer than three distinct points) make s3 singular.
  if (!s3_lu.isInvertible()) return std::nullopt;
  const Eigen::Matrix3d t = -s3_lu.solve(s2.transpose());
  const Eigen::Matrix3d reduced = s1 + s2 * t;
  // Premultiply by the inverse of the constraint matrix [[0, 0, 2], [0, -1, 0], [2, 0, 0]].
  Eigen::Matrix3d m;
  m.row(0) = 0.5 * reduced.row(2);
  m.row(1) = -reduced.row(1);
  m.row(2) = 0.5 * reduced.row(0);
  const Eigen::EigenSolver<Eigen::Matrix3d> eig(m);
  if (eig.info() != Eigen::Success) return std::nullopt;
  // The ellipse is the eigenvector with 4ac - b^2 > 0 (exactly one for an ellipse-like set).
  int best = -1;
  double best_constraint = 0.0;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d v = eig.eigenvectors().col(k).real();
    const double constraint = 4.0 * v(0) * v(2) - v(1) * v(1);
    if (constraint > best_constraint) {
      best_constraint = constraint;
      best = k;
    }
  }
  if (best < 0) return std::nullopt;
  const Eigen::Vector3d a1 = eig.eigenvectors().col(best).real();
  const Eigen::Vector3d a2 = t * a1;
  Eigen::Matrix3d conic_n;
  conic_n << a1(0), 0.5 * a1(1), 0.5 * a2(0), 0.5 * a1(1), a1(2), 0.5 * a2(1), 0.5 * a2(0),
      0.5 * a2(1), a2(2);
  // Back to image coordinates: p_n = N p with N = [[s, 0, -s mx], [0, s, -s my], [0, 0, 1]].
  Eigen::Matrix3d norm;
  norm << scale, 0.0, -scale * mean.x(), 0.0, scale, -scale * mean.y(), 0.0, 0.0, 1.0;
  return EllipseFromConic(norm.transpose() * conic_n * norm);
}

std::optional<Ellipse> EllipseFromMoments(const Eigen::Vector2d& centroid,
                                          const Eigen::Matrix2d& covariance) {
  if (!centroid.allFinite() || !covariance.allFinite()) return std::nullopt;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(0.5 *
                                                           (covariance + covariance.transpose()));
  const Eigen::Vector2d lambda = eig.eigenvalues();  // ascending
  if (!(lambda(0) > 0.0)) return std::nullopt;
  Ellipse e;
  e.centre = centroid;
  e.semi_major = 2.0 * std::sqrt(lambda(1));
  e.semi_minor = 2.0 * std::sqrt(lambda(0));
  const Eigen::Vector2d axis = eig.eigenvectors().col(1);
  double angle = std::atan2(axis.y(), axis.x());
  if (angle <= -std::numbers::pi / 2) angle += std::numbers::pi;
  if (angle > std::numbers::pi / 2) angle -= std::numbers::pi;
  e.angle_rad = angle;
  return e;
}

double SampsonDistance(const Eigen::Matrix3d& conic, const Eigen::Vector2d& p) {
  const Eigen::Vector3d x(p.x(), p.y(), 1.0);
  const Eigen::Vector3d cx = conic * x;
  const double q = x.dot(cx);
  const double gradient = 2.0 * cx.head<2>().norm();
  if (!(gradient > 0.0)) return std::numeric_limits<double>::infinity();
  return std::abs(q) / gradient;
}

Eigen::Matrix3d ImageOfCircle(const Eigen::Matrix3d& H, const Eigen::Vector2d& centre,
                              double radius) {
  Eigen::Matrix3d circle;
  circle << 1.0, 0.0, -centre.x(), 0.0, 1.0, -centre.y(), -centre.x(), -centre.y(),
      centre.squaredNorm() - radius * radius;
  const Eigen::Matrix3d h_inv = H.inverse();
  Eigen::Matrix3d image = h_inv.transpose() * circle * h_inv;
  image = 0.5 * (image + image.transpose());
  const double norm = image.norm();
  return norm > 0.0 ? Eigen::Matrix3d(image / norm) : image;
}

}  // namespace linecal

#include "detectors/common/edge_lines.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

namespace linecal {

bool InsideForBilinearGrey(const ImageView8& image, const Eigen::Vector2d& p) {
  return p.x() >= 0.0 && p.y() >= 0.0 && p.x() < image.width - 1.0 && p.y() < image.height - 1.0;
}

double BilinearGrey(const ImageView8& image, double u, double v) {
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

std::optional<EdgePoint> MeasureEdgePoint(const ImageView8& image, const Eigen::Vector2d& q,
                                          const Eigen::Vector2d& n, double half_window_px) {
  if (!InsideForBilinearGrey(image, q + (half_window_px + 1.0) * n) ||
      !InsideForBilinearGrey(image, q - (half_window_px + 1.0) * n)) {
    return std::nullopt;
  }
  const double step = 0.5;  // profile step, px: finer gains nothing after bilinear sampling
  constexpr int kMaxSamples = 24;
  double g_max = 0.0;
  std::array<double, kMaxSamples> g;
  std::array<double, kMaxSamples> s;
  // The grey level half a step before each sample: the one half a step after it is the
  // next sample's (the profile's steps are equal), so each is read once.
  const Eigen::Vector2d p_first = q + (-half_window_px - 0.5 * step) * n;
  double before = BilinearGrey(image, p_first.x(), p_first.y());
  int m = 0;
  for (double o = -half_window_px; o <= half_window_px + 1e-9 && m < kMaxSamples; o += step, ++m) {
    const Eigen::Vector2d p1 = q + (o + 0.5 * step) * n;
    const double after = BilinearGrey(image, p1.x(), p1.y());
    g[m] = after - before;
    before = after;
    s[m] = o;
    g_max = std::max(g_max, g[m]);
  }
  if (g_max <= 0.0) return std::nullopt;
  // Gradients under a quarter of the peak are noise or the tail of another edge.
  const double floor = 0.25 * g_max;
  double sw = 0.0;
  double sws = 0.0;
  // Without a branch (which half the samples take, at random): a sample at or under the
  // floor adds a weight of +0, which leaves both sums as they are.
  for (int j = 0; j < m; ++j) {
    const double w = std::max(g[j] - floor, 0.0);
    sw += w;
    sws += w * s[j];
  }
  if (sw <= 0.0) return std::nullopt;
  return EdgePoint{q + (sws / sw) * n, g_max};
}

std::optional<Line2d> FitWeightedLine(std::span<const EdgePoint> points,
                                      const Eigen::Vector2d& towards) {
  if (points.size() < 2) return std::nullopt;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  double wsum = 0.0;
  for (const EdgePoint& p : points) {
    mean += p.weight * p.uv_px;
    wsum += p.weight;
  }
  if (!(wsum > 0.0)) return std::nullopt;
  mean /= wsum;
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (const EdgePoint& p : points) {
    const Eigen::Vector2d r = p.uv_px - mean;
    cov += p.weight * r * r.transpose();
  }
  // The principal axis of a 2 x 2 covariance, in closed form.
  const double angle = 0.5 * std::atan2(2.0 * cov(0, 1), cov(0, 0) - cov(1, 1));
  Eigen::Vector2d axis(std::cos(angle), std::sin(angle));
  if (axis.dot(towards) < 0.0) axis = -axis;
  return Line2d{mean, axis};
}

std::optional<Eigen::Vector2d> IntersectLines(const Line2d& a, const Line2d& b) {
  const double denom = a.dir.x() * b.dir.y() - a.dir.y() * b.dir.x();
  // Lines within ~3 degrees of parallel do not define a corner.
  constexpr double kMinSin = 0.05;
  if (std::abs(denom) < kMinSin) return std::nullopt;
  const Eigen::Vector2d w = b.point - a.point;
  const double t = (w.x() * b.dir.y() - w.y() * b.dir.x()) / denom;
  return a.point + t * a.dir;
}

}  // namespace linecal

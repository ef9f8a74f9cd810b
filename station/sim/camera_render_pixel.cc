#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>

#include "station/sim/camera_render_internal.h"

namespace linecal::camera_render_internal {

// ------------------------------------------------------------------------------------------
// Integrating one pixel.
//
// Pixel-local coordinates (s, t) in [0, 1]^2 run along u and v; the ray at (s, t) is the
// bilinear blend of the four corner rays. A cell (the pixel or a quarter of it, ...) is
// probed on its boundary; no change of label around it (and its centre agreeing) means
// one look; exactly two changes mean one boundary curve between two looks, which is
// located by bisection at its two ends and its middle and integrated as a parabolic arc
// (exact for straight edges; circles of radius R px are off by ~L^4/R^3 of a pixel), after
// two more probes confirm the arc. Anything else splits the cell into quarters.

double PixelIntegrator::Integrate(const std::array<CornerSample*, 4>& c,
                                  const std::uint32_t* candidates, int n) {
  for (int k = 0; k < 4; ++k) rays_[k] = &c[k]->ray;
  candidates_ = candidates;
  n_candidates_ = n;
  front_ = FrontSurface(c);
  if (front_ != nullptr) {
    for (int k = 0; k < 4; ++k) {
      q_[k] = c[k]->hit.p_surface;
      inverse_t_[k] = 1.0 / c[k]->hit.t;
    }
  }
  // Loop order: top-left, top-right, bottom-right, bottom-left.
  return Cell(Eigen::Vector2d::Zero(), 1.0, 0,
              {c[0]->hit.look, c[1]->hit.look, c[3]->hit.look, c[2]->hit.look});
}

const SceneSurface* PixelIntegrator::FrontSurface(const std::array<CornerSample*, 4>& c) const {
  if (!InFrontOverPixel(scene_, c, candidates_, n_candidates_)) return nullptr;
  return &scene_.surfaces()[c[0]->hit.surface];
}

Look PixelIntegrator::Eval(const Eigen::Vector2d& st) const {
  const double s = st.x(), t = st.y();
  const std::array<double, 4> w = {(1 - s) * (1 - t), s * (1 - t), (1 - s) * t, s * t};
  if (front_ != nullptr) {
    // Where the blended ray meets the front surface: the corners' hits blended with
    // weights w / depth (perspective-correct), no ray-plane intersection needed.
    Eigen::Vector2d p = Eigen::Vector2d::Zero();
    double total = 0.0;
    for (int k = 0; k < 4; ++k) {
      p += w[k] * inverse_t_[k] * q_[k];
      total += w[k] * inverse_t_[k];
    }
    p /= total;
    if (std::abs(p.x()) <= front_->half_size_m.x() && std::abs(p.y()) <= front_->half_size_m.y()) {
      if (const std::optional<Look> look = scene_.LookAt(*front_, p)) return *look;
    }
  }
  const Eigen::Vector3d d =
      w[0] * *rays_[0] + w[1] * *rays_[1] + w[2] * *rays_[2] + w[3] * *rays_[3];
  return scene_.Trace(d, candidates_, n_candidates_).look;
}

Eigen::Vector2d PixelIntegrator::LoopPoint(const Eigen::Vector2d& origin, double size, int per_side,
                                           int k) {
  const int side = k / per_side;
  const double f = size * (k % per_side) / per_side;
  switch (side) {
    case 0:
      return origin + Eigen::Vector2d(f, 0);
    case 1:
      return origin + Eigen::Vector2d(size, f);
    case 2:
      return origin + Eigen::Vector2d(size - f, size);
    default:
      return origin + Eigen::Vector2d(0, size - f);
  }
}

bool PixelIntegrator::Bisect(Eigen::Vector2d a, std::uint64_t la, Eigen::Vector2d b,
                             std::uint64_t lb, Eigen::Vector2d* crossing) const {
  while ((b - a).norm() > tolerance_) {
    const Eigen::Vector2d m = 0.5 * (a + b);
    const std::uint64_t lm = Eval(m).label;
    if (lm == la) {
      a = m;
    } else if (lm == lb) {
      b = m;
    } else {
      return false;
    }
  }
  *crossing = 0.5 * (a + b);
  return true;
}

double PixelIntegrator::Cell(const Eigen::Vector2d& origin, double size, int depth,
                             const std::array<Look, 4>& corners) {
  const int per_side = std::max(kMinEdgeProbes, probes_ >> depth);
  const int n = 4 * per_side;
  std::array<Look, kMaxLoop> loop;
  for (int k = 0; k < n; ++k) {
    loop[k] =
        k % per_side == 0 ? corners[k / per_side] : Eval(LoopPoint(origin, size, per_side, k));
  }
  std::array<int, 3> changes;
  int n_changes = 0;
  for (int k = 0; k < n && n_changes < 3; ++k) {
    if (loop[k].label != loop[(k + 1) % n].label) changes[n_changes++] = k;
  }
  const double area = size * size;
  const Eigen::Vector2d centre = origin + Eigen::Vector2d::Constant(0.5 * size);
  if (n_changes == 0) {
    const Look c = Eval(centre);
    if (c.label == loop[0].label) return area * c.reflectance;
  } else if (n_changes == 2) {
    double value;
    if (Arc(origin, size, per_side, loop, changes[0], changes[1], &value)) return value;
  }
  if (depth == max_depth_) {
    // Smallest cell: the mean of its probes and its centre.
    double sum = Eval(centre).reflectance;
    for (int k = 0; k < n; ++k) sum += loop[k].reflectance;
    return area * sum / (n + 1);
  }
  const double half = 0.5 * size;
  const Look top = Eval(origin + Eigen::Vector2d(half, 0));
  const Look right = Eval(origin + Eigen::Vector2d(size, half));
  const Look bottom = Eval(origin + Eigen::Vector2d(half, size));
  const Look left = Eval(origin + Eigen::Vector2d(0, half));
  const Look mid = Eval(centre);
  return Cell(origin, half, depth + 1, {corners[0], top, mid, left}) +
         Cell(origin + Eigen::Vector2d(half, 0), half, depth + 1, {top, corners[1], right, mid}) +
         Cell(origin + Eigen::Vector2d(half, half), half, depth + 1,
              {mid, right, corners[2], bottom}) +
         Cell(origin + Eigen::Vector2d(0, half), half, depth + 1, {left, mid, bottom, corners[3]});
}

bool PixelIntegrator::Arc(const Eigen::Vector2d& origin, double size, int per_side,
                          const std::array<Look, kMaxLoop>& loop, int k1, int k2,
                          double* value) const {
  const int n = 4 * per_side;
  const Look& a = loop[(k2 + 1) % n];  // the arc k2+1 .. k1
  const Look& b = loop[(k1 + 1) % n];  // the arc k1+1 .. k2
  const auto point = [&](int k) { return LoopPoint(origin, size, per_side, k % n); };
  Eigen::Vector2d p, q;
  if (!Bisect(point(k1), a.label, point(k1 + 1), b.label, &p) ||
      !Bisect(point(k2), b.label, point(k2 + 1), a.label, &q)) {
    return false;
  }
  // The part of the cell on A's side of the chord p-q: q, the cell corners on A's arc,
  // p. It runs in the loop's positive sense, so A lies left of p -> q.
  std::array<Eigen::Vector2d, 6> polygon;
  int m = 0;
  polygon[m++] = q;
  for (int k = k2 + 1; k <= k2 + n; ++k) {
    const int kk = k % n;
    if (kk == (k1 + 1) % n) break;
    if (kk % per_side == 0) polygon[m++] = point(kk);
  }
  polygon[m++] = p;
  double twice_area_a = 0.0;
  for (int i = 0; i < m; ++i) {
    const Eigen::Vector2d& u = polygon[i];
    const Eigen::Vector2d& w = polygon[(i + 1) % m];
    twice_area_a += u.x() * w.y() - u.y() * w.x();
  }
  const Eigen::Vector2d chord = q - p;
  const double length = chord.norm();
  if (!(length > 0.0)) return false;
  const Eigen::Vector2d normal = Eigen::Vector2d(-chord.y(), chord.x()) / length;  // to A
  // The arc's offset from the chord at its middle, searched a quarter chord either side:
  // a bulge beyond that is a corner, not an arc.
  const Eigen::Vector2d middle = 0.5 * (p + q);
  const double reach = 0.25 * length + tolerance_;
  const Eigen::Vector2d on_a = middle + reach * normal, on_b = middle - reach * normal;
  if (Eval(on_a).label != a.label || Eval(on_b).label != b.label) return false;
  Eigen::Vector2d x;
  if (!Bisect(on_b, b.label, on_a, a.label, &x)) return false;
  const double offset = (x - middle).dot(normal);  // > 0: B bulges into A's side
  // Confirm a parabola through p, x and q at a quarter and three quarters of the chord
  // (offset 3/4 of the middle's), to twice the bisection tolerance.
  const double slack = 2.0 * tolerance_;
  for (const double f : {0.25, 0.75}) {
    const Eigen::Vector2d c = p + f * chord + 0.75 * offset * normal;
    if (Eval(c + slack * normal).label != a.label || Eval(c - slack * normal).label != b.label) {
      return false;
    }
  }
  // The segment between a parabolic arc and its chord has 2/3 of the area of the
  // enclosing parallelogram.
  const double area = size * size;
  const double area_a = std::clamp(0.5 * twice_area_a - 2.0 / 3.0 * length * offset, 0.0, area);
  *value = area_a * a.reflectance + (area - area_a) * b.reflectance;
  return true;
}

}  // namespace linecal::camera_render_internal

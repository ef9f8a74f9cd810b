#pragma once
// Ellipses in the image: direct least-squares fits to edge points, conversion between the
// conic matrix and the geometric parameters, the ellipse of a blob's second moments, the
// image of a plane circle under a homography, and the distance of a point to an ellipse.
//
// Conic convention: a symmetric 3x3 matrix C with [x; 1]^T C [x; 1] = 0 on the curve, i.e.
//   C = [[a, b/2, d/2], [b/2, c, e/2], [d/2, e/2, f]] for a x^2 + b xy + c y^2 + d x + e y + f.
// Coordinates are image pixels (pixel-centre convention) unless a function says otherwise;
// nothing here depends on the unit.

#include <Eigen/Core>
#include <optional>
#include <span>

namespace linecal {

struct Ellipse {
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  double semi_major = 0.0;  // >= semi_minor > 0
  double semi_minor = 0.0;
  // Direction of the major axis: radians from +x towards +y (in the image: from +u towards
  // +v, i.e. clockwise as seen on screen), in (-pi/2, pi/2].
  double angle_rad = 0.0;

  // The conic matrix of the ellipse, scaled so that it is -1 at the centre:
  // [x; 1]^T C [x; 1] is < 0 inside, 0 on the curve, > 0 outside. O(1).
  Eigen::Matrix3d Conic() const;
  // The point at parameter t: centre + R(angle) * (a cos t, b sin t). O(1).
  Eigen::Vector2d PointAt(double t) const;
};

// The ellipse of a conic matrix (any scale or sign). nullopt when the conic is not a real,
// non-degenerate ellipse (a hyperbola, parabola, imaginary ellipse, point, or non-finite
// coefficients). O(1).
std::optional<Ellipse> EllipseFromConic(const Eigen::Matrix3d& conic);

// The direct least-squares ellipse fit (Fitzgibbon, Pilu and Fisher 1999, in the numerically
// stable form of Halir and Flusser 1998) of points that lie near an ellipse: minimises the
// algebraic distance under the constraint 4ac - b^2 = 1, so the result is always an ellipse
// when one exists. The points are centred and scaled before the fit (the result does not
// depend on the image position or size). Weights, when given, multiply each point's
// algebraic residual (same size as points, >= 0). Needs >= 5 points not on one line; returns
// nullopt for fewer, for non-finite input or when no ellipse results. The spans are only
// read. Cost: O(n) plus a 3x3 eigenproblem; about 1 microsecond per 50 points.
std::optional<Ellipse> FitEllipse(std::span<const Eigen::Vector2d> points,
                                  std::span<const double> weights = {});

// The ellipse with the same area, centroid and second moments as a filled region: for a
// uniform filled ellipse of semi-axes a, b the covariance has eigenvalues a^2/4 and b^2/4.
// `covariance` is the region's second central moments divided by its area. nullopt when the
// covariance is not positive definite or not finite. O(1).
std::optional<Ellipse> EllipseFromMoments(const Eigen::Vector2d& centroid,
                                          const Eigen::Matrix2d& covariance);

// The first-order (Sampson) distance of p from the conic: |q(p)| / |grad q(p)|, q the
// quadratic form of the conic. It equals the Euclidean distance to first order: for a
// circle of radius r it is |d^2 - r^2| / (2 d) for a point at distance d from the centre.
// Infinity where the gradient vanishes (the centre). O(1).
double SampsonDistance(const Eigen::Matrix3d& conic, const Eigen::Vector2d& p);

// The image of the circle |p - centre| = radius of the source plane under the homography
// H ([x_dst; 1] ~ H [x_src; 1], homography.h): the conic H^-T C H^-1, scaled to unit
// Frobenius norm. Under perspective its ellipse's centre is NOT H * centre; the difference
// is what a circle detector must correct. The caller checks the result with
// EllipseFromConic (a circle that crosses the source plane's vanishing line does not image
// to an ellipse). H must be invertible. O(1).
Eigen::Matrix3d ImageOfCircle(const Eigen::Matrix3d& H, const Eigen::Vector2d& centre,
                              double radius);

}  // namespace linecal

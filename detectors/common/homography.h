#pragma once
// Plane-to-plane homographies: the map from a board's plane to the image (or between any two
// planes), fitted from point pairs, applied, and checked by its residuals.
//
// Convention: H maps a source point p_src (2-D, any unit) to a destination point p_dst as
// [p_dst; 1] ~ H * [p_src; 1]. For a board seen by a camera, src is the board frame (metres)
// and dst is the image (pixels, pixel-centre convention), so the fitted matrix is
// H_image_board and residuals are in pixels.
//
// Fitting: a normalised DLT (Hartley: both point sets shifted to their centroid and scaled
// to a mean distance of sqrt(2)), then, when asked, Levenberg-Marquardt on the destination
// (one-sided) reprojection error, which is the maximum-likelihood fit when the source points
// are exact (board coordinates) and only the image points are noisy.

#include <Eigen/Core>
#include <optional>
#include <span>
#include <vector>

namespace linecal {

struct HomographyFitOptions {
  // Refine the DLT estimate by minimising the destination reprojection error. The DLT alone
  // minimises an algebraic error; with noisy image points refinement lowers the residual.
  bool refine = true;
  // Upper bound on Levenberg-Marquardt iterations; a homography from a good DLT start
  // converges in 2-5, so 20 only bounds the cost of a pathological input.
  int max_iterations = 20;
};

struct HomographyFit {
  // [p_dst; 1] ~ H * [p_src; 1]; scaled to unit Frobenius norm with H(2, 2) >= 0.
  Eigen::Matrix3d H = Eigen::Matrix3d::Identity();
  double rms_residual = 0.0;  // root mean square of |Apply(H, src_i) - dst_i|, dst units
  double max_residual = 0.0;  // largest |Apply(H, src_i) - dst_i|, dst units
};

// Fits H from n >= 4 pairs src[i] -> dst[i]. Returns nullopt when the sizes differ, n < 4,
// a coordinate is not finite, the configuration is degenerate (three or more of every four
// points collinear, or all points on one line or at one point on either side), or the
// result maps a source point to infinity. The inputs are only read (no ownership).
// Cost: O(n) plus a 9x9 eigen decomposition; refinement adds O(n) per iteration
// (about 10 microseconds for 50 points).
std::optional<HomographyFit> FitHomography(std::span<const Eigen::Vector2d> src,
                                           std::span<const Eigen::Vector2d> dst,
                                           const HomographyFitOptions& options = {});

// The image of p under H: the dehomogenised H * [p; 1]. Returns (NaN, NaN) when p maps to
// the line at infinity (|w| below 1e-12 of the scale of H times the point). O(1).
Eigen::Vector2d ApplyHomography(const Eigen::Matrix3d& H, const Eigen::Vector2d& p);

// |ApplyHomography(H, src[i]) - dst[i]| for every i, in dst units, into *residuals (resized
// to n; a point mapped to infinity gives +infinity). Returns the RMS of the residuals (0 for
// n = 0; +infinity if any is infinite). The spans must have the same size. O(n).
double HomographyResiduals(const Eigen::Matrix3d& H, std::span<const Eigen::Vector2d> src,
                           std::span<const Eigen::Vector2d> dst, std::vector<double>* residuals);

// The side, in dst units, of the image of a square of side side_src at p_src: the square
// root of the area of the parallelogram that H maps the two steps of side_src from p_src to
// (a local scale under perspective). NaN when a step maps to infinity. O(1).
double LocalSquareSide(const Eigen::Matrix3d& H, const Eigen::Vector2d& p_src, double side_src);

}  // namespace linecal

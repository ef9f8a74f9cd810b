#pragma once
// Sub-pixel refinement of corners of printed patterns.
//
// X-corner (saddle) fit: two black squares touching at a vertex, seen through any affine
// map and blurred by a symmetric point spread, form an image that is point-symmetric about
// the vertex, so the vertex is a saddle point of the blurred image. The fit models the
// blurred image over a window centred on the current estimate by a quadratic
//   f(x, y) = a x^2 + b x y + c y^2 + d x + e y + g
// (least squares), moves to its stationary point and repeats with the window re-centred
// (bilinear samples), until the step is tiny. With the window centred on the vertex the odd
// terms vanish by symmetry, so the fixed point is the vertex whatever the window size.

#include <Eigen/Core>
#include <optional>

#include "detectors/common/image_filters.h"

namespace linecal {

struct SaddleFitOptions {
  // Window half-size in pixels: (2 half_window + 1)^2 samples. Larger averages more noise
  // but must stay inside the four squares around the vertex (below about a third of the
  // smallest square side seen). 1..15.
  int half_window = 3;
  // Iterations of re-centring; from a start within a pixel the step falls below
  // `converged_px` in 2-4.
  int max_iterations = 8;
  double converged_px = 0.005;
};

// The refined X-corner near `start_px` in `blurred` (an image already smoothed, e.g. by
// GaussianBlur with sigma about half_window / 2, so that the vertex is a smooth saddle).
// Returns nullopt when the fitted quadratic is not a saddle (no X-corner there), the
// estimate leaves the window around start_px, the window leaves the image, or half_window
// is outside 1..15.
// Cost: O(half_window^2) per iteration.
std::optional<Eigen::Vector2d> RefineSaddle(const ImageF& blurred, const Eigen::Vector2d& start_px,
                                            const SaddleFitOptions& options = {});

// The X-corner near start_px (pixels of the 8-bit `image`, which must be valid) refined by
// RefineSaddle on a patch of the image blurred by blur_sigma_px (0.5..4), with a window of
// a third of side_px, the local square side (2..7 px: below a third it stays inside the
// four squares; beyond 7 px the saddle of a 1.5 px blur is flat and more pixels add
// nothing). The patch keeps the blur's clamped border out of the window's reach, so the
// result equals RefineSaddle on the whole image blurred alike; blurring the patch alone
// costs far less. nullopt when the patch leaves the image, the fit fails, or it ends more
// than a pixel from start_px. Cost: O((half_window + 3 sigma)^2 * sigma) for the blur.
std::optional<Eigen::Vector2d> RefineXCornerOnPatch(const ImageView8& image,
                                                    const Eigen::Vector2d& start_px, double side_px,
                                                    double blur_sigma_px);

}  // namespace linecal

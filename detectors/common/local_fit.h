#pragma once
// Local models of a grid of printed features seen through a real lens: a feature's image
// position predicted from its neighbours by a low-order polynomial in board coordinates. Over a
// few neighbours a quadratic follows perspective and the bending of a lens alike (a fisheye
// bends a board's edge by a fifth of a square over three squares, which a homography
// extrapolated to the block's edge cannot follow), so the grid detectors judge each feature
// against its neighbourhood instead of one homography of the whole board.

#include <Eigen/Core>
#include <optional>
#include <span>

namespace linecal {

// The image position at board offset (0, 0) of the least-squares quadratic through the
// samples: each image coordinate modelled as a + b x + c y + d xy (+ e x^2 when quad_x, + f y^2
// when quad_y) of the sample's board offset (x, y) from the predicted point (any unit); the
// prediction is a. quad_x / quad_y false leave out the square term of an axis along which
// the samples take two values only. The spans must have the same size. nullopt when the
// samples do not determine the model (too few, or degenerate). O(n).
std::optional<Eigen::Vector2d> PredictQuadraticAtOrigin(std::span<const Eigen::Vector2d> offsets,
                                                        std::span<const Eigen::Vector2d> uv,
                                                        bool quad_x, bool quad_y);

}  // namespace linecal

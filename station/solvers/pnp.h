#pragma once
// Perspective-n-point: the pose of a known object (a board, or several boards in one frame)
// from its points' images, for any CameraModel (pinhole with distortion, or fisheye).
//
// Method. The observed pixels are unprojected to rays and turned into a virtual pinhole
// camera looking along their mean direction, so that wide fisheye views keep well-conditioned
// normalised coordinates. A closed-form start follows: for planar objects the object-plane
// to image homography, decomposed into [r1 r2 t] and made a rotation by SVD (exact for noise-
// free data, no flips when seen face-on); for non-planar objects a normalised DLT of the 3x4
// projection, its left 3x3 made a rotation by SVD. Ceres then refines rotation and
// translation together on the reprojection error through the full camera model, with a Huber
// loss; the rotation is optimised as a small rotation vector on the start, so there is no
// quaternion parameterisation to get wrong.
//
// Uncertainty: the 6x6 covariance of (rotation vector δθ, translation δt), both in the camera
// frame, meaning R_camera_object = exp(δθ) R̂ and t = t̂ + δt, is σ² (JᵀJ)⁻¹ with J the
// reprojection Jacobian at the solution and σ the feature noise: options.feature_sigma_px
// when given, else estimated from the residuals (Σ r² / (2n - 6)).
//
// Several boards of different detectors (feature_sigma_px = 0 and the points' `board` or
// `noise_class` not all equal): one σ from every residual would charge a checker's corners
// (0.007 px) with a marker's error (0.07 px), and a board's error that no pose change of the
// board could cause (a marker corner's pattern) does not move the pose. So each noise class c
// gets its own σ_c from the part of its boards' residuals a pose change of the board explains:
// with J_b, r_b a board's Jacobian and residuals, g_b = J_bᵀ r_b and A = (JᵀJ)⁻¹,
//   σ_c² = Σ_{b in c} g_bᵀ (J_bᵀJ_b)⁺ g_b / Σ_{b in c} (rank(J_bᵀJ_b) − tr(A J_bᵀJ_b)),
// unbiased when every board's error moves its pose as independent noise of σ_c would (the
// expectation of a numerator term under one σ is σ² times its denominator term); pooling a
// class's boards steadies it (one board alone has at most 6 degrees of freedom, fewer the more
// it fixes the pose). The covariance is the sandwich A (Σ_b σ_c(b)² J_bᵀJ_b) A. A class with
// under 8 degrees of freedom (one board; σ_c² then about ±50% or worse) takes the larger of
// σ_c and the σ from every residual, so an unsteady class never reports less than one σ would;
// except a class of marker corners (the points' `marker`) with enough markers, below.
//
// Markers. A marker's corners share its detector error: a shift, which moves the pose as noise
// at the marker would, and a size and shape error (most of a corner's error), which barely does
// (the corners' moves cancel), while it inflates every residual's σ. So a class under 8 degrees
// of freedom whose points are all marker corners, with n_m corners of marker m, r̄_m and J̄_m
// their mean residual and Jacobian, counts its markers' shifts' degrees of freedom,
//   d = Σ_m (2 − n_m tr(A J̄_mᵀJ̄_m))   (two a marker: about 70 for a floor grid of 36 tags),
// and from d = 48 up (about 25 markers; a 6 x 6 middle needs 8 for each of its directions) its
// markers give its share of the sandwich's middle directly, each marker
// its own error (a cluster-robust sandwich, one cluster a marker): with g_m = Σ_{i∈m} J_iᵀ r_i,
//   (2 M / d) Σ_m g_m g_mᵀ   in place of σ_c² Σ_b J_bᵀJ_b   (M markers),
// the factor undoing the part of the residuals the fit took. It holds what a scalar σ cannot:
// far tags noisier than near ones, shifts larger along one image axis (docs/solvers.md,
// "Marker classes"). Such a class's σ in `sigma_px` is its markers' shift σ,
// (Σ_m n_m |r̄_m|² / d)^½. A steady class keeps σ_c.
//
// Outcomes (not errors): too few points, collinear points, no closed-form start, not
// converged — each a reason code for verdicts. Errors: InvalidArgument for non-finite input
// or invalid options.

#include <Eigen/Core>
#include <span>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "detectors/core/pose.h"
#include "station/camera/camera_model.h"

namespace linecal {

struct PnpCorrespondence {
  Eigen::Vector3d p_object = Eigen::Vector3d::Zero();  // metres, in the object's frame
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();     // observed, pixel-centre convention
  // For the covariance from the residuals (see the top of this file): the board the point is
  // on, and its noise class (points of one detector share a σ); any integers.
  int board = 0;
  int noise_class = 0;
  // The marker (ArUco, AprilTag) whose corner the point is, unique within its board; -1 for a
  // feature of its own. A marker's corners share the detector's error of that marker.
  int marker = -1;
};

enum class PnpOutcome {
  kOk,
  kTooFewPoints,  // planar objects need 4 points, non-planar ones 6
  kCollinear,     // the object points lie on a line (or at one point): no pose
  kNoStart,       // the closed-form start failed (rays outside the lens, degenerate image)
  kNotConverged,  // Ceres stopped without converging
};

// "", "too_few_features", "collinear_features", "no_initial_pose", "did_not_converge": the
// reason codes of results (docs/interfaces.md).
const char* PnpOutcomeName(PnpOutcome outcome);

struct PnpOptions {
  // Huber loss scale, pixels: residuals below it count in full (a good detector's noise is a
  // tenth of a pixel), larger ones linearly, so one wrong feature cannot pull the pose. (0, 100].
  double huber_px = 1.0;
  // Feature noise for the covariance, pixels; 0: estimate it from the residuals. [0, 100].
  double feature_sigma_px = 0.0;
  // Ceres iterations; from the closed-form start the solve converges in 3-6. [1, 1000].
  int max_iterations = 100;

  // Empty when valid, else the name of the first field out of range.
  std::string_view Validate() const;
};

struct PnpResult {
  PnpOutcome outcome = PnpOutcome::kNoStart;
  Rigid3d T_camera_object;  // p_camera = T_camera_object * p_object
  bool planar = false;      // the object points lie on a plane (homography start)
  int points = 0;
  // RMS of the residual lengths, without the robust loss; +infinity (and outcome
  // kNotConverged) when the pose leaves a point outside the lens.
  double residual_rms_px = 0.0;
  double max_residual_px = 0.0;
  // The feature noise the covariance uses; with several noise classes, the RMS over the
  // points of their class's σ.
  double sigma_px = 0.0;
  // (δθ [rad], δt [m]), camera frame; see the top of this file.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
};

// Solves for T_camera_object. The spans are only read. Cost: about 0.1 ms for 20 points,
// 1 ms for 150 (one Ceres solve, dense QR); allocates O(n).
absl::StatusOr<PnpResult> SolvePnp(const CameraModel& camera,
                                   std::span<const PnpCorrespondence> points,
                                   const PnpOptions& options = {});

// True when a board's printed face (its +z, docs/boards.md) is turned towards the camera, i.e.
// the camera is on the print's side of the board plane. A board "seen from behind" is a
// mis-identified or mirrored board, never a real view of the print. O(1).
bool BoardFacesCamera(const Rigid3d& T_camera_board);

// Reprojection residuals |project(T * p_object) - uv_px| in pixels, one per point; +infinity
// for a point the camera cannot project. O(n).
std::vector<double> ReprojectionErrors(const CameraModel& camera, const Rigid3d& T_camera_object,
                                       std::span<const PnpCorrespondence> points);

}  // namespace linecal

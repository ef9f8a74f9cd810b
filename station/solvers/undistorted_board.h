#pragma once
// A detected board checked and located through a known camera model (`linecal detect
// --intrinsics`, docs/interfaces.md). The detectors judge a board in raw pixels, where a real
// lens bends it by pixels to tens of pixels; through the camera model the board's features
// lie on one plane again, so one homography must fit them to the detector's noise.
//
// Method: every feature's pixel is unprojected to a ray; the rays are turned into a virtual
// pinhole camera looking along their mean direction (as SolvePnp does, so that a fisheye's
// wide views keep well-conditioned coordinates), with the camera's mean focal length, i.e. in
// undistorted pixels. A homography board plane -> undistorted pixels is fitted there
// (FitHomography, refined). Its residuals are measured in raw pixels: each feature's board
// point through the homography, back to a ray, projected by the camera model, against the
// detected pixel. When their RMS is within the bound, SolvePnp gives the board's pose.
//
// Frames and units: p_board in metres on the board plane z = 0 (docs/boards.md); pixels as in
// docs/conventions.md; T_camera_board maps board points into the camera frame.

#include <span>

#include "absl/status/statusor.h"
#include "detectors/detection.h"
#include "station/camera/camera_model.h"
#include "station/solvers/pnp.h"

namespace linecal {

struct UndistortedBoardOptions {
  // Largest RMS of the homography's residuals, raw pixels, for a board to be taken. A right
  // camera model leaves the detector's noise, a tenth of a pixel on renders and a few tenths
  // on real photos; a wrong one (the wrong sign of k1 -0.3 measures 3.5 px on a board filling
  // half the image, tests/tools/cmd_detect_test.cc) or a shifted correspondence (a whole
  // square) leaves pixels. (0, 100].
  double max_homography_rms_px = 1.0;
  PnpOptions pnp;

  // OK, or InvalidArgument naming the first field out of range.
  absl::Status Validate() const;
};

struct UndistortedBoard {
  // The homography fitted within the bound, and the pose solved.
  bool verified = false;
  int points = 0;
  // RMS and largest homography residual, raw pixels; +infinity when no homography could be
  // fitted (fewer than 4 features, a feature without a ray, a degenerate configuration).
  double homography_rms_px = 0.0;
  double homography_max_px = 0.0;
  // SolvePnp's result when verified (outcome kNoStart otherwise).
  PnpResult pose;
};

// Checks `features` (a detection's, raw pixels, only read) through `camera`. An unverified
// board is an outcome, not an error; errors: InvalidArgument for invalid options or SolvePnp's
// own. Cost: one unprojection per feature and a homography fit (tens of microseconds for 50
// features), then SolvePnp's (pnp.h: 0.1 ms for 20 points, 1 ms for 150); allocates O(n).
absl::StatusOr<UndistortedBoard> CheckBoardUndistorted(const CameraModel& camera,
                                                       std::span<const DetectedFeature> features,
                                                       const UndistortedBoardOptions& options = {});

}  // namespace linecal

#pragma once
// What the after-sale calibration draws over the camera's image (docs/aftersale.md): the
// ground grid and the horizon of the estimated pose, and each lane line through its points to
// the vanishing point, all as polylines in the image as stored (distorted pixels, centre of
// the top-left pixel at (0, 0)). `linecal aftersale --out` rasterises them into the overlay
// PNG; the console's after-sale page draws them over the photo. One implementation, so both
// show the same lines.

#include <Eigen/Core>
#include <optional>
#include <vector>

#include "detectors/core/image_view.h"
#include "station/camera/camera_model.h"
#include "station/io/image_io.h"
#include "station/solvers/lane_calibration.h"

namespace linecal {

// Distorted pixels; nullopt where the line leaves the image or the camera's view (a gap).
using ImagePolyline = std::vector<std::optional<Eigen::Vector2d>>;

struct LaneOverlayOptions {
  // Straight segments a line is cut into: enough for the lens's curvature to look smooth.
  // 200 for a full-resolution PNG; a page redrawn as points move can take fewer. [1, 10000].
  int segments = 200;
};

struct LaneOverlay {
  // Every 5 m from 5 to 50 m ahead of the camera (across, from 5 m left to 5 m right), then
  // every metre from 5 m left to 5 m right (along, from 2 to 50 m ahead), in the car frame
  // around the camera's footprint; only where the ground is in the image.
  std::vector<ImagePolyline> ground_grid;
  // The images of ground directions at infinity, every degree from 60 left to 60 right.
  ImagePolyline horizon;
  // Per lane line: from its point farthest from the vanishing point to the vanishing point,
  // straight in the undistorted image and bent through the lens.
  std::vector<ImagePolyline> lane_lines;
  // The vanishing point as a distorted pixel, when the lens has one for it.
  std::optional<Eigen::Vector2d> vanishing_point_uv;
};

// The overlay of `result` for `camera` (the intrinsics of `input`). O(segments x 23 lines).
LaneOverlay LaneOverlayOf(const CameraModel& camera, const LaneCalibrationInput& input,
                          const LaneCalibrationResult& result,
                          const LaneOverlayOptions& options = {});

// The undistorted pixel q (image of K) as a distorted one; false when the lens has none.
bool DistortedPixelOf(const CameraModel& camera, const Eigen::Vector2d& q, Eigen::Vector2d* uv);

// The bird's-eye view's page: the ground from `near_m` to `far_m` ahead of the camera and
// `half_width_m` to either side of its footprint, at `px_per_m`; forward up, left on the left
// (for a camera looking backward, the camera's forward and left). The defaults, 20 px/m over
// 3..43 m and +-8 m, show the lane and its neighbours on a 320 x 800 px page.
struct BirdsEyeLayout {
  double px_per_m = 20, near_m = 3, far_m = 43, half_width_m = 8;
  int width() const { return static_cast<int>(2 * half_width_m * px_per_m); }
  int height() const { return static_cast<int>((far_m - near_m) * px_per_m); }
};

// The ground seen from above through the estimate (`linecal aftersale --out`, its
// <name>-birdseye.png without the grid lines): each page pixel's ground point is taken through
// the ground homography (the estimated pose) and the lens into `image` (the camera's image as
// stored, the size of input.intrinsics) and sampled bilinearly; 0 where the ground point is
// behind the camera or outside the image. O(width x height of the page).
Image8 BirdsEyeImage(const Image8& image, const CameraModel& camera,
                     const LaneCalibrationInput& input, const LaneCalibrationResult& result,
                     const BirdsEyeLayout& layout = {});

// The colour of BirdsEyePicture's grid lines.
inline constexpr std::array<std::uint8_t, 3> kBirdsEyeGridColour = {0, 200, 255};

// <name>-birdseye.png of `linecal aftersale --out`, and the console's after-sale page's
// bird's-eye view: BirdsEyeImage in grey with grid lines (kBirdsEyeGridColour, one pixel wide)
// every 5 m ahead and every metre across. O(width x height of the page).
RgbImage BirdsEyePicture(const Image8& image, const CameraModel& camera,
                         const LaneCalibrationInput& input, const LaneCalibrationResult& result,
                         const BirdsEyeLayout& layout = {});

}  // namespace linecal

#pragma once
// A board's perspective view, resampled from a wide-angle camera image. The detectors find
// boards by straight lines and homographies; through a fisheye lens 60 degrees off axis a
// board is bent too far for that. A virtual pinhole camera at the same optical centre, looking
// straight at where the board is expected, sees it undistorted: its image is resampled from
// the raw one through the camera model, the board is detected in it, and every feature is
// mapped back to the raw image through the same model (exactly: a ray, then Project), so the
// solvers still work on raw pixels.
//
// Frames: the view frame has the camera's optical centre, z toward the expected board centre,
// x and y as close to the camera's as that allows. Units: pixels, metres.

#include <Eigen/Core>
#include <optional>

#include "absl/status/statusor.h"
#include "detectors/core/image_view.h"
#include "detectors/core/pose.h"
#include "detectors/detection.h"
#include "station/camera/camera_model.h"

namespace linecal {

struct BoardViewOptions {
  // Added around the page on every side, as a share of the page's larger side: the board's
  // true pose differs from the expected one by the mounting and aligner tolerances.
  double margin = 0.15;
  // The view's focal length is the raw image's finest local scale at the expected board
  // centre (pixels per radian), so that no detail is lost, times this. Sampling 1.5 times
  // finer than the raw image keeps the bilinear resampling from blurring corners: on the
  // reference station's fisheye renders it halves the checker corners' error against 1.0
  // (tests/station/camera/board_view_test.cc prints them), and 2.0 gains nothing more.
  double scale = 1.5;
  // The board's smallest printed square or marker data cell (SmallestCellM, metres) and the
  // size in view pixels it is to have at least at the board's centre, foreshortened as the
  // expected pose turns it (0: no such bound). The detectors' windows and blurs are sized in
  // pixels for cells down to a size (docs/acceptance.md: 12 px squares, 4 px marker data
  // cells); a board facing the camera 67 degrees off the line of sight shows its squares
  // under half as wide as tall, and the raw image's finest scale can leave them too narrow
  // (surround_left's rear_left_board: 7.8 px at its centre, too_few_features). Interpolating
  // the raw pixels finer keeps what they hold. DetectInBoardView sets both from the board
  // for a second look when the first view does not show the board whole.
  double smallest_cell_m = 0;
  double min_cell_px = 0;
  // The view's larger side is at most this (pixels): a cap on time and memory when a board
  // is expected very close or turned far.
  int max_side_px = 3000;

  absl::Status Validate() const;
};

class BoardView {
 public:
  // Renders the view of the page (page_size_m, centred on the board origin in the board's
  // x-y plane) expected at T_camera_board. Pixels whose ray leaves the camera's valid region
  // or the raw image are mid-grey. InvalidArgument for bad options, an invalid raw view, or a
  // board not in front of the camera's valid region; the reason names what. Cost: one
  // projection and a bilinear sample per view pixel, about 30 ms for a 1000 x 800 view.
  static absl::StatusOr<BoardView> Render(const CameraModel& camera, const ImageView8& raw,
                                          const Rigid3d& T_camera_board,
                                          const Eigen::Vector2d& page_size_m,
                                          const BoardViewOptions& options = {});

  const Image8& image() const { return image_; }
  // The raw image pixel of a view pixel; nullopt when it falls outside the camera's valid
  // region. O(1) (one projection).
  std::optional<Eigen::Vector2d> ToRaw(const CameraModel& camera,
                                       const Eigen::Vector2d& uv_view_px) const;

 private:
  Image8 image_;
  double f_px_ = 1;
  Eigen::Vector2d c_px_ = Eigen::Vector2d::Zero();
  Eigen::Matrix3d R_camera_view_ = Eigen::Matrix3d::Identity();
};

// `board` detected (DetectBoard) in its view expected at T_camera_board, with every feature
// mapped back to raw pixels. When the board is not found whole, it is looked for once more in
// a view with options.smallest_cell_m and min_cell_px set from the board (its SmallestCellM at
// 12 px, or at 4 px for a board of markers: docs/acceptance.md's smallest sizes) when that
// view is finer, and that result is taken when it finds the board. nullopt when no view can be made
// (Render's errors), the board has no image detector, or a feature maps outside the camera's valid
// region; otherwise the detector's result, whatever its reason. Cost: Render plus the detector on
// the view.
std::optional<Detection> DetectInBoardView(const CameraModel& camera, const ImageView8& raw,
                                           const Rigid3d& T_camera_board, const Board& board,
                                           const BoardViewOptions& options = {});

}  // namespace linecal

#pragma once
// The station simulator's camera renderer: what one camera sees of a station layout, with
// exact ground truth (docs/simulator.md, "Camera renderer").
//
// Scene: every pixel sees the nearest of
//   - the boards of the layout: their printed paint (white or black reflectance on the
//     printed face, board_back_reflectance on the back); through holes and the area off
//     the page let the ray continue to whatever is behind;
//   - occluders placed for the frame (CameraRenderOptions::occluder_count), flat grey
//     rectangles facing the camera;
//   - the surfaces (walls) of the layout, grey at their reflectivity, with a procedural
//     clutter texture when CameraRenderOptions::clutter is on;
//   - the floor z = 0 of the station frame, grey at floor_reflectivity;
//   - else background_reflectance.
// Boards, walls and occluders are seen from both sides; nothing casts shadows.
//
// Geometry: the (W+1) x (H+1) pixel-corner rays come from CameraModel::Unproject (exact
// ones wherever an edge crosses a pixel), rays inside a pixel are blended bilinearly from
// its corners (exact for an undistorted pinhole, off by ~1/8 of the lens mapping's
// curvature otherwise: 5e-5 px for the reference front camera), and each pixel integrates
// the scene over its area: pixels of one surface and one paint are flat; the others (edge
// pixels) locate their edges by bisection and integrate them analytically as straight or
// parabolic arcs, splitting pixels with corners into quarters. Straight edges come out
// within ~2e-4 px of their projection (docs/simulator.md gives the measurements).
//
// Radiometry, in linear light: coverage-weighted reflectance x illumination x gradient x
// vignetting, then Gaussian blur, then gamma, Gaussian noise, JPEG-like block quantisation,
// and rounding to 8 or 16 bits.
//
// Frames and units: T_station_camera maps camera points (docs/conventions.md: x right, y down,
// z along the optical axis) into the station frame; metres; image coordinates as in
// camera_model.h (centre of the top-left pixel at (0, 0)).

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/core/pose.h"
#include "station/camera/camera_model.h"
#include "station/model/station_layout.h"

namespace linecal {

// How to render a frame. Plain data with defaults; Validate() before use (RenderCameraFrame
// does). Reflectances are linear, 0 = black, 1 = a perfect white diffuser.
struct CameraRenderOptions {
  // --- Anti-aliasing.
  // Points per pixel side probed for edges; a pixel whose probes, corners and centre all
  // see one paint of one surface counts as uniform, so details narrower than
  // 1 / edge_probes_per_side pixel that cross no probe can be missed. 2..64.
  int edge_probes_per_side = 8;
  // Edge crossings are located by bisection to this many pixels; it bounds the area error
  // of an edge pixel to about this fraction of a pixel. 1e-7..0.05.
  double edge_tolerance_px = 1e-4;
  // Pixels whose edges are not one smooth arc (corners, several edges, thin lines) are
  // split into 2 x 2 quarters, recursively, down to 2^-max_subdivision_depth pixel; the
  // smallest cells are point-sampled. 0..10.
  int max_subdivision_depth = 5;

  // --- Radiometry (linear light).
  double white_reflectance = 0.85;       // printed white (matte paper), [0, 1]
  double black_reflectance = 0.05;       // printed black (matte ink), [0, white_reflectance)
  double board_back_reflectance = 0.35;  // the unprinted back of a board, [0, 1]
  double background_reflectance = 0.2;   // rays that hit nothing, [0, 1]
  // Linear gain: a surface of reflectance r at the image centre without gradient and
  // vignetting gives r * illumination of full scale (values above full scale saturate).
  // (0, 100].
  double illumination = 1.0;
  // Illumination gradient: the ratio of brightest to darkest illumination across the
  // image, varying exponentially along a direction (1 = uniform). [1, 4].
  double illumination_gradient_ratio = 1.0;
  // The direction in which illumination increases, in degrees in the image: 0 = towards
  // +u (right), 90 = towards +v (down). Finite. The gradient is centred on the image
  // centre (factor 1 there) and spans the image's extent along the direction.
  double illumination_gradient_direction_deg = 0.0;
  // Vignetting: illumination falls as 1 - vignetting * (r / r_max)^2, r the distance from
  // the principal point and r_max the distance to the farthest image corner. [0, 1).
  double vignetting = 0.0;

  // --- Camera response.
  // Gaussian blur of the optics, sigma in pixels, applied in linear light. 0 = off. [0, 10].
  double blur_sigma_px = 0.0;
  // Encoding gamma: grey = full scale * linear^(1 / gamma); 1 = linear. [0.2, 5].
  double gamma = 1.0;
  // Gaussian noise added after gamma, sigma in 8-bit grey levels (16-bit output: times
  // 257). [0, 64].
  double noise_sigma = 0.0;
  // JPEG-like compression: 8 x 8 DCT blocks quantised with the standard luminance table
  // scaled to this quality (IJG scaling), then decoded. 0 = off, else [80, 100].
  int jpeg_quality = 0;
  // Output bits per pixel: 8 or 16.
  int bit_depth = 8;

  // --- Distractors.
  // Clutter on the walls: grey rectangles and discs of random size and grey, one per
  // 0.25 m cell of a randomly rotated grid with probability clutter_density. The clutter
  // depends on clutter_seed and the wall, not on the frame seed, so that every camera and
  // every frame sees the same walls.
  bool clutter = false;
  double clutter_density = 0.5;  // (0, 1]
  std::uint64_t clutter_seed = 1;
  // Occluders for this frame (they depend on the frame seed): grey rectangles facing the
  // camera, each placed on the line of sight to a random visible feature (so it hides at
  // least that feature) at 30..70% of its distance, about occluder_size_px across near the
  // image centre. Count 0..64; size (0, 4096].
  int occluder_count = 0;
  double occluder_size_px = 80.0;

  // --- Ground truth.
  // A feature is listed only if it projects at least this far inside the image border.
  // [0, 1000].
  double feature_margin_px = 2.0;

  // --- Execution.
  // Worker threads. The image does not depend on this number. [1, 16].
  int threads = 2;

  // OK, or InvalidArgument whose message starts with the name of the first bad field,
  // e.g. "gamma = 0: must be in [0.2, 5]". O(1).
  absl::Status Validate() const;
};

// One board feature that the camera sees.
struct RenderedFeature {
  std::string board_id;  // StationBoard::id
  int board_index = 0;   // index into StationLayout::boards
  int feature_id = 0;    // BoardFeature::id of that board
  FeatureKind kind = FeatureKind::kXCorner;
  // The exact projection of the feature through the camera model, pixels.
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();
};

struct CameraFrame {
  int bit_depth = 8;
  Image8 image8;    // the rendered image when bit_depth == 8, else empty
  Image16 image16;  // the rendered image when bit_depth == 16, else empty
  // VisibleCameraFeatures of the frame (occluders included), by board then feature id.
  std::vector<RenderedFeature> features;
  // The occluders placed for this frame, in the station frame (their surface z axis
  // points at the camera).
  std::vector<StationSurface> occluders;
};

// The features of the layout's boards that the camera sees, by board (layout order) then
// feature id: those in front of the camera that project (CameraModel::Project) at least
// margin_px inside the image, on a board whose printed face looks towards the camera, and
// whose line of sight is not blocked by anything else (another board's print, an
// occluder, a wall, the floor). The feature's own board never hides it, so hole centres
// count. Cost: per feature one projection and one ray test against every board, occluder
// and wall.
std::vector<RenderedFeature> VisibleCameraFeatures(const CameraModel& camera,
                                                   const Rigid3d& T_station_camera,
                                                   const StationLayout& layout,
                                                   const std::vector<StationSurface>& occluders,
                                                   double margin_px);

// Renders the frame of `camera` at T_station_camera in `layout`. Deterministic: the same
// arguments give the same bytes (whatever options.threads); `seed` drives the noise and
// the occluders. Errors (InvalidArgument): invalid options (the field is named), a
// non-finite camera pose, a layout surface with a non-positive or non-finite size or a
// reflectivity outside [0, 1]. Cost: about 150-180 ms for a 1920 x 1080 frame of the
// reference station on two idle cores, ~270 ms on one (docs/simulator.md); memory: a
// float per pixel, the rays of a coarse grid, and two rows of pixel-corner rays per
// thread.
absl::StatusOr<CameraFrame> RenderCameraFrame(const CameraModel& camera,
                                              const Rigid3d& T_station_camera,
                                              const StationLayout& layout,
                                              const CameraRenderOptions& options,
                                              std::uint64_t seed);

}  // namespace linecal

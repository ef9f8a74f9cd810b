#include <Eigen/Geometry>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numbers>
#include <random>
#include <vector>

#include "absl/strings/str_cat.h"
#include "station/sim/camera_render_internal.h"

namespace linecal::camera_render_internal {
namespace {

// ------------------------------------------------------------------------------------------
// Occluders.

// Along the line of sight, between 30% and 70% of the way to the feature: clear of the
// board and of the lens.
constexpr double kOccluderMinFraction = 0.3;
constexpr double kOccluderMaxFraction = 0.7;
// Sides of 1:2 to 2:1.
constexpr double kOccluderMaxAspect = 2.0;
// Greys from near black to near white.
constexpr double kOccluderMinGrey = 0.05;
constexpr double kOccluderMaxGrey = 0.95;
// Without a visible feature: 1-5 m in front, the scale of a station.
constexpr double kOccluderMinDistanceM = 1.0;
constexpr double kOccluderMaxDistanceM = 5.0;

}  // namespace

std::vector<StationSurface> PlaceOccluders(const CameraModel& camera,
                                           const Rigid3d& T_station_camera,
                                           const StationLayout& layout,
                                           const CameraRenderOptions& o, std::uint64_t seed) {
  std::vector<StationSurface> occluders;
  if (o.occluder_count == 0) return occluders;
  const std::vector<RenderedFeature> visible =
      VisibleCameraFeatures(camera, T_station_camera, layout, {}, o.feature_margin_px);
  const Rigid3d T_camera_station = T_station_camera.Inverse();
  std::mt19937_64 rng(Mix(seed, kOccluderStream));
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const CameraIntrinsics& c = camera.intrinsics();
  for (int i = 0; i < o.occluder_count; ++i) {
    Eigen::Vector3d centre_camera;
    if (!visible.empty()) {
      const RenderedFeature& f =
          visible[static_cast<std::size_t>(unit(rng) * visible.size()) % visible.size()];
      const StationBoard& b = layout.boards[f.board_index];
      const Eigen::Vector2d& p_board = b.board.features()[f.feature_id].p_board;
      const Eigen::Vector3d p_camera =
          T_camera_station * (b.T_station_board * Eigen::Vector3d(p_board.x(), p_board.y(), 0));
      const double fraction =
          kOccluderMinFraction + (kOccluderMaxFraction - kOccluderMinFraction) * unit(rng);
      centre_camera = fraction * p_camera;
    } else {
      Eigen::Vector3d ray;
      const Eigen::Vector2d uv(unit(rng) * c.width - 0.5, unit(rng) * c.height - 0.5);
      if (!camera.Unproject(uv, &ray)) ray = Eigen::Vector3d::UnitZ();
      const double distance =
          kOccluderMinDistanceM + (kOccluderMaxDistanceM - kOccluderMinDistanceM) * unit(rng);
      centre_camera = distance * ray;
    }
    // About occluder_size_px across at the image centre: pixels * distance / focal length.
    const double side_m = o.occluder_size_px * centre_camera.norm() / c.fx;
    const double aspect = std::exp(std::log(kOccluderMaxAspect) * (2 * unit(rng) - 1));
    // Facing the camera, turned by a random angle about the line of sight.
    const Eigen::Vector3d z = -centre_camera.normalized();
    const Eigen::Vector3d any =
        std::abs(z.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
    const Eigen::Vector3d x0 = z.cross(any).normalized();
    const double spin = 2 * std::numbers::pi * unit(rng);
    const Eigen::Vector3d x = std::cos(spin) * x0 + std::sin(spin) * z.cross(x0);
    Eigen::Matrix3d R_camera_occluder;
    R_camera_occluder << x, z.cross(x), z;
    StationSurface occluder;
    occluder.id = absl::StrCat("occluder_", i);
    occluder.T_station_surface = T_station_camera * Rigid3d(R_camera_occluder, centre_camera);
    occluder.size_m = side_m * Eigen::Vector2d(std::sqrt(aspect), 1.0 / std::sqrt(aspect));
    occluder.reflectivity = kOccluderMinGrey + (kOccluderMaxGrey - kOccluderMinGrey) * unit(rng);
    occluders.push_back(occluder);
  }
  return occluders;
}

}  // namespace linecal::camera_render_internal

#include "station/sim/camera_render.h"

#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "station/sim/camera_render_internal.h"

namespace linecal {
namespace {

using camera_render_internal::AllSurfaces;
using camera_render_internal::Blur;
using camera_render_internal::Encode;
using camera_render_internal::Hit;
using camera_render_internal::Illuminate;
using camera_render_internal::kMaxEdgeProbes;
using camera_render_internal::kMinEdgeProbes;
using camera_render_internal::PlaceOccluders;
using camera_render_internal::RenderLinearImage;
using camera_render_internal::Scene;
using camera_render_internal::SceneSurface;

// ------------------------------------------------------------------------------------------
// Option limits (the reasons are in the header's field comments; those of the edge probes
// are in camera_render_internal.h).

constexpr double kMinEdgeTolerancePx = 1e-7;
constexpr double kMaxEdgeTolerancePx = 0.05;
constexpr int kMaxSubdivisionDepth = 10;
constexpr double kMaxIllumination = 100.0;
constexpr double kMaxGradientRatio = 4.0;
constexpr double kMaxBlurSigmaPx = 10.0;
constexpr double kMinGamma = 0.2;
constexpr double kMaxGamma = 5.0;
constexpr double kMaxNoiseSigma = 64.0;
constexpr int kMinJpegQuality = 80;
constexpr int kMaxJpegQuality = 100;
constexpr int kMaxOccluders = 64;
constexpr double kMaxOccluderSizePx = 4096.0;
constexpr double kMaxFeatureMarginPx = 1000.0;
constexpr int kMaxThreads = 16;

absl::Status OutOfRange(absl::string_view field, double value, absl::string_view range) {
  return absl::InvalidArgumentError(absl::StrCat(field, " = ", value, ": must be in ", range));
}

// OK when lo <= value <= hi (NaN fails).
absl::Status CheckClosed(absl::string_view field, double value, double lo, double hi) {
  if (value >= lo && value <= hi) return absl::OkStatus();
  return OutOfRange(field, value, absl::StrCat("[", lo, ", ", hi, "]"));
}

bool PoseFinite(const Rigid3d& T) {
  return T.rotation().coeffs().allFinite() && T.translation().allFinite();
}

absl::Status CheckLayout(const StationLayout& layout) {
  const absl::Status reflectivity =
      CheckClosed("floor_reflectivity", layout.floor_reflectivity, 0.0, 1.0);
  if (!reflectivity.ok()) return reflectivity;
  for (std::size_t i = 0; i < layout.boards.size(); ++i) {
    if (!PoseFinite(layout.boards[i].T_station_board)) {
      return absl::InvalidArgumentError(
          absl::StrCat("boards[", i, "] '", layout.boards[i].id, "': pose is not finite"));
    }
  }
  for (std::size_t i = 0; i < layout.surfaces.size(); ++i) {
    const StationSurface& s = layout.surfaces[i];
    const std::string name = absl::StrCat("surfaces[", i, "] '", s.id, "'");
    if (!PoseFinite(s.T_station_surface)) {
      return absl::InvalidArgumentError(absl::StrCat(name, ": pose is not finite"));
    }
    if (!(s.size_m.allFinite() && s.size_m.minCoeff() > 0.0)) {
      return absl::InvalidArgumentError(absl::StrCat(name, ": size_m = [", s.size_m.x(), ", ",
                                                     s.size_m.y(), "]: must be finite and > 0"));
    }
    const absl::Status r = CheckClosed(absl::StrCat(name, ".reflectivity"), s.reflectivity, 0, 1);
    if (!r.ok()) return r;
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status CameraRenderOptions::Validate() const {
  const std::pair<absl::string_view, std::array<double, 3>> closed[] = {
      {"edge_probes_per_side", {double(edge_probes_per_side), kMinEdgeProbes, kMaxEdgeProbes}},
      {"edge_tolerance_px", {edge_tolerance_px, kMinEdgeTolerancePx, kMaxEdgeTolerancePx}},
      {"max_subdivision_depth", {double(max_subdivision_depth), 0, kMaxSubdivisionDepth}},
      {"white_reflectance", {white_reflectance, 0, 1}},
      {"board_back_reflectance", {board_back_reflectance, 0, 1}},
      {"background_reflectance", {background_reflectance, 0, 1}},
      {"illumination_gradient_ratio", {illumination_gradient_ratio, 1, kMaxGradientRatio}},
      {"vignetting", {vignetting, 0, 1}},
      {"blur_sigma_px", {blur_sigma_px, 0, kMaxBlurSigmaPx}},
      {"gamma", {gamma, kMinGamma, kMaxGamma}},
      {"noise_sigma", {noise_sigma, 0, kMaxNoiseSigma}},
      {"occluder_count", {double(occluder_count), 0, kMaxOccluders}},
      {"feature_margin_px", {feature_margin_px, 0, kMaxFeatureMarginPx}},
      {"threads", {double(threads), 1, kMaxThreads}},
  };
  for (const auto& [field, check] : closed) {
    if (absl::Status s = CheckClosed(field, check[0], check[1], check[2]); !s.ok()) return s;
  }
  if (!(black_reflectance >= 0.0 && black_reflectance < white_reflectance)) {
    return OutOfRange("black_reflectance", black_reflectance,
                      absl::StrCat("[0, white_reflectance = ", white_reflectance, ")"));
  }
  if (!(illumination > 0.0 && illumination <= kMaxIllumination)) {
    return OutOfRange("illumination", illumination, absl::StrCat("(0, ", kMaxIllumination, "]"));
  }
  if (!std::isfinite(illumination_gradient_direction_deg)) {
    return absl::InvalidArgumentError(
        absl::StrCat("illumination_gradient_direction_deg = ", illumination_gradient_direction_deg,
                     ": must be finite"));
  }
  if (vignetting >= 1.0) return OutOfRange("vignetting", vignetting, "[0, 1)");
  if (jpeg_quality != 0 && (jpeg_quality < kMinJpegQuality || jpeg_quality > kMaxJpegQuality)) {
    return OutOfRange("jpeg_quality", jpeg_quality,
                      absl::StrCat("{0} or [", kMinJpegQuality, ", ", kMaxJpegQuality, "]"));
  }
  if (bit_depth != 8 && bit_depth != 16) return OutOfRange("bit_depth", bit_depth, "{8, 16}");
  if (!(clutter_density > 0.0 && clutter_density <= 1.0)) {
    return OutOfRange("clutter_density", clutter_density, "(0, 1]");
  }
  if (!(occluder_size_px > 0.0 && occluder_size_px <= kMaxOccluderSizePx)) {
    return OutOfRange("occluder_size_px", occluder_size_px,
                      absl::StrCat("(0, ", kMaxOccluderSizePx, "]"));
  }
  return absl::OkStatus();
}

std::vector<RenderedFeature> VisibleCameraFeatures(const CameraModel& camera,
                                                   const Rigid3d& T_station_camera,
                                                   const StationLayout& layout,
                                                   const std::vector<StationSurface>& occluders,
                                                   double margin_px) {
  // Only the geometry of the scene matters here: every look is opaque alike.
  const Scene scene(T_station_camera, layout, occluders, CameraRenderOptions());
  const std::vector<std::uint32_t> all = AllSurfaces(scene);
  const Rigid3d T_camera_station = T_station_camera.Inverse();
  const CameraIntrinsics& c = camera.intrinsics();
  // Sight lines are tested up to just short of the feature, so that a surface through the
  // feature (its own board's plane, a board lying on the floor) does not hide it: 1e-9 of
  // the distance is a nanometre at a metre, far below anything the scene resolves.
  constexpr double kSightLineEnd = 1.0 - 1e-9;
  std::vector<RenderedFeature> visible;
  for (std::size_t b = 0; b < layout.boards.size(); ++b) {
    const StationBoard& board = layout.boards[b];
    // Boards come first in the scene, in layout order.
    const SceneSurface& surface = scene.surfaces()[b];
    if (surface.eye_surface.z() <= 0.0) continue;  // the printed face looks away
    const Rigid3d T_camera_board = T_camera_station * board.T_station_board;
    for (const BoardFeature& f : board.board.features()) {
      const Eigen::Vector3d p_camera =
          T_camera_board * Eigen::Vector3d(f.p_board.x(), f.p_board.y(), 0.0);
      Eigen::Vector2d uv;
      if (!camera.Project(p_camera, &uv)) continue;
      if (!(uv.x() >= -0.5 + margin_px && uv.x() <= c.width - 0.5 - margin_px &&
            uv.y() >= -0.5 + margin_px && uv.y() <= c.height - 0.5 - margin_px)) {
        continue;
      }
      const Hit blocker = scene.Trace(p_camera, all.data(), static_cast<int>(all.size()),
                                      static_cast<int>(b), kSightLineEnd);
      if (blocker.surface >= 0) continue;
      visible.push_back(RenderedFeature{board.id, static_cast<int>(b), f.id, f.kind, uv});
    }
  }
  return visible;
}

absl::StatusOr<CameraFrame> RenderCameraFrame(const CameraModel& camera,
                                              const Rigid3d& T_station_camera,
                                              const StationLayout& layout,
                                              const CameraRenderOptions& options,
                                              std::uint64_t seed) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (!PoseFinite(T_station_camera)) {
    return absl::InvalidArgumentError("T_station_camera: pose is not finite");
  }
  if (absl::Status s = CheckLayout(layout); !s.ok()) return s;
  CameraFrame frame;
  frame.occluders = PlaceOccluders(camera, T_station_camera, layout, options, seed);
  frame.features = VisibleCameraFeatures(camera, T_station_camera, layout, frame.occluders,
                                         options.feature_margin_px);
  const Scene scene(T_station_camera, layout, frame.occluders, options);
  std::vector<float> image = RenderLinearImage(camera, scene, options);
  const int width = camera.intrinsics().width, height = camera.intrinsics().height;
  Illuminate(camera, options, &image);
  if (options.blur_sigma_px > 0.0)
    Blur(width, height, options.blur_sigma_px, options.threads, &image);
  Encode(width, height, options, seed, &image, &frame);
  return frame;
}

}  // namespace linecal

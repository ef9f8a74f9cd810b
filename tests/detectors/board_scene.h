#pragma once
// Test scenes for the board detectors: one board in front of a 1280 x 720 pinhole camera,
// rendered by the station simulator's camera renderer with exact ground truth.

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <ctime>
#include <numbers>
#include <vector>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/core/pose.h"
#include "detectors/detection.h"
#include "station/camera/camera_model.h"
#include "station/model/station_layout.h"
#include "station/sim/camera_render.h"

namespace linecal::test_scene {

struct BoardView {
  BoardParams params;
  double distance_m = 2.0;  // from the camera to the board centre, along the optical axis
  double yaw_deg = 0.0;     // the board turned about its vertical axis
  double pitch_deg = 0.0;   // about its horizontal axis
  double roll_deg = 0.0;    // about its normal
  Eigen::Vector2d offset_m = Eigen::Vector2d::Zero();  // board centre, right and up
};

// docs/acceptance.md's two measuring conditions for sub-pixel errors: "clean" (noise 0, blur
// 0.5 px) and "noisy" (noise sigma 4 grey levels, blur 1.0 px).
inline CameraRenderOptions CleanRender() {
  CameraRenderOptions o;
  o.blur_sigma_px = 0.5;
  o.threads = 2;
  return o;
}

inline CameraRenderOptions NoisyRender() {
  CameraRenderOptions o = CleanRender();
  o.blur_sigma_px = 1.0;
  o.noise_sigma = 4.0;
  return o;
}

// 1280 x 720, f = 1000 px (a 65 degree horizontal view), no distortion.
inline CameraModel TestCamera() {
  CameraIntrinsics c;
  c.type = CameraModelType::kPinhole;
  c.width = 1280;
  c.height = 720;
  c.fx = 1000.0;
  c.fy = 1000.0;
  c.cx = 639.5;
  c.cy = 359.5;
  return *CameraModel::Create(c);
}

// The camera 1.5 m above the floor looking along the station's +x.
inline Rigid3d TestCameraPose() {
  return Rigid3d(RotationFromYawPitchRoll({0.0, 0.0, 0.0}) * CameraBaseRotation(),
                 Eigen::Vector3d(0.0, 0.0, 1.5));
}

inline StationLayout SceneOf(const BoardView& view) {
  constexpr double kDeg = std::numbers::pi / 180.0;
  // A board's zero orientation: upright, its print facing -x (towards the camera).
  Eigen::Matrix3d base;
  base.col(0) = -Eigen::Vector3d::UnitY();
  base.col(1) = Eigen::Vector3d::UnitZ();
  base.col(2) = -Eigen::Vector3d::UnitX();
  StationBoard b;
  b.id = "board";
  b.params = view.params;
  b.board = *Board::Create(view.params);
  b.T_station_board = Rigid3d(
      MountingRotation({view.yaw_deg * kDeg, view.pitch_deg * kDeg, view.roll_deg * kDeg}, base),
      Eigen::Vector3d(view.distance_m, -view.offset_m.x(), 1.5 + view.offset_m.y()));
  StationLayout layout;
  layout.name = "test";
  layout.boards.push_back(b);
  return layout;
}

inline CameraFrame RenderView(const BoardView& view, const CameraRenderOptions& options,
                              std::uint64_t seed) {
  absl::StatusOr<CameraFrame> frame =
      RenderCameraFrame(TestCamera(), TestCameraPose(), SceneOf(view), options, seed);
  EXPECT_TRUE(frame.ok()) << frame.status();
  return frame.ok() ? *std::move(frame) : CameraFrame();
}

// RMS of detected minus true image positions over the features both have, and how many
// detected ids have no true feature (must be none); *matched counts the pairs.
inline double FeatureRmsPx(const Detection& detection, const CameraFrame& frame, int* matched,
                           int* unknown_ids) {
  double sum_sq = 0.0;
  *matched = 0;
  *unknown_ids = 0;
  for (const DetectedFeature& f : detection.features) {
    bool known = false;
    for (const RenderedFeature& t : frame.features) {
      if (t.feature_id != f.id) continue;
      known = true;
      sum_sq += (f.uv_px - t.uv_px).squaredNorm();
      ++*matched;
    }
    if (!known) ++*unknown_ids;
  }
  return *matched > 0 ? std::sqrt(sum_sq / *matched) : 0.0;
}

// The largest error of any detected feature against the render's truth: a wrong id is
// off by a whole square (tens of pixels), a right one by a fraction of a pixel.
inline double MaxErrorPx(const Detection& d, const CameraFrame& frame) {
  double worst = 0.0;
  for (const DetectedFeature& f : d.features) {
    for (const RenderedFeature& t : frame.features) {
      if (t.feature_id == f.id) worst = std::max(worst, (f.uv_px - t.uv_px).norm());
    }
  }
  return worst;
}

// docs/acceptance.md's sub-pixel bars for the two conditions above.
inline constexpr double kCleanRmsBarPx = 0.05;  // noise 0, blur 0.5
inline constexpr double kNoisyRmsBarPx = 0.12;  // noise sigma 4, blur 1.0

// CPU time of the calling thread, milliseconds: the speed tests' clock (the machine is
// shared, so wall time says little).
inline double ThreadCpuMs() {
  timespec t;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}

// Every one of the board's features found, in id order, with its own board position.
inline void ExpectComplete(const Detection& d, const Board& board) {
  ASSERT_TRUE(d.found) << DetectReasonName(d.reason) << " " << d.features.size();
  ASSERT_EQ(d.features.size(), board.features().size());
  for (std::size_t i = 0; i < d.features.size(); ++i) {
    EXPECT_EQ(d.features[i].id, static_cast<int>(i));
    EXPECT_EQ(d.features[i].p_board, board.features()[i].p_board);
  }
}

// Uniform noise 0..255 from a fixed LCG: the same image on every machine.
inline Image8 UniformNoiseImage(int width, int height) {
  Image8 noise(width, height);
  std::uint32_t state = 12345;
  for (std::uint8_t& p : noise.pixels) {
    state = state * 1664525u + 1013904223u;
    p = static_cast<std::uint8_t>(state >> 24);
  }
  return noise;
}

// The best of `runs` calls of detect() in thread CPU milliseconds: a speed test's number.
template <typename Detect>
double BestThreadCpuMs(int runs, Detect&& detect) {
  double best_ms = 1e9;
  for (int i = 0; i < runs; ++i) {
    const double t0 = ThreadCpuMs();
    detect();
    best_ms = std::min(best_ms, ThreadCpuMs() - t0);
  }
  return best_ms;
}

}  // namespace linecal::test_scene

// The lane scene renderer: the painted lines are where the listed points say (bright paint
// under every point, road between the lines), the truth is the camera's, and bad options and
// cameras that cannot see the scene are refused by name.
#include "station/sim/lane_scene.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace linecal {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

CameraIntrinsics FrontCamera() {
  CameraIntrinsics k;
  k.width = 960;
  k.height = 540;
  k.fx = k.fy = 700;
  k.cx = 480.5;
  k.cy = 270.2;
  k.k1 = -0.1;
  return k;
}

Rigid3d Mounting(double yaw_deg, double pitch_deg, double roll_deg) {
  return Rigid3d(
      MountingRotation({yaw_deg * kDeg, pitch_deg * kDeg, roll_deg * kDeg}, CameraBaseRotation()),
      Eigen::Vector3d(1.9, 0.1, 1.35));
}

int Grey(const LaneScene& s, const Eigen::Vector2d& uv) {
  return s.frame.image8.at(static_cast<int>(std::lround(uv.x())),
                           static_cast<int>(std::lround(uv.y())));
}

TEST(LaneSceneTest, PaintIsUnderTheListedPoints) {
  const CameraModel camera = *CameraModel::Create(FrontCamera());
  LaneSceneOptions o;
  o.point_distances_m = {5, 10, 15};
  o.marker_distances_m = {7, 12};
  const absl::StatusOr<LaneScene> s = RenderLaneScene(camera, Mounting(0.5, 2.0, -0.4), o, 3);
  ASSERT_TRUE(s.ok()) << s.status();
  ASSERT_EQ(s->frame.image8.width, 960);
  ASSERT_EQ(s->frame.image8.height, 540);
  ASSERT_EQ(s->lanes_px.size(), 2u);
  // paint 0.8 and road 0.2 of full scale, no noise: 204 and 51 grey levels.
  for (const auto& lane : s->lanes_px) {
    ASSERT_EQ(lane.size(), 3u);
    for (const Eigen::Vector2d& uv : lane) EXPECT_NEAR(Grey(*s, uv), 204, 3) << uv.transpose();
  }
  for (const Eigen::Vector2d& uv : s->roll_line_px) EXPECT_NEAR(Grey(*s, uv), 204, 3);
  ASSERT_EQ(s->markers_px.size(), 4u);
  for (const Eigen::Vector2d& uv : s->markers_px) EXPECT_NEAR(Grey(*s, uv), 204, 3);
  // Halfway between the lines at 20 m, beyond the roll line: road.
  EXPECT_NEAR(Grey(*s, (s->lanes_px[0][2] + s->lanes_px[1][2]) / 2), 51, 3);
  EXPECT_TRUE(s->has_marked_point);
  // The truth: the mounting angles and the car axis' vanishing point.
  EXPECT_NEAR(s->angles.pitch, 2.0 * kDeg, 1e-12);
  EXPECT_NEAR(s->angles.roll, -0.4 * kDeg, 1e-12);
  // Yaw 0.5 deg left: the car's axis appears right of the principal point by about f tan(0.5).
  EXPECT_NEAR(s->vanishing_point_px.x() - 480.5, 700 * std::tan(0.5 * kDeg), 0.2);
}

TEST(LaneSceneTest, PointNoiseIsGaussianWithTheGivenSigma) {
  const CameraModel camera = *CameraModel::Create(FrontCamera());
  LaneSceneOptions o;
  o.render_image = false;
  const LaneScene exact = *RenderLaneScene(camera, Mounting(0, 2, 0), o, 1);
  EXPECT_EQ(exact.frame.image8.width, 0);
  o.point_noise_px = 0.5;
  double sum2 = 0;
  int n = 0;
  for (int seed = 0; seed < 200; ++seed) {
    const LaneScene noisy = *RenderLaneScene(camera, Mounting(0, 2, 0), o, seed);
    for (size_t i = 0; i < 2; ++i) {
      for (size_t j = 0; j < 2; ++j) {
        sum2 += (noisy.lanes_px[i][j] - exact.lanes_px[i][j]).squaredNorm();
        n += 2;
      }
    }
  }
  EXPECT_NEAR(std::sqrt(sum2 / n), 0.5, 0.05);
}

TEST(LaneSceneTest, RefusesWhatItCannotRender) {
  const CameraModel camera = *CameraModel::Create(FrontCamera());
  LaneSceneOptions o;
  o.render_image = false;
  o.lane_width_m = 0;
  EXPECT_EQ(RenderLaneScene(camera, Mounting(0, 2, 0), o, 1).status().message(),
            "lane_width_m = 0: must be in (0, 20]");
  o = LaneSceneOptions();
  o.render_image = false;
  EXPECT_EQ(RenderLaneScene(camera, Mounting(90, 2, 0), o, 1).status().message(),
            "the camera looks sideways: a lane scene needs a camera looking along the car");
  // Pitched up 20 degrees the near points leave the image.
  EXPECT_EQ(RenderLaneScene(camera, Mounting(0, -20, 0), o, 1).status().message(),
            "lane point at 6 m: the camera does not see it inside its image");
}

}  // namespace
}  // namespace linecal

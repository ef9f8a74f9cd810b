// After-sale lane calibration against simulated lane scenes (station/sim/lane_scene.h) of
// cameras at known mountings: pinhole with and without distortion, a camera looking backward
// and a fisheye. Exact points recover the mounting to rounding; noisy points are measured
// against the bars (vanishing point 0.5 px, pitch and yaw 0.05 deg, ranging 1% at
// 5-30 m); degenerate input is refused with a message naming the problem.
#include "station/solvers/lane_calibration.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "station/sim/lane_scene.h"

namespace linecal {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

struct Pose {
  const char* name;
  CameraIntrinsics intrinsics;
  Eigen::Vector3d position_m;
  YawPitchRoll angles_deg;
};

CameraIntrinsics Pinhole(int w, int h, double f, double cx, double cy, double k1 = 0, double k2 = 0,
                         double p1 = 0, double p2 = 0) {
  CameraIntrinsics k;
  k.width = w;
  k.height = h;
  k.fx = f;
  k.fy = f * 1.001;
  k.cx = cx;
  k.cy = cy;
  k.k1 = k1;
  k.k2 = k2;
  k.p1 = p1;
  k.p2 = p2;
  return k;
}

std::vector<Pose> Poses() {
  CameraIntrinsics fisheye;
  fisheye.type = CameraModelType::kFisheye;
  fisheye.width = 1280;
  fisheye.height = 960;
  fisheye.fx = fisheye.fy = 330;
  fisheye.cx = 640.5;
  fisheye.cy = 478.2;
  fisheye.k1 = 0.05;
  fisheye.k2 = -0.01;
  return {
      // The reference car's front camera (deploy/cars/reference.json).
      {"front_distorted",
       Pinhole(1920, 1080, 1400, 962.3, 541.8, -0.12, 0.05, 0.0004, -0.0002),
       {1.9, 0.0, 1.35},
       {0.8, 2.1, -0.6}},
      {"front_pinhole_offset",
       Pinhole(1280, 720, 1000, 641.0, 359.0),
       {2.2, 0.35, 1.2},
       {-1.5, 4.0, 1.2}},
      {"rear_distorted",
       Pinhole(1280, 960, 700, 644.0, 476.0, -0.2, 0.04),
       {-1.0, -0.1, 1.0},
       {181.0, 9.0, 0.7}},
      {"front_fisheye", fisheye, {3.7, 0.0, 0.6}, {0.5, 12.0, -1.0}},
  };
}

Rigid3d TrueMounting(const Pose& p) {
  const YawPitchRoll a{p.angles_deg.yaw * kDeg, p.angles_deg.pitch * kDeg,
                       p.angles_deg.roll * kDeg};
  return Rigid3d(MountingRotation(a, CameraBaseRotation()), p.position_m);
}

LaneSceneOptions PointsOnly(const Pose& p) {
  LaneSceneOptions o;
  o.render_image = false;
  // The fisheye sees far points too small and near ones too far off axis for 6 and 25 m.
  if (p.intrinsics.type == CameraModelType::kFisheye) {
    o.point_distances_m = {3.0, 12.0};
    o.roll_line_distance_m = 4.0;
    o.marked_point_distance_m = 6.0;
  }
  return o;
}

LaneCalibrationInput InputOf(const Pose& p, const LaneScene& scene) {
  LaneCalibrationInput in;
  in.intrinsics = p.intrinsics;
  in.lanes_px = scene.lanes_px;
  if (scene.has_roll_line) in.roll_line_px = scene.roll_line_px;
  in.looking_backward = std::cos(p.angles_deg.yaw * kDeg) < 0;
  in.camera_height_m = p.position_m.z();
  in.longitudinal_offset_m = p.position_m.x();
  in.lateral_offset_m = p.position_m.y();
  return in;
}

double AngleError(double a, double b) {
  return std::abs(std::remainder(a - b, 2 * std::numbers::pi));
}

// The worst relative ranging error over ground points 5-30 m ahead across the lane: each
// projected through the true camera, then back to the ground through the estimate.
double WorstRangingError(const Pose& p, const LaneCalibrationResult& r) {
  const CameraModel camera = *CameraModel::Create(p.intrinsics);
  const double along = std::cos(p.angles_deg.yaw * kDeg) < 0 ? -1 : 1;
  double worst = 0;
  const bool fisheye = p.intrinsics.type == CameraModelType::kFisheye;
  for (double d : fisheye ? std::vector<double>{3, 5, 8, 12} : std::vector<double>{5, 10, 20, 30}) {
    for (double y : {-1.75, 0.0, 1.75}) {
      const double e = RelativeRangingError(camera, TrueMounting(p), r.T_car_camera,
                                            Eigen::Vector2d(p.position_m.x() + along * d, y));
      EXPECT_TRUE(std::isfinite(e)) << p.name << " " << d << " " << y;
      worst = std::max(worst, e);
    }
  }
  return worst;
}

TEST(LaneCalibrationTest, ExactPointsRecoverEveryPose) {
  for (const Pose& p : Poses()) {
    SCOPED_TRACE(p.name);
    const CameraModel camera = *CameraModel::Create(p.intrinsics);
    const absl::StatusOr<LaneScene> scene =
        RenderLaneScene(camera, TrueMounting(p), PointsOnly(p), 1);
    ASSERT_TRUE(scene.ok()) << scene.status();
    LaneCalibrationInput in = InputOf(p, *scene);
    in.marked_point =
        LaneMarkedPoint{scene->marked_point_px, PointsOnly(p).marked_point_distance_m};
    const absl::StatusOr<LaneCalibrationResult> r = CalibrateFromLanes(in);
    ASSERT_TRUE(r.ok()) << r.status();
    EXPECT_TRUE(r->roll_from_line);
    EXPECT_LT((r->vanishing_point_px - scene->vanishing_point_px).norm(), 1e-6);
    EXPECT_LT(AngleError(r->angles.yaw, scene->angles.yaw), 1e-9);
    EXPECT_LT(AngleError(r->angles.pitch, scene->angles.pitch), 1e-9);
    EXPECT_LT(AngleError(r->angles.roll, scene->angles.roll), 1e-9);
    EXPECT_LT((r->T_car_camera.translation() - p.position_m).norm(), 1e-12);
    EXPECT_LT(WorstRangingError(p, *r), 1e-9);
    ASSERT_TRUE(r->distance_check.has_value());
    EXPECT_NEAR(r->distance_check->computed_distance_m, in.marked_point->measured_distance_m, 1e-8);
    EXPECT_TRUE(r->distance_check->pass);
    // The estimate's own vanishing point (of its rotation) is the lines' intersection.
    Eigen::Vector2d vp;
    ASSERT_TRUE(CarAxisVanishingPoint(p.intrinsics, r->T_car_camera.Inverse(), &vp));
    EXPECT_LT((vp - r->vanishing_point_px).norm(), 1e-6);
  }
}

TEST(LaneCalibrationTest, WithoutRollLineTheAssumedRollIsUsed) {
  const Pose p = Poses()[1];
  const CameraModel camera = *CameraModel::Create(p.intrinsics);
  const LaneScene scene = *RenderLaneScene(camera, TrueMounting(p), PointsOnly(p), 1);
  LaneCalibrationInput in = InputOf(p, scene);
  in.roll_line_px.reset();
  in.assumed_roll_rad = p.angles_deg.roll * kDeg;  // the true roll: exact again
  LaneCalibrationResult r = *CalibrateFromLanes(in);
  EXPECT_FALSE(r.roll_from_line);
  EXPECT_LT(AngleError(r.angles.pitch, scene.angles.pitch), 1e-9);
  EXPECT_LT(AngleError(r.angles.yaw, scene.angles.yaw), 1e-9);
  EXPECT_NEAR(r.angles.roll, in.assumed_roll_rad, 1e-12);
  // Assuming roll 0 for a camera rolled 1.2 degrees moves the angles and the ranging: what
  // the roll line is for.
  in.assumed_roll_rad = 0;
  r = *CalibrateFromLanes(in);
  EXPECT_GT(AngleError(r.angles.roll, scene.angles.roll), 1.1 * kDeg);
  EXPECT_GT(WorstRangingError(p, r), 0.01);
}

TEST(LaneCalibrationTest, FourMarkersParallelToTheCar) {
  const Pose p = Poses()[0];
  const CameraModel camera = *CameraModel::Create(p.intrinsics);
  LaneSceneOptions o = PointsOnly(p);
  o.paint_lane_lines = false;
  o.marker_distances_m = {7.0, 22.0};
  const LaneScene scene = *RenderLaneScene(camera, TrueMounting(p), o, 1);
  ASSERT_EQ(scene.markers_px.size(), 4u);
  EXPECT_TRUE(scene.lanes_px.empty());
  LaneCalibrationInput in = InputOf(p, scene);
  in.lanes_px = {{scene.markers_px[0], scene.markers_px[1]},
                 {scene.markers_px[2], scene.markers_px[3]}};
  const LaneCalibrationResult r = *CalibrateFromLanes(in);
  EXPECT_LT((r.vanishing_point_px - scene.vanishing_point_px).norm(), 1e-6);
  EXPECT_LT(AngleError(r.angles.pitch, scene.angles.pitch), 1e-9);
}

// Noisy clicks: Gaussian point noise, four points a line spread from 5 to 30 m, over many
// draws; the 95th percentiles against the bars.
struct NoiseStats {
  double vp_px, pitch_deg, yaw_deg, roll_deg, ranging;
};

NoiseStats MeasureNoise(const Pose& p, double noise_px, int trials) {
  const CameraModel camera = *CameraModel::Create(p.intrinsics);
  LaneSceneOptions o = PointsOnly(p);
  o.point_distances_m = {5, 10, 20, 30};
  o.point_noise_px = noise_px;
  std::vector<double> vp, pitch, yaw, roll, ranging;
  for (int t = 0; t < trials; ++t) {
    const LaneScene scene = *RenderLaneScene(camera, TrueMounting(p), o, 100 + t);
    const LaneCalibrationResult r = *CalibrateFromLanes(InputOf(p, scene));
    vp.push_back((r.vanishing_point_px - scene.vanishing_point_px).norm());
    pitch.push_back(AngleError(r.angles.pitch, scene.angles.pitch) / kDeg);
    yaw.push_back(AngleError(r.angles.yaw, scene.angles.yaw) / kDeg);
    roll.push_back(AngleError(r.angles.roll, scene.angles.roll) / kDeg);
    ranging.push_back(WorstRangingError(p, r));
  }
  const auto p95 = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[static_cast<size_t>(0.95 * (v.size() - 1))];
  };
  return {p95(vp), p95(pitch), p95(yaw), p95(roll), p95(ranging)};
}

TEST(LaneCalibrationTest, NoisyPointsMeetTheBars) {
  for (const Pose& p : {Poses()[0], Poses()[1]}) {
    SCOPED_TRACE(p.name);
    const NoiseStats s = MeasureNoise(p, 0.1, 200);
    printf("%s: p95 vp %.3f px, pitch %.4f, yaw %.4f, roll %.4f deg, ranging %.3f%%\n", p.name,
           s.vp_px, s.pitch_deg, s.yaw_deg, s.roll_deg, 100 * s.ranging);
    EXPECT_LE(s.vp_px, 0.5);
    EXPECT_LE(s.pitch_deg, 0.05);
    EXPECT_LE(s.yaw_deg, 0.05);
    EXPECT_LE(s.ranging, 0.01);
  }
}

class LaneCalibrationBadInputTest : public ::testing::Test {
 protected:
  void SetUp() override {
    pose_ = Poses()[0];
    const CameraModel camera = *CameraModel::Create(pose_.intrinsics);
    scene_ = *RenderLaneScene(camera, TrueMounting(pose_), PointsOnly(pose_), 1);
    in_ = InputOf(pose_, scene_);
    ASSERT_TRUE(CalibrateFromLanes(in_).ok());
  }
  std::string Error() const {
    const absl::StatusOr<LaneCalibrationResult> r = CalibrateFromLanes(in_);
    EXPECT_FALSE(r.ok());
    if (r.ok()) return "";
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
    return std::string(r.status().message());
  }
  Pose pose_;
  LaneScene scene_;
  LaneCalibrationInput in_;
};

TEST_F(LaneCalibrationBadInputTest, ParallelLines) {
  // Two lines 0.2 degrees apart in the image: a camera looking straight down would see that.
  in_.lanes_px = {{{500, 900}, {600, 300}}, {{900, 900}, {1000 + 600 * std::tan(0.2 * kDeg), 300}}};
  EXPECT_EQ(Error().rfind("parallel lines: ", 0), 0u) << Error();
}

TEST_F(LaneCalibrationBadInputTest, PointsAboveTheHorizon) {
  // The lanes' mirror image above the horizon: the lines still meet at the vanishing point,
  // but the points cannot lie on the ground.
  for (auto& lane : in_.lanes_px) {
    for (Eigen::Vector2d& uv : lane) uv.y() = 2 * scene_.vanishing_point_px.y() - uv.y();
  }
  const std::string e = Error();
  EXPECT_NE(e.find("above the horizon"), std::string::npos) << e;
  EXPECT_EQ(e.rfind("lanes[0][0]", 0), 0u) << e;
}

TEST_F(LaneCalibrationBadInputTest, MarkedPointAboveTheHorizon) {
  in_.marked_point = LaneMarkedPoint{{960, 100}, 12.0};
  EXPECT_EQ(Error().rfind("marked_point (960.0, 100.0) is above the horizon", 0), 0u) << Error();
}

TEST_F(LaneCalibrationBadInputTest, MissingOrBadValues) {
  in_.camera_height_m = 0;  // not given
  EXPECT_EQ(Error(), "camera_height_m = 0: must be in (0, 10]");
  in_.camera_height_m = 1.35;
  in_.lanes_px.pop_back();
  EXPECT_EQ(Error(), "lanes: at least 2 lines needed, got 1");
  in_.lanes_px = scene_.lanes_px;
  in_.lanes_px[1].pop_back();
  EXPECT_EQ(Error(), "lanes[1]: at least 2 points needed, got 1");
  in_.lanes_px[1].push_back(in_.lanes_px[1][0] + Eigen::Vector2d(0.3, 0.2));
  EXPECT_EQ(Error().rfind("lanes[1]: its points coincide", 0), 0u) << Error();
  in_.lanes_px = scene_.lanes_px;
  in_.lanes_px[0][1] = {-20, 300};
  EXPECT_EQ(Error(), "lanes[0][1] (-20.0, 300.0): outside the image");
  in_.lanes_px = scene_.lanes_px;
  in_.intrinsics.fx = -3;
  EXPECT_EQ(Error().rfind("intrinsics: fx = -3", 0), 0u) << Error();
  in_.intrinsics = pose_.intrinsics;
  in_.marked_point = LaneMarkedPoint{scene_.marked_point_px, 0};
  EXPECT_EQ(Error(), "measured_distance_m = 0: must be in (0, 10000)");
}

TEST_F(LaneCalibrationBadInputTest, RollLineAlongTheCar) {
  in_.roll_line_px = std::array<Eigen::Vector2d, 2>{in_.lanes_px[0][0], in_.lanes_px[0][1]};
  EXPECT_EQ(Error().rfind("roll_line: it runs (nearly) through the vanishing point", 0), 0u)
      << Error();
}

TEST(LaneCalibrationTest, DistanceCheckFailsBeyondTheTolerance) {
  const Pose p = Poses()[0];
  const CameraModel camera = *CameraModel::Create(p.intrinsics);
  const LaneScene scene = *RenderLaneScene(camera, TrueMounting(p), PointsOnly(p), 1);
  LaneCalibrationInput in = InputOf(p, scene);
  in.marked_point = LaneMarkedPoint{scene.marked_point_px, 15.0 * 1.02};  // the tape says 2% more
  in.tolerance_percent = 1.0;
  LaneCalibrationResult r = *CalibrateFromLanes(in);
  EXPECT_NEAR(r.distance_check->error_percent, 100 * (1 / 1.02 - 1), 1e-6);
  EXPECT_FALSE(r.distance_check->pass);
  in.tolerance_percent = 2.5;
  r = *CalibrateFromLanes(in);
  EXPECT_TRUE(r.distance_check->pass);
}

}  // namespace
}  // namespace linecal

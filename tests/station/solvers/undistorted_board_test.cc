// The board check through a known camera model (station/solvers/undistorted_board.h), closed
// loop: a board's corners projected through a strong barrel lens and a fisheye from a known
// pose, with Gaussian noise, pass the check with a residual of the noise and give the pose; the
// same corners through a wrong lens, or with a shifted correspondence, are refused.
#include "station/solvers/undistorted_board.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace linecal {
namespace {

constexpr double kDeg = M_PI / 180.0;

CameraIntrinsics BarrelLens() {
  return {.type = CameraModelType::kPinhole,
          .width = 1280,
          .height = 720,
          .fx = 1000.0,
          .fy = 1000.0,
          .cx = 639.5,
          .cy = 359.5,
          .k1 = -0.3,
          .k2 = 0.08,
          .p1 = 0.0005,
          .p2 = -0.0003};
}

CameraIntrinsics FisheyeLens() {
  return {.type = CameraModelType::kFisheye,
          .width = 1280,
          .height = 960,
          .fx = 330.0,
          .fy = 331.0,
          .cx = 640.5,
          .cy = 478.5,
          .k1 = 0.05,
          .k2 = -0.01,
          .k3 = 0.002,
          .k4 = -0.0005};
}

// A board turned 25 degrees about its vertical and 10 about its horizontal axis, in front of
// the camera at `distance_m`, its centre `side_m` to the right.
Rigid3d BoardPose(double distance_m, double side_m) {
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(25.0 * kDeg, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(10.0 * kDeg, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  return Rigid3d(R, Eigen::Vector3d(side_m, 0.02, distance_m));
}

// The 9 x 6 inner corners of a checker of 40 mm squares seen from T_camera_board, each moved
// by Gaussian noise of `sigma_px` per axis (seeded).
std::vector<DetectedFeature> Corners(const CameraModel& camera, const Rigid3d& T_camera_board,
                                     double sigma_px) {
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, sigma_px);
  std::vector<DetectedFeature> features;
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 9; ++c) {
      DetectedFeature f;
      f.id = r * 9 + c;
      f.p_board = Eigen::Vector2d((c - 4) * 0.04, (2.5 - r) * 0.04);
      Eigen::Vector2d uv;
      EXPECT_TRUE(
          camera.Project(T_camera_board * Eigen::Vector3d(f.p_board.x(), f.p_board.y(), 0.0), &uv));
      f.uv_px = uv + Eigen::Vector2d(noise(rng), noise(rng));
      features.push_back(f);
    }
  }
  return features;
}

// `max_mm`, `max_deg`: the pose's bounds, which scale with the board's size in the image.
void ExpectVerifiedAt(const CameraModel& camera, const Rigid3d& T_camera_board, double max_mm,
                      double max_deg) {
  // 0.05 px per axis: a good detector's noise.
  constexpr double kSigmaPx = 0.05;
  const std::vector<DetectedFeature> features = Corners(camera, T_camera_board, kSigmaPx);
  const absl::StatusOr<UndistortedBoard> check = CheckBoardUndistorted(camera, features);
  ASSERT_TRUE(check.ok()) << check.status();
  EXPECT_TRUE(check->verified);
  EXPECT_EQ(check->points, 54);
  // Residual vectors of 2D noise σ per axis have an RMS length of σ √2, less the share the
  // homography's 8 parameters take of the 108 coordinates: σ √2 √(100 / 108) ≈ 0.068 px.
  const double expected_px = kSigmaPx * std::sqrt(2.0 * 100.0 / 108.0);
  EXPECT_NEAR(check->homography_rms_px, expected_px, 0.3 * expected_px);
  EXPECT_GE(check->homography_max_px, check->homography_rms_px);
  ASSERT_EQ(check->pose.outcome, PnpOutcome::kOk);
  const Rigid3d& T = check->pose.T_camera_object;
  EXPECT_LT((T.translation() - T_camera_board.translation()).norm(), 1e-3 * max_mm);
  EXPECT_LT(T.rotation().angularDistance(T_camera_board.rotation()), max_deg * kDeg);
  std::printf("%s: homography %.4f px RMS (expected %.4f), pose %.4f mm, %.5f deg\n",
              CameraModelTypeName(camera.type()), check->homography_rms_px, expected_px,
              1e3 * (T.translation() - T_camera_board.translation()).norm(),
              T.rotation().angularDistance(T_camera_board.rotation()) / kDeg);
}

TEST(UndistortedBoardTest, BarrelLensBoardIsVerifiedAndLocated) {
  const CameraModel camera = *CameraModel::Create(BarrelLens());
  // The corners span about 550 px: noise of 0.07 px (per corner) leaves the rotation to about
  // 0.07 / 550 rad ≈ 0.007° and the depth to 0.55 m × 0.07 / 550 ≈ 0.07 mm; three times that.
  ExpectVerifiedAt(camera, BoardPose(0.55, 0.05), 0.2, 0.02);
}

// A fisheye's board 45 degrees off the optical axis, where the lens bends it most.
TEST(UndistortedBoardTest, FisheyeBoardOffAxisIsVerifiedAndLocated) {
  const CameraModel camera = *CameraModel::Create(FisheyeLens());
  // The corners span about 150 px at 0.7 m: 0.07 / 150 rad ≈ 0.027° and 0.7 m × 0.07 / 150 ≈
  // 0.33 mm; three times that.
  ExpectVerifiedAt(camera, BoardPose(0.5, 0.5), 1.0, 0.08);
}

TEST(UndistortedBoardTest, WrongLensIsRefused) {
  const CameraModel truth = *CameraModel::Create(BarrelLens());
  CameraIntrinsics wrong_k1 = BarrelLens();
  wrong_k1.k1 = -wrong_k1.k1;
  const std::vector<DetectedFeature> features = Corners(truth, BoardPose(0.55, 0.05), 0.05);
  const absl::StatusOr<UndistortedBoard> check =
      CheckBoardUndistorted(*CameraModel::Create(wrong_k1), features);
  ASSERT_TRUE(check.ok()) << check.status();
  EXPECT_FALSE(check->verified);
  EXPECT_GT(check->homography_rms_px, 1.0);
  EXPECT_EQ(check->pose.outcome, PnpOutcome::kNoStart);  // not solved
}

// One row's ids shifted by a square: the corners are on the board plane but not where their
// ids say.
TEST(UndistortedBoardTest, ShiftedCorrespondenceIsRefused) {
  const CameraModel camera = *CameraModel::Create(BarrelLens());
  std::vector<DetectedFeature> features = Corners(camera, BoardPose(0.55, 0.05), 0.05);
  for (int c = 0; c < 9; ++c) features[c].p_board.x() += 0.04;
  const absl::StatusOr<UndistortedBoard> check = CheckBoardUndistorted(camera, features);
  ASSERT_TRUE(check.ok()) << check.status();
  EXPECT_FALSE(check->verified);
  EXPECT_GT(check->homography_rms_px, 1.0);
}

TEST(UndistortedBoardTest, TooFewFeaturesAreNotChecked) {
  const CameraModel camera = *CameraModel::Create(BarrelLens());
  std::vector<DetectedFeature> features = Corners(camera, BoardPose(0.55, 0.05), 0.0);
  features.resize(3);
  const absl::StatusOr<UndistortedBoard> check = CheckBoardUndistorted(camera, features);
  ASSERT_TRUE(check.ok()) << check.status();
  EXPECT_FALSE(check->verified);
  EXPECT_EQ(check->points, 3);
  EXPECT_TRUE(std::isinf(check->homography_rms_px));
}

TEST(UndistortedBoardTest, InvalidOptionsAreErrors) {
  const CameraModel camera = *CameraModel::Create(BarrelLens());
  const std::vector<DetectedFeature> features = Corners(camera, BoardPose(0.55, 0.05), 0.0);
  UndistortedBoardOptions options;
  options.max_homography_rms_px = 0.0;
  const absl::StatusOr<UndistortedBoard> zero = CheckBoardUndistorted(camera, features, options);
  ASSERT_FALSE(zero.ok());
  EXPECT_EQ(zero.status().message(), "max_homography_rms_px = 0: must be within (0, 100]");
  options = {};
  options.pnp.huber_px = -1.0;
  const absl::StatusOr<UndistortedBoard> huber = CheckBoardUndistorted(camera, features, options);
  ASSERT_FALSE(huber.ok());
  EXPECT_EQ(huber.status().message(), "pnp.huber_px: out of range");
}

}  // namespace
}  // namespace linecal

#include "detectors/core/pose.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

namespace linecal {
namespace {

// Double-precision round-off of a few chained 3x3 products stays far below this.
constexpr double kTight = 1e-12;

Rigid3d RandomPose(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  const Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  return Rigid3d(q, Eigen::Vector3d(n(rng), n(rng), n(rng)) * 5.0);
}

TEST(Rigid3dTest, IdentityLeavesPointsAlone) {
  const Eigen::Vector3d p(1.5, -2.0, 0.25);
  EXPECT_TRUE((Rigid3d() * p).isApprox(p, kTight));
}

TEST(Rigid3dTest, ClosedFormRotationAboutZ) {
  // 90 degrees about z maps x to y; then translate by (1, 2, 3).
  const Rigid3d t(
      Eigen::Quaterniond(Eigen::AngleAxisd(std::numbers::pi / 2, Eigen::Vector3d::UnitZ())),
      Eigen::Vector3d(1, 2, 3));
  const Eigen::Vector3d p = t * Eigen::Vector3d(1, 0, 0);
  EXPECT_NEAR(p.x(), 1.0, kTight);
  EXPECT_NEAR(p.y(), 3.0, kTight);
  EXPECT_NEAR(p.z(), 3.0, kTight);
}

TEST(Rigid3dTest, RandomCompositionMatchesMatrices) {
  std::mt19937 rng(42);
  for (int i = 0; i < 1000; ++i) {
    const Rigid3d a = RandomPose(rng), b = RandomPose(rng);
    const Eigen::Matrix4d ab = a.Matrix() * b.Matrix();
    EXPECT_TRUE((a * b).Matrix().isApprox(ab, kTight));
    const Eigen::Vector3d p(0.3 * i, -1.0, 2.0);
    EXPECT_TRUE(((a * b) * p).isApprox(a * (b * p), kTight));
  }
}

TEST(Rigid3dTest, InverseCancels) {
  std::mt19937 rng(7);
  for (int i = 0; i < 1000; ++i) {
    const Rigid3d a = RandomPose(rng);
    EXPECT_TRUE((a * a.Inverse()).Matrix().isApprox(Eigen::Matrix4d::Identity(), kTight));
    EXPECT_TRUE(a.Inverse().Matrix().isApprox(a.Matrix().inverse(), kTight));
  }
}

TEST(Rigid3dTest, MatrixRoundTrip) {
  std::mt19937 rng(3);
  for (int i = 0; i < 100; ++i) {
    const Rigid3d a = RandomPose(rng);
    EXPECT_TRUE(Rigid3d::FromMatrix(a.Matrix()).Matrix().isApprox(a.Matrix(), kTight));
  }
}

TEST(Rigid3dTest, QuaternionIsNormalised) {
  const Rigid3d a(Eigen::Quaterniond(2, 0, 0, 0), Eigen::Vector3d::Zero());
  EXPECT_NEAR(a.rotation().norm(), 1.0, kTight);
}

TEST(MountingAnglesTest, CameraLookingForwardIsZero) {
  const YawPitchRoll a = MountingAngles(CameraBaseRotation(), CameraBaseRotation());
  EXPECT_NEAR(a.yaw, 0, kTight);
  EXPECT_NEAR(a.pitch, 0, kTight);
  EXPECT_NEAR(a.roll, 0, kTight);
  // And the base rotation is the convention's: optical axis forward, x right, y down.
  const Eigen::Matrix3d r = CameraBaseRotation();
  EXPECT_TRUE(r.col(2).isApprox(Eigen::Vector3d::UnitX()));
  EXPECT_TRUE(r.col(0).isApprox(-Eigen::Vector3d::UnitY()));
  EXPECT_TRUE(r.col(1).isApprox(-Eigen::Vector3d::UnitZ()));
  EXPECT_NEAR(r.determinant(), 1.0, kTight);
}

TEST(MountingAnglesTest, PositiveYawTurnsCameraLeft) {
  // ISO 8855: yaw about +z, so +10 degrees looks to the left (+y of the car).
  const double yaw = 10.0 * std::numbers::pi / 180;
  const Eigen::Matrix3d r = MountingRotation({yaw, 0, 0}, CameraBaseRotation());
  const Eigen::Vector3d axis = r.col(2);  // optical axis in the car frame
  EXPECT_NEAR(std::atan2(axis.y(), axis.x()), yaw, kTight);
}

TEST(MountingAnglesTest, PositivePitchLooksDown) {
  // Ry(+pitch) tips the x axis towards -z: a camera pitched positive looks at the ground.
  const Eigen::Matrix3d r = MountingRotation({0, 0.1, 0}, CameraBaseRotation());
  EXPECT_LT(r.col(2).z(), 0.0);
}

TEST(MountingAnglesTest, RandomRoundTrip) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> yaw(-3.1, 3.1), pitch(-1.5, 1.5), roll(-3.1, 3.1);
  for (int i = 0; i < 1000; ++i) {
    const YawPitchRoll a{yaw(rng), pitch(rng), roll(rng)};
    const YawPitchRoll b =
        MountingAngles(MountingRotation(a, CameraBaseRotation()), CameraBaseRotation());
    EXPECT_NEAR(a.yaw, b.yaw, 1e-10);
    EXPECT_NEAR(a.pitch, b.pitch, 1e-10);
    EXPECT_NEAR(a.roll, b.roll, 1e-10);
  }
}

TEST(MountingAnglesTest, GimbalLockKeepsTheRotation) {
  // At pitch = 90 degrees only yaw - roll is defined; the recovered angles must still
  // reproduce the same rotation.
  const YawPitchRoll a{0.4, std::numbers::pi / 2, 0.1};
  const Eigen::Matrix3d r = RotationFromYawPitchRoll(a);
  const YawPitchRoll b = YawPitchRollFromRotation(r);
  EXPECT_NEAR(b.pitch, std::numbers::pi / 2, 1e-7);
  EXPECT_TRUE(RotationFromYawPitchRoll(b).isApprox(r, 1e-9));
}

}  // namespace
}  // namespace linecal

// The verdict's guard band (station/solvers/mounting.h): conformity or non-conformity is
// claimed only when the deviation is more than 2 sigma from the tolerance edge.

#include "station/solvers/mounting.h"

#include <gtest/gtest.h>

#include <numbers>
#include <string>

namespace linecal {
namespace {

constexpr double kDeg = std::numbers::pi / 180;

TEST(DecideToleranceTest, TwoSigmaBandAroundTheEdge) {
  // Tolerance 1.0, sigma 0.1: inside up to 0.8, outside beyond 1.2, undecided between.
  EXPECT_EQ(DecideTolerance(0.8, 0.1, 1.0), ToleranceDecision::kInside);
  EXPECT_EQ(DecideTolerance(-0.8, 0.1, 1.0), ToleranceDecision::kInside);
  EXPECT_EQ(DecideTolerance(0.81, 0.1, 1.0), ToleranceDecision::kUndecided);
  EXPECT_EQ(DecideTolerance(1.0, 0.1, 1.0), ToleranceDecision::kUndecided);
  EXPECT_EQ(DecideTolerance(-1.2, 0.1, 1.0), ToleranceDecision::kUndecided);
  EXPECT_EQ(DecideTolerance(1.21, 0.1, 1.0), ToleranceDecision::kOutside);
  EXPECT_EQ(DecideTolerance(-1.21, 0.1, 1.0), ToleranceDecision::kOutside);
  // Without a guard the rule is the bare comparison.
  EXPECT_EQ(DecideTolerance(0.99, 0.1, 1.0, 0.0), ToleranceDecision::kInside);
  EXPECT_EQ(DecideTolerance(1.01, 0.1, 1.0, 0.0), ToleranceDecision::kOutside);
}

SensorModel Camera() {
  SensorModel s;
  s.name = "front_camera";
  s.tolerance.yaw_rad = 1.0 * kDeg;
  s.tolerance.pitch_rad = 1.0 * kDeg;
  s.tolerance.roll_rad = 1.0 * kDeg;
  s.tolerance.xyz_m = Eigen::Vector3d(0.01, 0.01, 0.01);
  return s;
}

MountingEstimate Estimate(double yaw_deg, double x_m) {
  MountingEstimate m;
  m.angles_deviation.yaw = yaw_deg * kDeg;
  m.position_deviation_m = Eigen::Vector3d(x_m, 0, 0);
  m.sigma << 0.02 * kDeg, 0.02 * kDeg, 0.02 * kDeg, 0.0005, 0.0005, 0.0005;
  return m;
}

TEST(JudgeMountingTest, PassFailAndNearTheEdge) {
  const SensorModel s = Camera();
  MountingJudgement j = JudgeMounting(s, Estimate(0.95, 0.0), 1.0 / 3.0);
  EXPECT_EQ(j.verdict, Verdict::kPass);
  EXPECT_EQ(j.reason, "");

  // 0.97 deg: within 2 sigma (0.04 deg) of the 1 deg edge.
  j = JudgeMounting(s, Estimate(0.97, 0.0), 1.0 / 3.0);
  EXPECT_EQ(j.verdict, Verdict::kError);
  EXPECT_EQ(j.reason, "near_tolerance_edge");
  EXPECT_NE(j.message.find("yaw +0.970 deg (2 sigma 0.040, tolerance 1.000)"), std::string::npos)
      << j.message;

  // 1.03 deg is also undecided; 1.05 deg is shown out.
  EXPECT_EQ(JudgeMounting(s, Estimate(1.03, 0.0), 1.0 / 3.0).reason, "near_tolerance_edge");
  j = JudgeMounting(s, Estimate(1.05, 0.0), 1.0 / 3.0);
  EXPECT_EQ(j.verdict, Verdict::kFail);
  EXPECT_EQ(j.reason, "yaw_out_of_tolerance");

  // A component shown out wins over another that is undecided.
  j = JudgeMounting(s, Estimate(0.99, 0.012), 1.0 / 3.0);
  EXPECT_EQ(j.verdict, Verdict::kFail);
  EXPECT_EQ(j.reason, "x_out_of_tolerance");
  EXPECT_NE(j.message.find("x +12.000 mm"), std::string::npos) << j.message;
}

TEST(JudgeMountingTest, UnobservedComponentsAreNotJudged) {
  const SensorModel s = Camera();
  MountingEstimate m = Estimate(0.0, 0.0);
  m.position_deviation_m.x() = 0.0099;  // within 2 sigma of the edge, but not observed
  m.observed[3] = false;
  EXPECT_EQ(JudgeMounting(s, m, 1.0 / 3.0).verdict, Verdict::kPass);
}

}  // namespace
}  // namespace linecal

#include "detectors/common/homography.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <vector>

namespace linecal {
namespace {

// A board 0.5 m x 0.3 m, 1.5 m in front of a 1000 px pinhole camera, turned 30 degrees about
// y and 10 about x: a typical station view, H_image_board = K [r1 r2 t].
Eigen::Matrix3d StationView() {
  Eigen::Matrix3d K;
  K << 1000.0, 0.0, 640.0, 0.0, 1000.0, 360.0, 0.0, 0.0, 1.0;
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(0.5236, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(0.1745, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  Eigen::Matrix3d Rt;
  Rt.col(0) = R.col(0);
  Rt.col(1) = R.col(1);
  Rt.col(2) = Eigen::Vector3d(0.05, -0.02, 1.5);
  return K * Rt;
}

std::vector<Eigen::Vector2d> GridPoints(int cols, int rows, double step_m) {
  std::vector<Eigen::Vector2d> points;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      points.emplace_back((c - 0.5 * (cols - 1)) * step_m, (r - 0.5 * (rows - 1)) * step_m);
    }
  }
  return points;
}

std::vector<Eigen::Vector2d> Project(const Eigen::Matrix3d& H,
                                     const std::vector<Eigen::Vector2d>& src) {
  std::vector<Eigen::Vector2d> dst;
  for (const Eigen::Vector2d& p : src) dst.push_back(ApplyHomography(H, p));
  return dst;
}

TEST(HomographyTest, RecoversExactHomographyFromFourPoints) {
  const Eigen::Matrix3d H_true = StationView();
  const std::vector<Eigen::Vector2d> src = GridPoints(2, 2, 0.3);
  const std::vector<Eigen::Vector2d> dst = Project(H_true, src);
  const std::optional<HomographyFit> fit = FitHomography(src, dst);
  ASSERT_TRUE(fit.has_value());
  // Exact data: only rounding remains (pixel coordinates of order 10^3, double precision).
  constexpr double kExactTolPx = 1e-9;
  EXPECT_LT(fit->max_residual, kExactTolPx);
  // A point off the fitted ones is mapped the same way too.
  const Eigen::Vector2d p(0.4, -0.35);
  EXPECT_LT((ApplyHomography(fit->H, p) - ApplyHomography(H_true, p)).norm(), kExactTolPx);
  EXPECT_NEAR(fit->H.norm(), 1.0, 1e-12);
  EXPECT_GE(fit->H(2, 2), 0.0);
}

TEST(HomographyTest, NoisyFitHasResidualOfTheNoiseAndRefinementHelps) {
  const Eigen::Matrix3d H_true = StationView();
  const std::vector<Eigen::Vector2d> src = GridPoints(9, 6, 0.05);
  std::vector<Eigen::Vector2d> dst = Project(H_true, src);
  std::mt19937 rng(7);
  constexpr double kSigmaPx = 0.5;
  std::normal_distribution<double> noise(0.0, kSigmaPx);
  for (Eigen::Vector2d& q : dst) q += Eigen::Vector2d(noise(rng), noise(rng));

  const std::optional<HomographyFit> dlt = FitHomography(src, dst, {.refine = false});
  const std::optional<HomographyFit> ml = FitHomography(src, dst);
  ASSERT_TRUE(dlt.has_value());
  ASSERT_TRUE(ml.has_value());
  // The ML fit minimises the sum of squares, so it is never worse than the DLT.
  EXPECT_LE(ml->rms_residual, dlt->rms_residual + 1e-12);
  // Residual RMS of a 2-D point with 8 parameters fitted out of 2n = 108 observations:
  // sigma * sqrt(2 (n - 4) / n) ~ 0.68 px; 20 % covers the sampling spread for n = 54.
  const double expected = kSigmaPx * std::sqrt(2.0 * (54 - 4) / 54.0);
  EXPECT_NEAR(ml->rms_residual, expected, 0.2 * expected);
  // The fitted map is close to the true one at the fitted points: for a least-squares fit of
  // 8 parameters the summed squared map error is about 8 sigma^2, so its RMS over the 54
  // points is sigma sqrt(8 / 54) ~ 0.19 px; twice that bounds the sampling spread.
  double sum_sq = 0.0;
  for (const Eigen::Vector2d& p : src) {
    sum_sq += (ApplyHomography(ml->H, p) - ApplyHomography(H_true, p)).squaredNorm();
  }
  EXPECT_LT(std::sqrt(sum_sq / 54.0), 2.0 * kSigmaPx * std::sqrt(8.0 / 54.0));
}

TEST(HomographyTest, RefusesBadInput) {
  const Eigen::Matrix3d H_true = StationView();
  const std::vector<Eigen::Vector2d> src = GridPoints(3, 3, 0.1);
  const std::vector<Eigen::Vector2d> dst = Project(H_true, src);
  // Too few points.
  EXPECT_FALSE(FitHomography(std::span(src).first(3), std::span(dst).first(3)).has_value());
  // Sizes differ.
  EXPECT_FALSE(FitHomography(std::span(src).first(5), std::span(dst).first(4)).has_value());
  // A NaN coordinate.
  std::vector<Eigen::Vector2d> bad = dst;
  bad[4].x() = std::nan("");
  EXPECT_FALSE(FitHomography(src, bad).has_value());
  // All source points on one line.
  const std::vector<Eigen::Vector2d> line = {{0, 0}, {1, 0}, {2, 0}, {3, 0}, {4, 0}};
  EXPECT_FALSE(FitHomography(line, Project(H_true, line)).has_value());
  // All destination points at one point.
  const std::vector<Eigen::Vector2d> same(src.size(), Eigen::Vector2d(5, 5));
  EXPECT_FALSE(FitHomography(src, same).has_value());
  // Destination points on one line: a rank-deficient map, not a view of a plane.
  std::vector<Eigen::Vector2d> flat;
  for (const Eigen::Vector2d& p : src) flat.emplace_back(100.0 * p.x() + 10.0 * p.y(), 7.0);
  EXPECT_FALSE(FitHomography(src, flat).has_value());
}

TEST(HomographyTest, ApplyAtInfinityIsNanAndResidualsReportIt) {
  Eigen::Matrix3d H = Eigen::Matrix3d::Identity();
  H(2, 0) = 1.0;  // w = x + 1: the source line x = -1 maps to infinity
  EXPECT_TRUE(ApplyHomography(H, Eigen::Vector2d(-1.0, 3.0)).array().isNaN().all());
  EXPECT_TRUE(ApplyHomography(H, Eigen::Vector2d(1.0, 3.0)).isApprox(Eigen::Vector2d(0.5, 1.5)));
  const std::vector<Eigen::Vector2d> src = {{1.0, 3.0}, {-1.0, 3.0}};
  const std::vector<Eigen::Vector2d> dst = {{0.5, 1.5}, {0.0, 0.0}};
  std::vector<double> residuals;
  EXPECT_TRUE(std::isinf(HomographyResiduals(H, src, dst, &residuals)));
  ASSERT_EQ(residuals.size(), 2u);
  EXPECT_EQ(residuals[0], 0.0);
  EXPECT_TRUE(std::isinf(residuals[1]));
}

}  // namespace
}  // namespace linecal

#include "detectors/common/ellipse.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "detectors/common/homography.h"

namespace linecal {
namespace {

constexpr double kPi = std::numbers::pi;
// Exact inputs: only double rounding (condition numbers ~1e3 at these sizes).
constexpr double kExactTolerance = 1e-8;

Ellipse MakeEllipse(double cx, double cy, double a, double b, double angle) {
  Ellipse e;
  e.centre = Eigen::Vector2d(cx, cy);
  e.semi_major = a;
  e.semi_minor = b;
  e.angle_rad = angle;
  return e;
}

std::vector<Eigen::Vector2d> Sample(const Ellipse& e, int n, double t0 = 0.0, double t1 = 2 * kPi) {
  std::vector<Eigen::Vector2d> points;
  for (int i = 0; i < n; ++i) points.push_back(e.PointAt(t0 + (t1 - t0) * i / n));
  return points;
}

void ExpectSameEllipse(const Ellipse& expected, const Ellipse& actual, double tolerance) {
  EXPECT_NEAR(actual.centre.x(), expected.centre.x(), tolerance);
  EXPECT_NEAR(actual.centre.y(), expected.centre.y(), tolerance);
  EXPECT_NEAR(actual.semi_major, expected.semi_major, tolerance);
  EXPECT_NEAR(actual.semi_minor, expected.semi_minor, tolerance);
  // The angle is defined modulo pi.
  const double d = std::remainder(actual.angle_rad - expected.angle_rad, kPi);
  EXPECT_NEAR(d, 0.0, tolerance);
}

TEST(EllipseTest, ConicRoundTripAndSign) {
  const Ellipse e = MakeEllipse(640.3, 351.7, 40.0, 25.0, 0.7);
  const Eigen::Matrix3d c = e.Conic();
  const std::optional<Ellipse> back = EllipseFromConic(c);
  ASSERT_TRUE(back.has_value());
  ExpectSameEllipse(e, *back, kExactTolerance);
  // Any scale and sign of the conic gives the same ellipse.
  const std::optional<Ellipse> negated = EllipseFromConic(-3.5 * c);
  ASSERT_TRUE(negated.has_value());
  ExpectSameEllipse(e, *negated, kExactTolerance);
  // Negative inside, positive outside, zero on the curve.
  const Eigen::Vector3d centre(e.centre.x(), e.centre.y(), 1.0);
  EXPECT_NEAR(centre.dot(c * centre), -1.0, kExactTolerance);
  const Eigen::Vector2d on = e.PointAt(1.1);
  EXPECT_NEAR(SampsonDistance(c, on), 0.0, kExactTolerance);
  // For a circle of radius 5, a point at distance 7: (49 - 25) / 14.
  const Ellipse circle = MakeEllipse(10.0, 20.0, 5.0, 5.0, 0.0);
  EXPECT_NEAR(SampsonDistance(circle.Conic(), Eigen::Vector2d(17.0, 20.0)), 24.0 / 14.0,
              kExactTolerance);
}

TEST(EllipseTest, RejectsNonEllipses) {
  Eigen::Matrix3d hyperbola;  // x^2 - y^2 - 1
  hyperbola << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  EXPECT_FALSE(EllipseFromConic(hyperbola).has_value());
  Eigen::Matrix3d imaginary;  // x^2 + y^2 + 1
  imaginary << 1, 0, 0, 0, 1, 0, 0, 0, 1;
  EXPECT_FALSE(EllipseFromConic(imaginary).has_value());
  Eigen::Matrix3d parabola;  // x^2 - y
  parabola << 1, 0, 0, 0, 0, -0.5, 0, -0.5, 0;
  EXPECT_FALSE(EllipseFromConic(parabola).has_value());
  Eigen::Matrix3d nan = Eigen::Matrix3d::Identity();
  nan(0, 0) = std::nan("");
  EXPECT_FALSE(EllipseFromConic(nan).has_value());
}

TEST(EllipseTest, FitsExactPointsOfManyEllipses) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> position(0.0, 2000.0);
  std::uniform_real_distribution<double> axis(3.0, 200.0);
  std::uniform_real_distribution<double> ratio(0.2, 1.0);
  std::uniform_real_distribution<double> angle(-1.5, 1.5);
  for (int trial = 0; trial < 100; ++trial) {
    const double a = axis(rng);
    const Ellipse e = MakeEllipse(position(rng), position(rng), a, a * ratio(rng), angle(rng));
    const std::optional<Ellipse> fit = FitEllipse(Sample(e, 24));
    ASSERT_TRUE(fit.has_value()) << trial;
    // Near-circles have an ill-defined angle; compare the conics' shape instead.
    EXPECT_NEAR(fit->centre.x(), e.centre.x(), 1e-6 * a);
    EXPECT_NEAR(fit->centre.y(), e.centre.y(), 1e-6 * a);
    EXPECT_NEAR(fit->semi_major, e.semi_major, 1e-6 * a);
    EXPECT_NEAR(fit->semi_minor, e.semi_minor, 1e-6 * a);
  }
}

TEST(EllipseTest, FitOfNoisyPointsKeepsTheCentre) {
  // 64 edge points with 0.1 px noise, as from a sub-pixel edge detector on a 20 px ellipse.
  const Ellipse e = MakeEllipse(100.25, 50.75, 20.0, 12.0, 0.4);
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.1);
  std::vector<Eigen::Vector2d> points = Sample(e, 64);
  for (Eigen::Vector2d& p : points) p += Eigen::Vector2d(noise(rng), noise(rng));
  const std::optional<Ellipse> fit = FitEllipse(points);
  ASSERT_TRUE(fit.has_value());
  // The centre's standard error is about 0.1 / sqrt(64 / 2) = 0.018 px: allow 3 sigma.
  constexpr double kCentreTolerancePx = 0.055;
  EXPECT_NEAR(fit->centre.x(), e.centre.x(), kCentreTolerancePx);
  EXPECT_NEAR(fit->centre.y(), e.centre.y(), kCentreTolerancePx);
}

TEST(EllipseTest, WeightsRemoveOutliers) {
  const Ellipse e = MakeEllipse(300.0, 200.0, 30.0, 18.0, -0.3);
  std::vector<Eigen::Vector2d> points = Sample(e, 40);
  std::vector<double> weights(points.size(), 1.0);
  points[5] += Eigen::Vector2d(8.0, -6.0);
  weights[5] = 0.0;
  const std::optional<Ellipse> fit = FitEllipse(points, weights);
  ASSERT_TRUE(fit.has_value());
  ExpectSameEllipse(e, *fit, 1e-6);
}

TEST(EllipseTest, FitRejectsDegenerateInput) {
  std::vector<Eigen::Vector2d> line;
  for (int i = 0; i < 10; ++i) line.emplace_back(i, 2.0 * i + 1.0);
  EXPECT_FALSE(FitEllipse(line).has_value());
  const Ellipse e = MakeEllipse(0.0, 0.0, 5.0, 3.0, 0.0);
  EXPECT_FALSE(FitEllipse(Sample(e, 4)).has_value());
  std::vector<Eigen::Vector2d> with_nan = Sample(e, 10);
  with_nan[3].x() = std::nan("");
  EXPECT_FALSE(FitEllipse(with_nan).has_value());
  const std::vector<double> wrong_size_weights(3, 1.0);
  EXPECT_FALSE(FitEllipse(Sample(e, 10), wrong_size_weights).has_value());
}

TEST(EllipseTest, MomentsOfAFilledEllipse) {
  // Rasterise an ellipse on a fine grid and compare its moment ellipse with the truth.
  const Ellipse e = MakeEllipse(0.0, 0.0, 40.0, 15.0, 0.5);
  const Eigen::Matrix3d c = e.Conic();
  double area = 0.0;
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  Eigen::Matrix2d second = Eigen::Matrix2d::Zero();
  constexpr double kStep = 0.25;
  for (double y = -45; y <= 45; y += kStep) {
    for (double x = -45; x <= 45; x += kStep) {
      const Eigen::Vector3d p(x, y, 1.0);
      if (p.dot(c * p) >= 0.0) continue;
      area += 1.0;
      sum += p.head<2>();
      second += p.head<2>() * p.head<2>().transpose();
    }
  }
  const Eigen::Vector2d centroid = sum / area;
  const Eigen::Matrix2d covariance = second / area - centroid * centroid.transpose();
  const std::optional<Ellipse> m = EllipseFromMoments(centroid, covariance);
  ASSERT_TRUE(m.has_value());
  // Sampling on a 0.25 grid: the axes come out within a fraction of the step.
  ExpectSameEllipse(e, *m, 0.05);
  EXPECT_FALSE(EllipseFromMoments(centroid, Eigen::Matrix2d::Zero()).has_value());
}

TEST(EllipseTest, ImageOfCircleUnderPerspective) {
  // A 25 mm circle on a board turned 45 degrees about y, 1.2 m from a 1000 px camera.
  Eigen::Matrix3d K;
  K << 1000.0, 0.0, 640.0, 0.0, 1000.0, 360.0, 0.0, 0.0, 1.0;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(kPi / 4, Eigen::Vector3d::UnitY()).toRotationMatrix();
  Eigen::Matrix3d Rt;
  Rt.col(0) = R.col(0);
  Rt.col(1) = -R.col(1);
  Rt.col(2) = Eigen::Vector3d(0.0, 0.0, 1.2);
  const Eigen::Matrix3d H = K * Rt;
  const Eigen::Vector2d centre(0.2, 0.05);
  const double radius = 0.025;
  const Eigen::Matrix3d conic = ImageOfCircle(H, centre, radius);
  for (int i = 0; i < 16; ++i) {
    const double t = 2 * kPi * i / 16;
    const Eigen::Vector2d p =
        ApplyHomography(H, centre + radius * Eigen::Vector2d(std::cos(t), std::sin(t)));
    EXPECT_LT(SampsonDistance(conic, p), 1e-9);
  }
  const std::optional<Ellipse> e = EllipseFromConic(conic);
  ASSERT_TRUE(e.has_value());
  // The ellipse's centre is not the projected centre: the shift is a sizeable fraction of a
  // pixel here (the reason circle detectors must correct it).
  const double shift = (e->centre - ApplyHomography(H, centre)).norm();
  EXPECT_GT(shift, 0.1);
  EXPECT_LT(shift, 2.0);
}

}  // namespace
}  // namespace linecal

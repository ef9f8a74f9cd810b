#include "station/camera/camera_model.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "detectors/core/image_view.h"
#include "tests/support/reference_cameras.h"

namespace linecal {
namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kPi = std::numbers::pi;

// The bars for the round trips over the image.
constexpr double kPixelRoundTripPx = 1e-9;
constexpr double kRayRoundTripRad = 1e-12;
// A unit vector computed in double is unit to a few ulps.
constexpr double kUnitNormTolerance = 1e-15;
// Closed-form valid regions against the companion-matrix roots: eigenvalues of a small
// companion matrix are accurate to ~1e-14 relative for simple roots.
constexpr double kRootTolerance = 1e-12;

// Central differences with relative step h = 1e-6 (1 + |value|): the truncation error
// h² f''' / 6 is ~1e-12 relative for curvature of order one (1e-6 leaves room for the
// high powers of strong distortion near the image corners), and rounding adds the error of
// two projections divided by 2h.
constexpr double kNumericStepRelative = 1e-6;
constexpr double kNumericJacobianRelative = 1e-6;
// Rounding of one projection: a few tens of ulps of coordinates up to 2000 px, ~1e-11 px.
constexpr double kProjectionRoundingPx = 1e-10;
// The analytic Jacobian and autodiff through the templated core evaluate the same
// derivatives with different rounding: they agree to rounding, far below this.
constexpr double kAutodiffJacobianRelative = 1e-10;
// The analytic projection and the templated core round differently (x / r * theta_d vs
// theta_d / r * x): a few ulps of coordinates up to 2000 px.
constexpr double kTemplateValuePx = 1e-11;

// Realistic cameras of the reference car (docs/acceptance.md).
using reference_cameras::Fisheye190;
using reference_cameras::MildPinhole;
using reference_cameras::StrongPinhole;

CameraModel MakeModel(const CameraIntrinsics& c) {
  absl::StatusOr<CameraModel> model = CameraModel::Create(c);
  EXPECT_TRUE(model.ok()) << model.status();
  return *model;
}

struct NamedCamera {
  const char* name;
  CameraIntrinsics intrinsics;
};

std::vector<NamedCamera> ReferenceCameras() {
  return {{"mild pinhole", MildPinhole()},
          {"strong pinhole", StrongPinhole()},
          {"fisheye 190", Fisheye190()}};
}

double AngleBetween(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

// Pixel centres every 8 px plus the last one, and the outer edges of the image area.
std::vector<double> GridCoordinates(int side) {
  std::vector<double> values = {-0.5};
  for (int i = 0; i < side - 1; i += 8) values.push_back(i);
  values.push_back(side - 1);
  values.push_back(side - 0.5);
  return values;
}

// ---------------------------------------------------------------- validation

struct BadIntrinsics {
  std::string field;
  std::function<void(CameraIntrinsics&)> mutate;
  CameraIntrinsics base = MildPinhole();
};

TEST(CameraIntrinsicsTest, ReferenceCamerasAreValid) {
  for (const NamedCamera& camera : ReferenceCameras()) {
    EXPECT_TRUE(camera.intrinsics.Validate().ok()) << camera.name;
    EXPECT_TRUE(CameraModel::Create(camera.intrinsics).ok()) << camera.name;
  }
}

TEST(CameraIntrinsicsTest, InvalidFieldsAreNamed) {
  const std::vector<BadIntrinsics> cases = {
      {"type", [](CameraIntrinsics& c) { c.type = static_cast<CameraModelType>(7); }},
      {"width", [](CameraIntrinsics& c) { c.width = 0; }},
      {"width", [](CameraIntrinsics& c) { c.width = -1920; }},
      {"width", [](CameraIntrinsics& c) { c.width = kMaxImageSide + 1; }},
      {"height", [](CameraIntrinsics& c) { c.height = 0; }},
      {"height", [](CameraIntrinsics& c) { c.height = kMaxImageSide + 1; }},
      {"fx", [](CameraIntrinsics& c) { c.fx = 0.0; }},
      {"fx", [](CameraIntrinsics& c) { c.fx = -2000.0; }},
      {"fx", [](CameraIntrinsics& c) { c.fx = kNan; }},
      {"fx", [](CameraIntrinsics& c) { c.fx = kInf; }},
      {"fy", [](CameraIntrinsics& c) { c.fy = -1.0; }},
      {"fy", [](CameraIntrinsics& c) { c.fy = kNan; }},
      {"cx", [](CameraIntrinsics& c) { c.cx = kNan; }},
      {"cx", [](CameraIntrinsics& c) { c.cx = -0.6; }},
      {"cx", [](CameraIntrinsics& c) { c.cx = 1919.6; }},
      {"cy", [](CameraIntrinsics& c) { c.cy = 1079.6; }},
      {"cy", [](CameraIntrinsics& c) { c.cy = -kInf; }},
      {"k1", [](CameraIntrinsics& c) { c.k1 = kNan; }},
      {"k2", [](CameraIntrinsics& c) { c.k2 = kInf; }},
      {"k3", [](CameraIntrinsics& c) { c.k3 = -kInf; }},
      {"p1", [](CameraIntrinsics& c) { c.p1 = kNan; }},
      {"p2", [](CameraIntrinsics& c) { c.p2 = kNan; }},
      {"k4", [](CameraIntrinsics& c) { c.k4 = 0.01; }},
      {"k4", [](CameraIntrinsics& c) { c.k4 = kNan; }, Fisheye190()},
      {"p1", [](CameraIntrinsics& c) { c.p1 = 1e-3; }, Fisheye190()},
      {"p2", [](CameraIntrinsics& c) { c.p2 = -1e-3; }, Fisheye190()},
  };
  for (const BadIntrinsics& bad : cases) {
    CameraIntrinsics c = bad.base;
    bad.mutate(c);
    const absl::Status status = c.Validate();
    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << bad.field;
    EXPECT_EQ(std::string(status.message()).rfind(bad.field + " = ", 0), 0u)
        << "expected the message to start with '" << bad.field << " = ': " << status.message();
    const absl::StatusOr<CameraModel> model = CameraModel::Create(c);
    EXPECT_EQ(model.status(), status) << bad.field;
  }
}

TEST(CameraIntrinsicsTest, EdgesOfTheValidRangesAreAccepted) {
  CameraIntrinsics c = MildPinhole();
  c.width = kMaxImageSide;
  c.height = 1;
  c.cx = -0.5;
  c.cy = 0.5;
  EXPECT_TRUE(c.Validate().ok()) << c.Validate();
  c.cx = kMaxImageSide - 0.5;
  EXPECT_TRUE(c.Validate().ok()) << c.Validate();
}

TEST(CameraParametersTest, RoundTripAndNames) {
  for (const NamedCamera& camera : ReferenceCameras()) {
    const CameraIntrinsics& c = camera.intrinsics;
    const CameraParameters p = ToCameraParameters(c);
    ASSERT_EQ(p.size(), CameraParameterCount(c.type)) << camera.name;
    const CameraIntrinsics back =
        CameraIntrinsicsFromParameters(c.type, c.width, c.height, p.data());
    EXPECT_EQ(ToCameraParameters(back), p) << camera.name;
    EXPECT_EQ(back.k4, c.k4);
    EXPECT_EQ(back.p1, c.p1);
    EXPECT_EQ(back.p2, c.p2);
    EXPECT_EQ(back.width, c.width);
  }
  const CameraParameters pinhole = ToCameraParameters(StrongPinhole());
  EXPECT_EQ(pinhole[6], StrongPinhole().p1);
  EXPECT_EQ(pinhole[8], StrongPinhole().k3);
  EXPECT_STREQ(CameraParameterName(CameraModelType::kPinhole, 6), "p1");
  EXPECT_STREQ(CameraParameterName(CameraModelType::kPinhole, 8), "k3");
  EXPECT_STREQ(CameraParameterName(CameraModelType::kFisheye, 6), "k3");
  EXPECT_STREQ(CameraParameterName(CameraModelType::kFisheye, 7), "k4");
  EXPECT_STREQ(CameraParameterName(CameraModelType::kFisheye, 8), "");
  EXPECT_STREQ(CameraParameterName(CameraModelType::kPinhole, -1), "");
  EXPECT_STREQ(CameraModelTypeName(CameraModelType::kFisheye), "fisheye");
}

// ---------------------------------------------------------------- basic geometry

TEST(CameraModelTest, OpticalAxisMapsToPrincipalPoint) {
  for (const NamedCamera& camera : ReferenceCameras()) {
    const CameraModel model = MakeModel(camera.intrinsics);
    for (const double depth : {1e-6, 1.0, 7.5, 1e6}) {
      Eigen::Vector2d uv;
      ASSERT_TRUE(model.Project(Eigen::Vector3d(0, 0, depth), &uv)) << camera.name;
      EXPECT_EQ(uv.x(), camera.intrinsics.cx) << camera.name;
      EXPECT_EQ(uv.y(), camera.intrinsics.cy) << camera.name;
    }
    Eigen::Vector3d ray;
    ASSERT_TRUE(model.Unproject(Eigen::Vector2d(camera.intrinsics.cx, camera.intrinsics.cy), &ray));
    EXPECT_EQ(ray, Eigen::Vector3d::UnitZ()) << camera.name;
  }
}

TEST(CameraModelTest, UndistortedPinholeIsThePinholeFormula) {
  CameraIntrinsics c = MildPinhole();
  c.k1 = c.k2 = c.k3 = c.p1 = c.p2 = 0.0;
  const CameraModel model = MakeModel(c);
  EXPECT_EQ(model.max_angle_rad(), kPi / 2);
  Eigen::Vector2d uv;
  ASSERT_TRUE(model.Project(Eigen::Vector3d(0.3, -0.2, 2.0), &uv));
  EXPECT_NEAR(uv.x(), c.cx + c.fx * 0.15, 1e-12 * c.fx);
  EXPECT_NEAR(uv.y(), c.cy - c.fy * 0.1, 1e-12 * c.fy);
  // Up to 90 degrees off axis is still valid, however far outside the image it lands.
  ASSERT_TRUE(model.Project(Eigen::Vector3d(1.0, 0.0, 1e-3), &uv));
  EXPECT_NEAR(uv.x(), c.cx + c.fx * 1e3, 1e-12 * c.fx * 1e3);
  EXPECT_FALSE(model.IsInImage(uv));
}

TEST(CameraModelTest, EquidistantFisheyeIsTheAngleTimesFocalLength) {
  CameraIntrinsics c = Fisheye190();
  c.k1 = c.k2 = c.k3 = c.k4 = 0.0;
  const CameraModel model = MakeModel(c);
  EXPECT_EQ(model.max_angle_rad(), kPi);
  // 120 degrees off axis, azimuth 30 degrees from +x towards +y.
  const double theta = 2 * kPi / 3;
  const double phi = kPi / 6;
  const Eigen::Vector3d p(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                          std::cos(theta));
  Eigen::Vector2d uv;
  ASSERT_TRUE(model.Project(5.0 * p, &uv));
  EXPECT_NEAR(uv.x(), c.cx + c.fx * theta * std::cos(phi), 1e-12 * c.fx);
  EXPECT_NEAR(uv.y(), c.cy + c.fy * theta * std::sin(phi), 1e-12 * c.fy);
  Eigen::Vector3d ray;
  ASSERT_TRUE(model.Unproject(uv, &ray));
  EXPECT_LT(AngleBetween(ray, p), kRayRoundTripRad);
  // The negative axis has no azimuth; just off it is still valid.
  EXPECT_FALSE(model.Project(Eigen::Vector3d(0, 0, -1), &uv));
  EXPECT_TRUE(model.Project(Eigen::Vector3d(1e-3, 0, -1), &uv));
}

TEST(CameraModelTest, ImageAreaIncludesHalfPixelBorder) {
  const CameraModel model = MakeModel(MildPinhole());
  EXPECT_TRUE(model.IsInImage({-0.5, -0.5}));
  EXPECT_TRUE(model.IsInImage({1919.5, 1079.5}));
  EXPECT_FALSE(model.IsInImage({-0.51, 10}));
  EXPECT_FALSE(model.IsInImage({10, 1079.51}));
  EXPECT_FALSE(model.IsInImage({kNan, 10}));
}

// ---------------------------------------------------------------- refusals

TEST(CameraModelTest, PinholeRefusesPointsBehindOrBesideTheCamera) {
  const CameraModel model = MakeModel(StrongPinhole());
  const Eigen::Vector2d sentinel(-7, -7);
  for (const Eigen::Vector3d& p :
       {Eigen::Vector3d(0, 0, -1), Eigen::Vector3d(0.1, 0.2, -5), Eigen::Vector3d(1, 2, 0),
        Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(kNan, 0, 1), Eigen::Vector3d(0, kInf, 1),
        Eigen::Vector3d(0, 0, -0.0)}) {
    Eigen::Vector2d uv = sentinel;
    ProjectionPointJacobian j = ProjectionPointJacobian::Constant(-7);
    EXPECT_FALSE(model.Project(p, &uv, &j)) << p.transpose();
    EXPECT_EQ(uv, sentinel);
    EXPECT_EQ(j, ProjectionPointJacobian::Constant(-7));
  }
}

TEST(CameraModelTest, FisheyeRefusesPointsBeyondTheValidAngle) {
  const CameraModel model = MakeModel(Fisheye190());
  const double max_angle = model.max_angle_rad();
  // The reference fisheye folds at about 138 degrees, well outside its image corners.
  EXPECT_GT(max_angle, 130 * kPi / 180);
  EXPECT_LT(max_angle, 140 * kPi / 180);
  const auto direction = [](double theta, double phi) {
    return Eigen::Vector3d(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                           std::cos(theta));
  };
  Eigen::Vector2d uv;
  for (const double phi : {0.0, 1.0, 2.5, -2.0}) {
    EXPECT_TRUE(model.Project(direction(max_angle - 1e-6, phi), &uv)) << phi;
    EXPECT_FALSE(model.Project(direction(max_angle + 1e-6, phi), &uv)) << phi;
  }
  EXPECT_FALSE(model.Project(Eigen::Vector3d(0, 0, -1), &uv));
  EXPECT_FALSE(model.Project(Eigen::Vector3d::Zero(), &uv));
  EXPECT_FALSE(model.Project(Eigen::Vector3d(kNan, 0, 1), &uv));
}

TEST(CameraModelTest, UnprojectRefusesNonFinitePixels) {
  for (const NamedCamera& camera : ReferenceCameras()) {
    const CameraModel model = MakeModel(camera.intrinsics);
    Eigen::Vector3d ray(-7, -7, -7);
    EXPECT_FALSE(model.Unproject({kNan, 100}, &ray)) << camera.name;
    EXPECT_FALSE(model.Unproject({100, kInf}, &ray)) << camera.name;
    EXPECT_EQ(ray, Eigen::Vector3d(-7, -7, -7));
  }
}

// ---------------------------------------------------------------- valid regions

// k1 = -0.5 alone: r_d = r (1 - r²/2) peaks at r² = 2/3 and folds back beyond it, so two
// rays would share each pixel just inside the peak radius.
TEST(CameraModelValidRegionTest, PinholeRadialFoldClosedForm) {
  CameraIntrinsics c = MildPinhole();
  c.k1 = -0.5;
  c.k2 = c.k3 = c.p1 = c.p2 = 0.0;
  const CameraModel model = MakeModel(c);
  const double max_r = std::sqrt(2.0 / 3.0);
  EXPECT_NEAR(model.max_angle_rad(), std::atan(max_r), kRootTolerance);
  const double peak_r_d = max_r * (1.0 - 0.5 * max_r * max_r);

  // A point beyond the fold lands where a point inside it does: it must be refused.
  const double beyond = 1.1 * max_r;
  const double beyond_r_d = beyond * (1.0 - 0.5 * beyond * beyond);
  Eigen::Vector2d uv;
  EXPECT_FALSE(model.Project(Eigen::Vector3d(beyond, 0, 1), &uv));
  EXPECT_TRUE(model.Project(Eigen::Vector3d(0.999 * max_r, 0, 1), &uv));
  Eigen::Vector3d ray;
  ASSERT_TRUE(model.Unproject({c.cx + c.fx * beyond_r_d, c.cy}, &ray));
  EXPECT_LT(std::atan2(ray.head<2>().norm(), ray.z()), model.max_angle_rad());

  // Pixels beyond the peak distorted radius have no ray at all.
  EXPECT_TRUE(model.Unproject({c.cx + c.fx * 0.999 * peak_r_d, c.cy}, &ray));
  EXPECT_FALSE(model.Unproject({c.cx + c.fx * 1.001 * peak_r_d, c.cy}, &ray));
  EXPECT_FALSE(model.Unproject({c.cx, c.cy - c.fy * 1.001 * peak_r_d}, &ray));
}

// The radial eigenvalue 1 + 3 k1 r² + 5 k2 r⁴ is 1 - 6 r² + 5 r⁴ = (1 - r²)(1 - 5 r²) for
// k1 = -2, k2 = 1: first zero at r² = 1/5 (the tangential-direction one, 1 - 2 r² + r⁴,
// only touches zero at r = 1).
TEST(CameraModelValidRegionTest, PinholeFirstOfSeveralRoots) {
  CameraIntrinsics c = MildPinhole();
  c.k1 = -2.0;
  c.k2 = 1.0;
  c.k3 = c.p1 = c.p2 = 0.0;
  EXPECT_NEAR(MakeModel(c).max_angle_rad(), std::atan(std::sqrt(0.2)), kRootTolerance);
}

// With tangential distortion alone the bound is 1 - 6 |p| r.
TEST(CameraModelValidRegionTest, PinholeTangentialBound) {
  CameraIntrinsics c = MildPinhole();
  c.k1 = c.k2 = c.k3 = 0.0;
  c.p1 = 3e-3;
  c.p2 = -4e-3;
  EXPECT_NEAR(MakeModel(c).max_angle_rad(), std::atan(1.0 / (6.0 * 5e-3)), kRootTolerance);
}

// A pinhole whose polynomial never folds is valid up to 90 degrees.
TEST(CameraModelValidRegionTest, PinholeWithoutFold) {
  CameraIntrinsics c = MildPinhole();
  c.k1 = -0.3;
  c.k2 = 0.09;
  c.k3 = c.p1 = c.p2 = 0.0;
  EXPECT_EQ(MakeModel(c).max_angle_rad(), kPi / 2);
}

// k1 = -0.1 alone: d theta_d / d theta = 1 - 0.3 theta² vanishes at theta = sqrt(1 / 0.3).
TEST(CameraModelValidRegionTest, FisheyeFoldClosedForm) {
  CameraIntrinsics c = Fisheye190();
  c.k1 = -0.1;
  c.k2 = c.k3 = c.k4 = 0.0;
  const CameraModel model = MakeModel(c);
  const double max_theta = std::sqrt(1.0 / 0.3);
  EXPECT_NEAR(model.max_angle_rad(), max_theta, kRootTolerance);
  const double peak_theta_d = max_theta * (1.0 - 0.1 * max_theta * max_theta);
  Eigen::Vector3d ray;
  ASSERT_TRUE(model.Unproject({c.cx + c.fx * 0.999 * peak_theta_d, c.cy}, &ray));
  EXPECT_LT(std::atan2(ray.head<2>().norm(), ray.z()), max_theta);
  EXPECT_LT(ray.z(), 0.0);  // 105 degrees off axis
  EXPECT_FALSE(model.Unproject({c.cx + c.fx * 1.001 * peak_theta_d, c.cy}, &ray));
}

// The whole image of each reference camera lies inside its valid region, and the fisheye
// sees about 190 degrees across its width.
TEST(CameraModelValidRegionTest, ReferenceCamerasAreValidOverTheirImages) {
  for (const NamedCamera& camera : ReferenceCameras()) {
    const CameraModel model = MakeModel(camera.intrinsics);
    const CameraIntrinsics& c = camera.intrinsics;
    std::printf("%s: valid up to %.3f deg off axis\n", camera.name,
                model.max_angle_rad() * 180 / kPi);
    for (const double u : {-0.5, c.width - 0.5}) {
      for (const double v : {-0.5, c.height - 0.5}) {
        Eigen::Vector3d ray;
        EXPECT_TRUE(model.Unproject({u, v}, &ray)) << camera.name << " " << u << "," << v;
      }
    }
  }
  const CameraModel fisheye = MakeModel(Fisheye190());
  Eigen::Vector3d left, right;
  ASSERT_TRUE(fisheye.Unproject({-0.5, Fisheye190().cy}, &left));
  ASSERT_TRUE(fisheye.Unproject({1279.5, Fisheye190().cy}, &right));
  const double fov_deg =
      (std::atan2(-left.x(), left.z()) + std::atan2(right.x(), right.z())) * 180 / kPi;
  EXPECT_GT(fov_deg, 185.0);
  EXPECT_LT(fov_deg, 195.0);
}

// ---------------------------------------------------------------- round trips

TEST(CameraModelRoundTripTest, PixelRayPixelOverTheWholeImage) {
  for (const NamedCamera& camera : ReferenceCameras()) {
    const CameraModel model = MakeModel(camera.intrinsics);
    double max_pixel_error = 0.0;
    double max_ray_error = 0.0;
    int count = 0;
    for (const double v : GridCoordinates(camera.intrinsics.height)) {
      for (const double u : GridCoordinates(camera.intrinsics.width)) {
        const Eigen::Vector2d uv(u, v);
        Eigen::Vector3d ray;
        ASSERT_TRUE(model.Unproject(uv, &ray)) << camera.name << " at " << u << "," << v;
        EXPECT_NEAR(ray.norm(), 1.0, kUnitNormTolerance);
        Eigen::Vector2d uv_back;
        ASSERT_TRUE(model.Project(ray, &uv_back)) << camera.name << " at " << u << "," << v;
        max_pixel_error = std::max(max_pixel_error, (uv_back - uv).norm());
        // And ray -> pixel -> ray from the ray of this pixel.
        Eigen::Vector3d ray_back;
        ASSERT_TRUE(model.Unproject(uv_back, &ray_back));
        max_ray_error = std::max(max_ray_error, AngleBetween(ray, ray_back));
        ++count;
      }
    }
    std::printf("%s: %d grid pixels, pixel->ray->pixel max %.3g px, ray->pixel->ray max %.3g rad\n",
                camera.name, count, max_pixel_error, max_ray_error);
    EXPECT_LE(max_pixel_error, kPixelRoundTripPx) << camera.name;
    EXPECT_LE(max_ray_error, kRayRoundTripRad) << camera.name;
  }
}

// Rays drawn uniformly on the sphere (independent of the pixel grid) that land in the image.
TEST(CameraModelRoundTripTest, RandomRaysThroughTheImage) {
  std::mt19937 rng(20240611);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (const NamedCamera& camera : ReferenceCameras()) {
    const CameraModel model = MakeModel(camera.intrinsics);
    double max_ray_error = 0.0;
    int in_image = 0;
    for (int i = 0; i < 200000; ++i) {
      const Eigen::Vector3d ray =
          Eigen::Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
      Eigen::Vector2d uv;
      if (!model.Project(ray, &uv) || !model.IsInImage(uv)) continue;
      Eigen::Vector3d ray_back;
      ASSERT_TRUE(model.Unproject(uv, &ray_back)) << camera.name << " " << ray.transpose();
      max_ray_error = std::max(max_ray_error, AngleBetween(ray, ray_back));
      ++in_image;
    }
    std::printf("%s: %d random rays in the image, ray->pixel->ray max %.3g rad\n", camera.name,
                in_image, max_ray_error);
    // 200000 rays cover the smallest field of view (the mild pinhole's ~50 x 30 degrees,
    // about 3% of the sphere) with thousands of samples.
    EXPECT_GT(in_image, 3000) << camera.name;
    EXPECT_LE(max_ray_error, kRayRoundTripRad) << camera.name;
  }
}

TEST(CameraModelRoundTripTest, FisheyeRaysBeyondNinetyDegrees) {
  const CameraModel model = MakeModel(Fisheye190());
  for (const double theta_deg : {91.0, 100.0, 110.0, 119.0}) {
    const double theta = theta_deg * kPi / 180;
    const Eigen::Vector3d ray(std::sin(theta) * std::cos(0.3), std::sin(theta) * std::sin(0.3),
                              std::cos(theta));
    Eigen::Vector2d uv;
    ASSERT_TRUE(model.Project(ray, &uv)) << theta_deg;
    Eigen::Vector3d ray_back;
    ASSERT_TRUE(model.Unproject(uv, &ray_back)) << theta_deg;
    EXPECT_LT(ray_back.z(), 0.0);
    EXPECT_LE(AngleBetween(ray, ray_back), kRayRoundTripRad) << theta_deg;
  }
}

// ---------------------------------------------------------------- Jacobians

// A forward-mode dual number with N derivatives: just enough arithmetic for the templated
// projections (what ceres::Jet provides), so the test needs no Ceres.
template <int N>
struct Dual {
  using Gradient = Eigen::Matrix<double, N, 1>;
  double a = 0.0;
  Gradient v = Gradient::Zero();

  Dual() = default;
  explicit Dual(double value) : a(value) {}
  Dual(double value, const Gradient& gradient) : a(value), v(gradient) {}
  static Dual Variable(double value, int index) {
    Dual d(value);
    d.v[index] = 1.0;
    return d;
  }
};

template <int N>
Dual<N> operator+(const Dual<N>& f, const Dual<N>& g) {
  return {f.a + g.a, f.v + g.v};
}
template <int N>
Dual<N> operator-(const Dual<N>& f, const Dual<N>& g) {
  return {f.a - g.a, f.v - g.v};
}
template <int N>
Dual<N> operator*(const Dual<N>& f, const Dual<N>& g) {
  return {f.a * g.a, g.a * f.v + f.a * g.v};
}
template <int N>
Dual<N> operator/(const Dual<N>& f, const Dual<N>& g) {
  return {f.a / g.a, (f.v - (f.a / g.a) * g.v) / g.a};
}
template <int N>
bool operator<(const Dual<N>& f, const Dual<N>& g) {
  return f.a < g.a;
}
template <int N>
bool operator>(const Dual<N>& f, const Dual<N>& g) {
  return f.a > g.a;
}
template <int N>
Dual<N> sqrt(const Dual<N>& f) {
  const double s = std::sqrt(f.a);
  return {s, f.v / (2.0 * s)};
}
template <int N>
Dual<N> atan2(const Dual<N>& y, const Dual<N>& x) {
  const double n2 = x.a * x.a + y.a * y.a;
  return {std::atan2(y.a, x.a), (x.a * y.v - y.a * x.v) / n2};
}

constexpr int kDualSize = 3 + kMaxCameraParameterCount;
using Jet = Dual<kDualSize>;

// Value and Jacobians of the templated core, by autodiff.
void AutodiffProjection(const CameraModel& model, const Eigen::Vector3d& p, Eigen::Vector2d* uv,
                        ProjectionPointJacobian* d_uv_d_p,
                        ProjectionParameterJacobian* d_uv_d_parameters) {
  const int n = CameraParameterCount(model.type());
  Jet point[3];
  for (int i = 0; i < 3; ++i) point[i] = Jet::Variable(p[i], i);
  Jet parameters[kMaxCameraParameterCount];
  for (int i = 0; i < n; ++i) parameters[i] = Jet::Variable(model.parameters()[i], 3 + i);
  Jet out[2];
  if (model.type() == CameraModelType::kPinhole) {
    ProjectPinhole(parameters, point, out);
  } else {
    ProjectFisheye(parameters, point, out);
  }
  d_uv_d_parameters->resize(2, n);
  for (int r = 0; r < 2; ++r) {
    (*uv)[r] = out[r].a;
    d_uv_d_p->row(r) = out[r].v.head<3>().transpose();
    d_uv_d_parameters->row(r) = out[r].v.segment(3, n).transpose();
  }
}

// Central differences of CameraModel::Project; steps per column in *steps.
void NumericJacobians(const CameraModel& model, const Eigen::Vector3d& p,
                      ProjectionPointJacobian* d_uv_d_p,
                      ProjectionParameterJacobian* d_uv_d_parameters, Eigen::Vector3d* point_steps,
                      CameraParameters* parameter_steps) {
  const auto project = [](const CameraModel& m, const Eigen::Vector3d& q) {
    Eigen::Vector2d uv;
    EXPECT_TRUE(m.Project(q, &uv)) << q.transpose();
    return uv;
  };
  for (int i = 0; i < 3; ++i) {
    const double h = kNumericStepRelative * (1.0 + p.norm());
    (*point_steps)[i] = h;
    Eigen::Vector3d plus = p, minus = p;
    plus[i] += h;
    minus[i] -= h;
    d_uv_d_p->col(i) = (project(model, plus) - project(model, minus)) / (2 * h);
  }
  const CameraIntrinsics& c = model.intrinsics();
  const int n = CameraParameterCount(c.type);
  d_uv_d_parameters->resize(2, n);
  parameter_steps->resize(n);
  for (int i = 0; i < n; ++i) {
    const double h = kNumericStepRelative * (1.0 + std::abs(model.parameters()[i]));
    (*parameter_steps)[i] = h;
    CameraParameters plus = model.parameters(), minus = model.parameters();
    plus[i] += h;
    minus[i] -= h;
    const CameraModel model_plus =
        MakeModel(CameraIntrinsicsFromParameters(c.type, c.width, c.height, plus.data()));
    const CameraModel model_minus =
        MakeModel(CameraIntrinsicsFromParameters(c.type, c.width, c.height, minus.data()));
    d_uv_d_parameters->col(i) = (project(model_plus, p) - project(model_minus, p)) / (2 * h);
  }
}

// Column i of `actual` must match `expected` to relative * |expected_i| + absolute_px / steps[i]:
// the pixel change the two predict for a change steps[i] of variable i agrees to that
// relative error or to absolute_px.
template <typename Matrix, typename Steps>
void ExpectColumnsNear(const Matrix& actual, const Matrix& expected, const Steps& steps,
                       double relative, double absolute_px, const std::string& what) {
  ASSERT_EQ(actual.cols(), expected.cols()) << what;
  for (int i = 0; i < actual.cols(); ++i) {
    const double error = (actual.col(i) - expected.col(i)).norm();
    EXPECT_LE(error, relative * expected.col(i).norm() + absolute_px / steps[i])
        << what << ", column " << i << ": actual " << actual.col(i).transpose() << ", expected "
        << expected.col(i).transpose();
  }
}

// Points across each image at depths 0.5-30 m, plus the optical axis, points next to it
// (the fisheye's axis limit and just outside it) and, for the fisheye, beyond 90 degrees.
std::vector<Eigen::Vector3d> JacobianTestPoints(const CameraModel& model, std::mt19937& rng) {
  const CameraIntrinsics& c = model.intrinsics();
  std::uniform_real_distribution<double> u(-0.5, c.width - 0.5), v(-0.5, c.height - 0.5),
      depth(0.5, 30.0);
  // tan²θ = 5e-20 and 1e-18 straddle the fisheye's axis limit kFisheyeAxisMaxTan2.
  std::vector<Eigen::Vector3d> points = {{0, 0, 2},       {1e-10, -2e-10, 1}, {6e-10, 8e-10, 1},
                                         {3e-6, 4e-6, 1}, {2e-5, 0, 1},       {-0.3, 0.2, 4}};
  if (c.type == CameraModelType::kFisheye) {
    points.push_back({2.0, 1.0, -0.4});
    points.push_back({-1.0, -0.2, -0.35});
  }
  for (int i = 0; i < 300; ++i) {
    Eigen::Vector3d ray;
    EXPECT_TRUE(model.Unproject({u(rng), v(rng)}, &ray));
    points.push_back(depth(rng) * ray);
  }
  return points;
}

TEST(CameraModelJacobianTest, AnalyticMatchesNumericAndAutodiff) {
  std::mt19937 rng(77);
  for (const NamedCamera& camera : ReferenceCameras()) {
    const CameraModel model = MakeModel(camera.intrinsics);
    for (const Eigen::Vector3d& p : JacobianTestPoints(model, rng)) {
      const std::string what =
          std::string(camera.name) + " at " +
          ::testing::PrintToString(std::vector<double>(p.data(), p.data() + 3));
      Eigen::Vector2d uv;
      ProjectionPointJacobian d_p;
      ProjectionParameterJacobian d_params;
      ASSERT_TRUE(model.Project(p, &uv, &d_p, &d_params)) << what;
      ASSERT_EQ(d_params.cols(), CameraParameterCount(model.type()));
      // The Jacobian outputs do not change the value.
      Eigen::Vector2d uv_only;
      ASSERT_TRUE(model.Project(p, &uv_only));
      EXPECT_EQ(uv_only, uv) << what;

      ProjectionPointJacobian numeric_d_p;
      ProjectionParameterJacobian numeric_d_params;
      Eigen::Vector3d point_steps;
      CameraParameters parameter_steps;
      NumericJacobians(model, p, &numeric_d_p, &numeric_d_params, &point_steps, &parameter_steps);
      ExpectColumnsNear(d_p, numeric_d_p, point_steps, kNumericJacobianRelative,
                        kProjectionRoundingPx, what + " d_uv_d_p vs numeric");
      ExpectColumnsNear(d_params, numeric_d_params, parameter_steps, kNumericJacobianRelative,
                        kProjectionRoundingPx, what + " d_uv_d_parameters vs numeric");

      Eigen::Vector2d auto_uv;
      ProjectionPointJacobian auto_d_p;
      ProjectionParameterJacobian auto_d_params;
      AutodiffProjection(model, p, &auto_uv, &auto_d_p, &auto_d_params);
      EXPECT_LE((auto_uv - uv).norm(), kTemplateValuePx) << what;
      ExpectColumnsNear(d_p, auto_d_p, point_steps, kAutodiffJacobianRelative, kTemplateValuePx,
                        what + " d_uv_d_p vs autodiff");
      ExpectColumnsNear(d_params, auto_d_params, parameter_steps, kAutodiffJacobianRelative,
                        kTemplateValuePx, what + " d_uv_d_parameters vs autodiff");
    }
  }
}

// Projection is invariant to the length of p_camera, also for extreme magnitudes, and so is
// the Jacobian up to the chain rule factor.
TEST(CameraModelJacobianTest, ScaleInvariance) {
  for (const NamedCamera& camera : ReferenceCameras()) {
    const CameraModel model = MakeModel(camera.intrinsics);
    const Eigen::Vector3d p(0.4, -0.25, 1.0);
    Eigen::Vector2d uv;
    ProjectionPointJacobian d_p;
    ASSERT_TRUE(model.Project(p, &uv, &d_p));
    for (const double scale : {1e-200, 1e-5, 3.0, 1e200}) {
      Eigen::Vector2d uv_scaled;
      ProjectionPointJacobian d_p_scaled;
      ASSERT_TRUE(model.Project(scale * p, &uv_scaled, &d_p_scaled)) << camera.name << scale;
      EXPECT_LE((uv_scaled - uv).norm(), kTemplateValuePx) << camera.name << " " << scale;
      EXPECT_TRUE((scale * d_p_scaled).isApprox(d_p, 1e-14)) << camera.name << " " << scale;
    }
  }
}

}  // namespace
}  // namespace linecal

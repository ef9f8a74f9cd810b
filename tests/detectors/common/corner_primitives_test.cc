// Gaussian blur, bilinear sampling, the saddle fit and the X-corner finder on synthetic
// images with exactly known geometry.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "detectors/common/corner_refine.h"
#include "detectors/common/image_filters.h"
#include "detectors/common/x_corners.h"

namespace linecal {
namespace {

// 16 x 16 samples per pixel: a pixel's grey is exact to 1/256 of the contrast, so edges are
// placed to well under 0.01 px.
constexpr int kSupersample = 16;

// An image whose pixels integrate `paint(u, v)` (true = white 220, false = black 30).
template <typename Paint>
Image8 Render(int w, int h, Paint paint) {
  Image8 img(w, h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      int white = 0;
      for (int j = 0; j < kSupersample; ++j) {
        for (int i = 0; i < kSupersample; ++i) {
          white += paint(x - 0.5 + (i + 0.5) / kSupersample, y - 0.5 + (j + 0.5) / kSupersample);
        }
      }
      img.at(x, y) = static_cast<std::uint8_t>(
          std::lround(30.0 + 190.0 * white / (kSupersample * kSupersample)));
    }
  }
  return img;
}

// Two lines through (cu, cv) at angles a1, a2: white where the signed sides agree.
auto XCornerPaint(double cu, double cv, double a1, double a2) {
  return [=](double u, double v) {
    const double s1 = -(u - cu) * std::sin(a1) + (v - cv) * std::cos(a1);
    const double s2 = -(u - cu) * std::sin(a2) + (v - cv) * std::cos(a2);
    return (s1 > 0) == (s2 > 0);
  };
}

TEST(ImageFiltersTest, BlurKeepsConstantsAndSpreadsAnImpulseBySigma) {
  const Image8 flat(20, 15, 77);
  const ImageF blurred_flat = GaussianBlur(flat.view(), 2.0);
  for (float v : blurred_flat.pixels) EXPECT_NEAR(v, 77.0f, 1e-3f);
  Image8 impulse(41, 41, 0);
  impulse.at(20, 20) = 255;
  const double sigma = 2.0;
  const ImageF b = GaussianBlur(impulse.view(), sigma);
  double sum = 0.0, var_u = 0.0;
  for (int y = 0; y < 41; ++y) {
    for (int x = 0; x < 41; ++x) {
      sum += b.at(x, y);
      var_u += b.at(x, y) * (x - 20.0) * (x - 20.0);
    }
  }
  // Weights are normalised; the kernel cut at 3 sigma loses 0.3 % of the variance.
  EXPECT_NEAR(sum, 255.0, 1e-2);
  EXPECT_NEAR(std::sqrt(var_u / sum), sigma, 0.02 * sigma);
  EXPECT_FLOAT_EQ(b.at(20, 20), b.at(20, 20));
  // sigma 0 copies.
  EXPECT_EQ(GaussianBlur(impulse.view(), 0.0).at(20, 20), 255.0f);
}

TEST(ImageFiltersTest, BilinearInterpolatesAndClamps) {
  ImageF img(2, 2);
  img.at(0, 0) = 0.0f;
  img.at(1, 0) = 10.0f;
  img.at(0, 1) = 20.0f;
  img.at(1, 1) = 30.0f;
  EXPECT_FLOAT_EQ(SampleBilinear(img, 0.5, 0.5), 15.0f);
  EXPECT_FLOAT_EQ(SampleBilinear(img, 0.25, 0.0), 2.5f);
  EXPECT_FLOAT_EQ(SampleBilinear(img, -3.0, 7.0), 20.0f);
}

TEST(SaddleFitTest, FindsSkewedXCornersToHundredthsOfAPixel) {
  // The render is exact to well below 0.01 px; the fit resamples its window bilinearly at
  // the current sub-pixel position, which is not point-symmetric and leaves a bias of up to
  // 0.02 px on these sharp corners (measured; far less on camera-blurred renders).
  constexpr double kTolPx = 0.025;
  const double pi = std::numbers::pi;
  for (const auto& [cu, cv, a1, a2] :
       {std::array<double, 4>{30.3, 29.8, 0.1, 0.1 + pi / 2},
        std::array<double, 4>{31.71, 28.45, 0.5, 1.4},  // lines 52 degrees apart
        std::array<double, 4>{29.5, 30.5, -0.3, 0.9}}) {
    const Image8 img = Render(60, 60, XCornerPaint(cu, cv, a1, a2));
    const ImageF blurred = GaussianBlur(img.view(), 1.5);
    const std::optional<Eigen::Vector2d> p =
        RefineSaddle(blurred, Eigen::Vector2d(std::round(cu), std::round(cv)));
    ASSERT_TRUE(p.has_value());
    EXPECT_NEAR(p->x(), cu, kTolPx);
    EXPECT_NEAR(p->y(), cv, kTolPx);
  }
}

TEST(SaddleFitTest, RefusesFlatImagesBlobsAndTheBorder) {
  const ImageF flat = GaussianBlur(Image8(40, 40, 100).view(), 1.5);
  EXPECT_FALSE(RefineSaddle(flat, Eigen::Vector2d(20, 20)).has_value());
  const Image8 disc =
      Render(40, 40, [](double u, double v) { return std::hypot(u - 20, v - 20) < 6.0; });
  EXPECT_FALSE(RefineSaddle(GaussianBlur(disc.view(), 1.5), Eigen::Vector2d(20, 20)).has_value());
  const Image8 x = Render(40, 40, XCornerPaint(20, 20, 0.2, 1.7));
  EXPECT_FALSE(RefineSaddle(GaussianBlur(x.view(), 1.5), Eigen::Vector2d(1, 20)).has_value());
}

TEST(XCornersTest, FindsTheXCornerNotTheLCornerWithItsGeometry) {
  // Left half: an X-corner at (30.4, 40.2) with lines at 0.3 and 1.8 rad. Right half: an
  // L-corner (one dark quadrant) at (90, 40).
  const auto x_paint = XCornerPaint(30.4, 40.2, 0.3, 1.8);
  const Image8 img = Render(120, 80, [&](double u, double v) {
    if (u < 60.0) return x_paint(u, v);
    return !(u > 90.0 && v > 40.0);
  });
  const std::vector<XCorner> corners = FindXCorners(GaussianBlur(img.view(), 1.5));
  ASSERT_EQ(corners.size(), 1u);
  EXPECT_NEAR(corners[0].uv_px.x(), 30.4, 0.025);  // the saddle fit's bias, as above
  EXPECT_NEAR(corners[0].uv_px.y(), 40.2, 0.025);
  // Line directions within 2 degrees (32 ring samples, interpolated crossings).
  const double tol = std::cos(2.0 * std::numbers::pi / 180.0);
  const Eigen::Vector2d l1(std::cos(0.3), std::sin(0.3));
  const Eigen::Vector2d l2(std::cos(1.8), std::sin(1.8));
  EXPECT_GT(std::max(std::abs(corners[0].line_a.dot(l1)), std::abs(corners[0].line_b.dot(l1))),
            tol);
  EXPECT_GT(std::max(std::abs(corners[0].line_a.dot(l2)), std::abs(corners[0].line_b.dot(l2))),
            tol);
  EXPECT_GT(corners[0].line_a.x() * corners[0].line_b.y() - corners[0].line_a.y() * corners[0].line_b.x(),
            0.0);
  // The dark sectors are where the two sides disagree, which holds the bisector at angle
  // (a1 + a2) / 2 (it is left of line 1 and right of line 2).
  const double dark_angle = 0.5 * (0.3 + 1.8);
  const Eigen::Vector2d dark(std::cos(dark_angle), std::sin(dark_angle));
  EXPECT_GT(std::abs(corners[0].dark_axis.dot(dark)), tol);
  // The ring (radius 4 px) samples near the edges see them blurred: the contrast is most,
  // not all, of the printed 190.
  EXPECT_GT(corners[0].contrast, 150.0f);
  EXPECT_LE(corners[0].contrast, 190.0f);
}

}  // namespace
}  // namespace linecal

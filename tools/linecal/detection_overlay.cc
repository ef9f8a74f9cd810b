#include "tools/linecal/detection_overlay.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>

namespace linecal::tools {
namespace {

// A 3 x 5 pixel font for the digits 0-9: five rows of three bits, top row first, the
// leftmost pixel in the high bit.
constexpr std::array<std::array<std::uint8_t, 5>, 10> kDigits = {{
    {7, 5, 5, 5, 7},  // 0
    {2, 6, 2, 2, 7},  // 1
    {7, 1, 7, 4, 7},  // 2
    {7, 1, 7, 1, 7},  // 3
    {5, 5, 7, 1, 1},  // 4
    {7, 4, 7, 1, 7},  // 5
    {7, 4, 7, 5, 7},  // 6
    {7, 1, 1, 1, 1},  // 7
    {7, 5, 7, 5, 7},  // 8
    {7, 5, 7, 1, 7},  // 9
}};
// Digits drawn at twice their size: readable on a 1280 x 720 overlay.
constexpr int kFontScale = 2;
constexpr int kCrossHalfPx = 5;

// Beyond this many pixels from the image a mark is not drawn (and its coordinates cannot
// overflow an int).
constexpr double kFarOutsidePx = 1e6;

void DrawNumber(RgbImage* img, int x0, int y0, int number, const RgbColour& colour) {
  const std::string text = std::to_string(number);
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (text[i] < '0' || text[i] > '9') continue;
    const auto& glyph = kDigits[text[i] - '0'];
    const int gx = x0 + static_cast<int>(i) * 4 * kFontScale;
    for (int row = 0; row < 5; ++row) {
      for (int col = 0; col < 3; ++col) {
        if ((glyph[row] >> (2 - col) & 1) == 0) continue;
        for (int dy = 0; dy < kFontScale; ++dy) {
          for (int dx = 0; dx < kFontScale; ++dx) {
            PutPixel(img, gx + col * kFontScale + dx, y0 + row * kFontScale + dy, colour);
          }
        }
      }
    }
  }
}

}  // namespace

RgbImage GreyToRgb(const ImageView8& image) {
  RgbImage img(image.width, image.height);
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      const std::uint8_t g = image.At(x, y);
      PutPixel(&img, x, y, {g, g, g});
    }
  }
  return img;
}

void PutPixel(RgbImage* img, int x, int y, const RgbColour& colour) {
  if (x < 0 || y < 0 || x >= img->width || y >= img->height) return;
  std::uint8_t* p = img->at(x, y);
  p[0] = colour[0];
  p[1] = colour[1];
  p[2] = colour[2];
}

void DrawCross(RgbImage* img, const Eigen::Vector2d& uv_px, int half_px, const RgbColour& colour) {
  if (!(uv_px.cwiseAbs().maxCoeff() < kFarOutsidePx)) return;
  const int u = static_cast<int>(std::lround(uv_px.x()));
  const int v = static_cast<int>(std::lround(uv_px.y()));
  for (int d = -half_px; d <= half_px; ++d) {
    PutPixel(img, u + d, v, colour);
    PutPixel(img, u, v + d, colour);
  }
}

void DrawSegment(RgbImage* img, const Eigen::Vector2d& a, const Eigen::Vector2d& b, int thickness,
                 const RgbColour& colour) {
  if (!(a.cwiseAbs().maxCoeff() < kFarOutsidePx && b.cwiseAbs().maxCoeff() < kFarOutsidePx)) return;
  const int steps = std::max(1, static_cast<int>(std::ceil((b - a).cwiseAbs().maxCoeff())));
  const int lo = -(thickness - 1) / 2;
  for (int i = 0; i <= steps; ++i) {
    const Eigen::Vector2d p = a + (b - a) * (static_cast<double>(i) / steps);
    const int u = static_cast<int>(std::lround(p.x()));
    const int v = static_cast<int>(std::lround(p.y()));
    for (int dy = lo; dy < lo + thickness; ++dy) {
      for (int dx = lo; dx < lo + thickness; ++dx) PutPixel(img, u + dx, v + dy, colour);
    }
  }
}

void DrawFeatures(RgbImage* img, std::span<const DetectedFeature> features,
                  const RgbColour& colour) {
  for (const DetectedFeature& f : features) {
    if (!(f.uv_px.cwiseAbs().maxCoeff() < kFarOutsidePx)) continue;
    DrawCross(img, f.uv_px, kCrossHalfPx, colour);
    DrawNumber(img, static_cast<int>(std::lround(f.uv_px.x())) + 3,
               static_cast<int>(std::lround(f.uv_px.y())) + 3, f.id, colour);
  }
}

RgbImage DrawDetectionOverlay(const ImageView8& image, const Detection& detection) {
  RgbImage img = GreyToRgb(image);
  DrawFeatures(&img, detection.features, detection.found ? kFoundColour : kPartialColour);
  return img;
}

}  // namespace linecal::tools

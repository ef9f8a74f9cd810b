#pragma once
// Drawing over images, for `linecal detect --overlay`, `linecal calibrate --report` and
// `linecal aftersale`.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <span>

#include "detectors/core/image_view.h"
#include "detectors/detection.h"
#include "station/io/image_io.h"

namespace linecal::tools {

using RgbColour = std::array<std::uint8_t, 3>;
// A board's features when the whole board was found, and when not.
inline constexpr RgbColour kFoundColour = {0, 230, 0};
inline constexpr RgbColour kPartialColour = {255, 140, 0};

// The grey image as RGB. The view must be valid. O(pixels).
RgbImage GreyToRgb(const ImageView8& image);

// Sets pixel (x, y); pixels outside the image are skipped. O(1).
void PutPixel(RgbImage* img, int x, int y, const RgbColour& colour);

// A cross of arms half_px long centred on the rounded uv_px, clipped to the image; nothing for
// a point far outside it (or not a number). O(half_px).
void DrawCross(RgbImage* img, const Eigen::Vector2d& uv_px, int half_px, const RgbColour& colour);

// A straight segment from a to b (pixel centres), `thickness` pixels wide, clipped to the
// image; nothing when an end is far outside it. O(length x thickness^2).
void DrawSegment(RgbImage* img, const Eigen::Vector2d& a, const Eigen::Vector2d& b, int thickness,
                 const RgbColour& colour);

// Marks each feature on *img: a cross at its (rounded) position in `colour` and its id in
// small digits to the lower right. Marks falling partly outside the image are clipped.
// O(features).
void DrawFeatures(RgbImage* img, std::span<const DetectedFeature> features,
                  const RgbColour& colour);

// The grey image as RGB with each feature marked (DrawFeatures), green when the whole board
// was found and orange otherwise. Cost: one pass over the image plus O(features).
RgbImage DrawDetectionOverlay(const ImageView8& image, const Detection& detection);

}  // namespace linecal::tools

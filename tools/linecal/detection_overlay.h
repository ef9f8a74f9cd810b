#pragma once
// Drawing detected features over their image, for `linecal detect --overlay` and
// `linecal calibrate --report`.

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

// The grey image as RGB. The view must be valid. One pass over the image.
RgbImage GreyToRgb(const ImageView8& image);

// Marks each feature on *img: a cross at its (rounded) position in `colour` and its id in
// small digits to the lower right. Marks falling partly outside the image are clipped.
// O(features).
void DrawFeatures(RgbImage* img, std::span<const DetectedFeature> features, const RgbColour& colour);

// The grey image as RGB with each feature marked (DrawFeatures), green when the whole board
// was found and orange otherwise. Cost: one pass over the image plus O(features).
RgbImage DrawDetectionOverlay(const ImageView8& image, const Detection& detection);

}  // namespace linecal::tools

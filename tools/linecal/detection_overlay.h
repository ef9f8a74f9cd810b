#pragma once
// Drawing a detection over its image, for `linecal detect --overlay`.

#include "detectors/core/image_view.h"
#include "detectors/detection.h"
#include "station/io/image_io.h"

namespace linecal::tools {

// The grey image as RGB with each feature marked: a cross at its (rounded) position, green
// when the whole board was found and orange otherwise, and its id in small digits to the
// lower right. Marks falling partly outside the image are clipped. The view must be valid.
// Cost: one pass over the image plus O(features).
RgbImage DrawDetectionOverlay(const ImageView8& image, const Detection& detection);

}  // namespace linecal::tools

#pragma once
// One entry point for every camera board detector: picks the detector of the board's type.
//
// Board types with an image detector return a Detection (found or not, with its reason).
// A board type without an image detector returns nullopt: "no detector for this board
// type", which is not the same as "no board in this image" (callers report it as a usage
// error, e.g. `linecal detect` exits 2). Each detector engineer adds the case of their
// board in detect.cc.

#include <optional>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/detection.h"

namespace linecal {

// Runs the detector of board.type() with its default options on an 8-bit grey view.
// nullopt: no detector for that type. An invalid view gives a Detection with kBadImage.
// Pure function; cost: that detector's (a few ms at 1280 x 720).
std::optional<Detection> DetectBoard(const ImageView8& image, const Board& board);

// The same for a 16-bit view, converted by RangeTo8Bit. Cost: the conversion, then the
// 8-bit detector.
std::optional<Detection> DetectBoard(const ImageView16& image, const Board& board);

// A 16-bit view as 8 bits by the image's own range: its darkest pixel becomes 0, its
// brightest 255, linearly, rounded, so that a camera using a part of the 16-bit range keeps
// its full contrast. A constant image becomes all 0 (no contrast); an invalid view gives an
// empty image. Cost: two passes; allocates width * height bytes.
Image8 RangeTo8Bit(const ImageView16& image);

}  // namespace linecal

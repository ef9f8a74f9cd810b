#pragma once
// Detector of the ArUco marker board (docs/boards.md §4) and of the camera side of the
// round-hole board (§6): the same four DICT_4X4_50 markers (ids 4, 11, 12, 19) at the same
// places; the two boards differ only in what else is printed, which the whole-board paint
// check tells apart.
//
// Method: detectors/markers/square_markers.h, DetectMarkerBoard (local-contrast binarisation,
// quads from contours, edge-line sub-pixel corners, decoding against all 50 codes in all
// rotations with at most 1 corrected bit, coarse to fine; then one board fit, homography and
// the markers' dilation, through every marker corner, markers not read placed by it, and the
// board's paint checked through it).

#include <string_view>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/detection.h"
#include "detectors/markers/square_markers.h"

namespace linecal {

struct ArucoOptions {
  MarkerDetectOptions markers;

  // Empty when valid, else the name of the first field out of range. O(1).
  std::string_view Validate() const { return markers.Validate(); }
};

// Finds `board` (type kAruco or kRoundHole; any other type gives kWrongBoard) in `image`.
// found = true with the 16 marker corners (ids 0..15, corner 0 = the marker's top-left in
// its canonical orientation, then clockwise) when all four markers pass the whole-board
// check; found = false, kPartial with the corners of the 2 or 3 markers that pass;
// otherwise found = false, no features, and the reason: kBadImage (invalid view or options,
// or smaller than a marker), kLowContrast, kNoCandidates, kTooFewFeatures (one marker),
// kAmbiguous (a marker id twice), kVerificationFailed (the markers do not fit one board),
// kWrongBoard (other marker ids, or another board's print). Pure function; round-hole
// features 16..20 (hole centres) are never reported. Cost: about 2.5 ms at 1280 x 720 and
// 4.5 ms at 2448 x 2048 (docs/detectors.md).
Detection DetectAruco(const ImageView8& image, const Board& board,
                      const ArucoOptions& options = {});

}  // namespace linecal

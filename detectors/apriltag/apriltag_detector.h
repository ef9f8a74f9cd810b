#pragma once
// Detector of the AprilTag board (docs/boards.md §5): a Kalibr-style AprilGrid of 6 x 6
// tag36h11 tags, ids 0..35, with a 2-bit black border (BoardParams::apriltag_border_bits = 2,
// which stock AprilTag 3 cannot read) or the ordinary 1-bit border.
//
// Method: detectors/markers/square_markers.h (DetectMarkerBoard) with the tag36h11 codes of
// libapriltag laid out for the board's border width (10 x 10 or 8 x 8 cells), decoded in all
// rotations with at most 2 corrected bits, coarse to fine; one board fit (homography and the
// tags' dilation) through every tag corner; the tags not read placed by it and checked
// against their print; the board's paint checked through it.

#include <string_view>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/detection.h"
#include "detectors/markers/square_markers.h"

namespace linecal {

struct ApriltagOptions {
  // Two erosions: the grid's corner squares touch every tag's corners, and under blur up to
  // 1.5 px and gamma the junction leaves a dark bridge up to two pixels wide. No pass nearer
  // the dark level: the tags' quiet zones are 3 bits wide all round, which blur leaves their
  // contrast, and the pass cost 1.7 ms (5.3 -> 7.0 ms) on the benchmark's grid, whose coarse
  // levels do not read all 36 tags (docs/detectors.md).
  MarkerDetectOptions markers = {.max_erosion_px = 2, .near_dark_fraction = 0.0};

  // Empty when valid, else the name of the first field out of range. O(1).
  std::string_view Validate() const { return markers.Validate(); }
};

// Finds the AprilGrid `board` (type kApriltag, else kWrongBoard) in `image`. found = true
// with all 144 tag corners (id 4 * tag + corner, corner 0 = the tag's top-left, then
// clockwise) when all 36 tags pass the whole-board check; found = false, kPartial with the
// corners of the 2..35 tags that pass; otherwise found = false, no features, and the reason
// (as DetectAruco: kBadImage, kLowContrast, kNoCandidates, kTooFewFeatures, kAmbiguous,
// kVerificationFailed, kWrongBoard). Pure function; cost: about 6 ms at 1280 x 720 and 8 ms at
// 2448 x 2048 (docs/detectors.md).
Detection DetectApriltag(const ImageView8& image, const Board& board,
                         const ApriltagOptions& options = {});

}  // namespace linecal

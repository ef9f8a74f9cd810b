#pragma once
// Detector of the generic chessboard (`checker`, docs/boards.md §7): cols x rows inner
// X-corners, as printed boards come: either colour at a corner, outer squares whole or cut,
// with or without a white margin, seen through real lenses from mild to fisheye.
//
// Method: X-corner candidates over the whole image (x_corners.h); a graph joining each
// corner to its nearest neighbour along each of its four edge directions (the neighbour
// must lie on one of its own edge lines, have its dark sectors turned by 90 degrees and be
// joined to it by a printed edge, and the link must be mutual); integer grid coordinates
// spread over each connected graph by breadth-first search. In each component every
// complete cols x rows window is a candidate (the component itself, or each placement inside
// a component grown into clutter or part of a larger grid), verified locally, never by one
// homography of the whole board, which a real lens bends by tens of pixels:
//   - each corner agrees with a quadratic through the other corners of its 3 x 3 block;
//   - the squares, sampled through homographies of 3 x 3 blocks of corners, alternate dark
//     and light between every pair of neighbours, the outer ring of squares included (sampled
//     just beyond the outer corners, where even a cut square is paint);
//   - the pattern does not go on beyond the window (the next row of squares alternating in
//     phase means a larger board or grid: kWrongBoard).
// Corners are then refined by the saddle fit with a window scaled to the local square size.
// All but that refinement run coarse to fine: on the image halved while its short side keeps
// kMinCoarseLevelSidePx (x_corners.h) first, then on each finer level until one finds the
// board, and last on the image under a larger blur for squares that do not touch
// (CheckerOptions::gap_blur_sigma_px); the refinement is always at full resolution.
//
// Orientation: docs/boards.md numbers corner (col c, row r) from the top-left square, which is
// black. The colours fix the orientation unless the board is symmetric under a rotation
// that keeps them: under 180 degrees when cols + rows is even (then the bottom-right square
// is black too), and under 90 degrees when cols == rows and both are even. A board printed
// the other way round (white at its top-left) is the same board turned by 180 degrees when
// cols + rows is odd; when it is even, such a board is accepted too, its colours not fixing
// anything. Among the orientations left, the detector chooses the one whose board x axis
// points most nearly along the image's +u (the board as upright as possible), the usual
// convention for symmetric targets. Use a board with cols + rows odd when the orientation
// matters.

#include <string_view>

#include "detectors/boards/board.h"
#include "detectors/common/x_corners.h"
#include "detectors/core/image_view.h"
#include "detectors/detection.h"

namespace linecal {

struct CheckerOptions {
  // Gaussian blur before the corner response and the saddle fit, pixels: enough to make
  // the response stable under noise of sigma 6, small enough for 12 px squares. [0.5, 4].
  double blur_sigma_px = 1.5;
  XCornerOptions corners;
  // Each corner must agree with the quadratic through its 3 x 3 block's other corners within
  // this fraction of the local square side (or 1 px, whichever is larger), half as large
  // again per axis along which it is extrapolated: a corner that is not the grid's is off by
  // a good part of a square, while a close fisheye view bends a block by up to 0.17 of a
  // side at its corners. (0, 0.5].
  double max_residual_square_fraction = 0.15;
  // When the image holds corners but no board, it is searched once more under this blur:
  // squares that do not touch (Kalibr's boards, 2-3 px apart) leave no saddle at their
  // vertices under blur_sigma_px once the gap is wider than about a pixel, and do under
  // 2 px up to gaps of about 3 px. It costs a full-resolution search on images without the
  // board. 0 (no such pass) or [0.5, 4].
  double gap_blur_sigma_px = 2.0;

  // Empty when valid, else the name of the first field out of range ("blur_sigma_px").
  std::string_view Validate() const;
};

// Finds the checker `board` (board.type() must be kChecker, else reason kWrongBoard) in
// `image`. found = true with all cols * rows features ordered by id, or found = false with
// a reason and no features: kBadImage (invalid view, or below 16 px a side, or invalid
// options), kLowContrast, kNoCandidates, kTooFewFeatures (no complete grid), kWrongBoard
// (a larger checker or grid around every candidate), kAmbiguous (two complete grids),
// kVerificationFailed. Pure function;
// cost: about 2 ms at 1280 x 720 and 3 ms at 2448 x 2048 when the half image holds the board
// (squares of 20 px or more at 1280 x 720), the full-resolution search on top for smaller.
Detection DetectChecker(const ImageView8& image, const Board& board,
                        const CheckerOptions& options = {});

}  // namespace linecal

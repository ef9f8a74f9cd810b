#pragma once
// Detector of the vertical board (`vertical`, docs/boards.md §3): a column of 4 x 18 cells with a
// one-cell white margin, whose 51 corners lie on three vertical lines: the middle line is a
// run of 17 X-corners between two L-corners, the outer lines carry 16 L-corners each. The
// board stands upright and is often cut by the image's top or bottom border; such partial
// views are reported (found = false, kPartial, with the features that are certain).
//
// Method:
// 1. X-corner candidates over the image (x_corners.h) and their neighbour graph
//    (LinkXCorners); straight runs of at least min_chain_corners linked corners that are
//    not part of a two-dimensional grid are candidate middle lines.
// 2. For each run, per cell row between two of its corners, the image is walked across the
//    row from the middle line to both sides: the colour next to the middle line and the
//    distance to the first change of colour (thresholded halfway between the two cells
//    beside the middle line, which are always one black and one white: the threshold
//    follows the local contrast). On the board that distance is 1, 2 or at least 3 cells,
//    which the board's code fixes per row; every placement of the run on the middle line
//    (either way up) whose colours and distances fit the code with one common cell width
//    is a hypothesis, and the crossings give image points of known board coordinates for
//    a first homography.
// 3. The homography predicts every feature; X-corners are refined by the saddle fit, L-corners
//    by intersecting lines fitted to their two edges (edge_lines.h), accepted within a
//    fraction of a cell of the prediction, and the homography is refitted from them,
//    growing from the run over the visible board.
// 4. Verification: every feature within max_residual_cell_fraction of its local cell of the
//    final homography, and every visible cell of the page (margin included) of the colour
//    the board's code gives, against its row's own black/white threshold. The decoded
//    position must be unique: no other placement of the board's code (shifted along the
//    board, or turned by 180 degrees) fits the visible cells, else kAmbiguous.
//
// Feature ids, kinds and board coordinates are the board's (Board::features(), docs/boards.md);
// the detector reads the cell colours from Board::PaintAt.

#include <string_view>

#include "detectors/boards/board.h"
#include "detectors/common/x_corners.h"
#include "detectors/core/image_view.h"
#include "detectors/detection.h"

namespace linecal {

struct VerticalOptions {
  // Gaussian blur for the corner response, the saddle fit and the colour samples, pixels:
  // as the checker detector (stable under noise of sigma 6, small enough for 12 px cells).
  // [0.5, 4].
  double blur_sigma_px = 1.5;
  XCornerOptions corners;
  // Shortest run of middle-line X-corners that starts a hypothesis: 4 corners span three
  // cell rows, enough to fix the cell width across from two or more rows, while a view cut
  // at a third of the board still shows 11. [3, 17].
  int min_chain_corners = 4;
  // Every feature must fit the board homography within this fraction of its local cell
  // side: a wrong correspondence is off by a whole cell; lens distortion over the board
  // stays well below. (0, 0.5].
  double max_residual_cell_fraction = 0.15;
  // A verified cell differs from its row's threshold by at least this fraction of the row's
  // contrast, on the side of its printed colour: far above the noise of a five-point mean,
  // while lighting may change by a third across a row. (0, 0.5).
  double min_cell_margin_fraction = 0.15;

  // Empty when valid, else the name of the first field out of range ("blur_sigma_px").
  std::string_view Validate() const;
};

// Finds the vertical `board` (board.type() must be kVertical, else kWrongBoard) in `image`
// (8-bit grey, pixel-centre convention). found = true with all 51 features ordered by id;
// or found = false with a reason: kPartial with the certain features (refined, fitting the
// homography, and all four cells around them visible and of the right colour) when part of
// the board is cut off; otherwise no features and kBadImage (invalid view, below 16 px a
// side, invalid options), kLowContrast, kNoCandidates (no X-corners), kTooFewFeatures (no
// run of middle-line corners placed on the code), kVerificationFailed, or kAmbiguous (two
// different boards or placements fit). Pure function; steps 1-4 run coarse to fine (first on
// the image halved while its short side keeps kMinCoarseLevelSidePx, x_corners.h) and a
// board found coarse is fitted again at full resolution on the part of the image that holds
// it. Cost: the X-corner pass of the level that finds the board (about 3 ms in all at
// 1280 x 720 with cells of 20 px or more, 6 ms at 2448 x 2048) plus well under a millisecond
// per run examined; smaller boards add the full-resolution pass.
Detection DetectVertical(const ImageView8& image, const Board& board,
                         const VerticalOptions& options = {});

}  // namespace linecal

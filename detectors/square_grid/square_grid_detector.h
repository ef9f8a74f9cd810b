#pragma once
// Detector of the square grid (`square_grid`, docs/boards.md §9): cols x rows black squares
// apart by white gaps, as BoofCV prints it; the features are the four corners of every square.
//
// Method:
//   1. Dark squares: the local-contrast binarisation and the quads of its dark components
//      (binarise.h, contours.h; a corner rounded by blur may leave two vertices, the quad
//      then lies on the four longest sides), each quad's corners refined to where lines
//      fitted to the edges of its four sides meet (edge_lines.h).
//   2. Links: each quad's homography (its corners onto a unit square) puts the centre of the
//      gap beyond each of its sides (half a gap out, the gap known from the board); two
//      quads of a similar size whose sides put it at the same point, within
//      max_link_side_fraction of a side, are neighbours when each is the other's nearest.
//      Integer grid coordinates spread over each connected group by breadth-first search.
//   3. Windows: every complete cols x rows (or rows x cols) placement of squares in a group is
//      verified locally, never by one homography of the whole board, which a real lens bends
//      by tens of pixels:
//        - along every row and column of corners, each gap agrees with the two squares beside
//          it (exact for any quadratic image of the line: the lens's bending drops out), in
//          its component along the line (a corner's shift across a row is one along a column);
//        - the paint: each gap between neighbouring squares and each crossing of gaps lighter
//          than the squares around it by half the board's contrast (a chessboard prints a
//          black square at every crossing, an AprilGrid a corner square);
//        - the grid does not go on: no square linked beyond the window in the gap geometry
//          of the window's square beside it (a larger grid: kWrongBoard).
//   4. Lost squares: when no window passes, each square missing from a window that lacks at
//      most an eighth of its squares is predicted by its linked neighbours' homographies and
//      looked for there with a threshold of its own (halfway between the neighbours' dark
//      level and the gaps' light level: a lens's dark rim or a shadow lowers the local
//      threshold); a quad found there is refined as in step 1, and steps 2 and 3 run again
//      with it among the squares. Nothing is placed where no square is seen.
//
// Orientation: the print is the same under a turn of 180 degrees (and of 90 degrees when
// cols == rows), so nothing printed fixes it; among the rotations that fit, the detector
// chooses the one whose board x axis points most nearly along the image's +u (the board as
// upright as possible), as for the symmetric checker and circle grids.

#include <string_view>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/detection.h"

namespace linecal {

struct SquareGridOptions {
  // Smallest difference between the local dark and light levels, grey levels; raised to
  // noise_contrast_factor x the image's noise sigma on noisy images (as the marker detectors
  // do). [4, 200].
  int min_contrast = 12;
  // The local extremes are taken over 144 means of 2 x 2 pixels, whose range exceeds 4 noise
  // sigma with a probability of about 1e-4 (square_markers.h). [0, 10].
  double noise_contrast_factor = 4.0;
  // Smallest square side in pixels: below it a square's edges hold too few points for the line
  // fits. [6, 1000].
  int min_square_side_px = 8;
  // Two neighbours' homographies, each carried half a gap beyond its side, must put the
  // gap's centre within this fraction of their mean side of each other. Perspective is in
  // the homographies; a lens bends half a gap by a few percent of a side; a square of another
  // grid or of clutter is off by a good part of a side. (0, 0.5].
  double max_link_side_fraction = 0.25;
  // Along every row and column of corners, each gap must agree with the two squares beside it
  // (its component along the line in a window of 2 x 2 squares or more, the whole residual
  // between two squares alone) within this fraction of their mean side (or 1 px, whichever is
  // larger). A square that is not the grid's is off by a good part of a side. (0, 0.5].
  double max_residual_side_fraction = 0.2;

  // Empty when valid, else the name of the first field out of range ("min_contrast").
  std::string_view Validate() const;
};

// Finds the square grid `board` (board.type() must be kSquareGrid, else reason kWrongBoard)
// in `image`. found = true with all 4 * cols * rows corners ordered by id, or found = false
// with a reason and no features: kBadImage (invalid view, a side below 16 px, or invalid
// options), kLowContrast, kNoCandidates (no dark quads), kTooFewFeatures (no complete
// cols x rows group of linked squares), kVerificationFailed (complete groups failed the local
// geometry or paint checks), kWrongBoard (every complete group is part of a larger grid),
// kAmbiguous (two different grids). Pure function; cost: a binarisation and labelling, O(W * H),
// O(perimeter) per dark component, and O(quads^2) for the links (twice when step 4 finds a
// square): 4-6 ms on the corpus's 640 x 480 photos, 4.5-5 ms of CPU for 54 squares at
// 1280 x 720 (detectors_bench, machine under a load of 4-6 where the checker took 3.9 ms;
// docs/detectors.md, "The square grid and the hexagonal grid made faster").
Detection DetectSquareGrid(const ImageView8& image, const Board& board,
                           const SquareGridOptions& options = {});

}  // namespace linecal

#pragma once
// Detector of the square grid (`square_grid`, docs/boards.md §9): cols x rows black squares
// apart by white gaps, as BoofCV prints it; the features are the four corners of every square.
//
// Method:
//   1. Dark squares: the local-contrast binarisation and the quads of its dark components
//      (binarise.h, contours.h), each quad's corners refined to where lines fitted to the
//      edges of its four sides meet (edge_lines.h).
//   2. Links: each quad's homography (its corners onto a unit square) predicts the centre of
//      the neighbour across each of its sides one pitch away (square + gap, known from the
//      board); the nearest quad of a similar size within max_link_pitch_fraction of a pitch of
//      that prediction is linked when the link is mutual. Integer grid coordinates spread
//      over each connected group by breadth-first search.
//   3. Windows: every complete cols x rows (or rows x cols) placement of squares in a group is
//      verified locally, never by one homography of the whole board, which a real lens bends
//      by tens of pixels:
//        - every corner agrees with the quadratic through the corners of the neighbouring
//          squares of its 3 x 3 block of squares (local_fit.h);
//        - the paint: each square dark inside; each gap between neighbouring squares and each
//          crossing of gaps light (a chessboard's black squares, an AprilGrid's tags and
//          corner squares print black there);
//        - the grid does not go on: no square linked beyond the window (a larger grid:
//          kWrongBoard).
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
  // A neighbour's centre must lie within this fraction of the pitch (the predicted distance
  // between the two centres) of where the square's homography puts it. Perspective is in the
  // prediction; a lens bends a one-pitch step by a few percent of it; a square of another
  // grid or of clutter is off by a good part of a pitch. (0, 0.5].
  double max_link_pitch_fraction = 0.25;
  // Each corner must agree with its prediction from the neighbouring squares' corners within
  // this fraction of the local square side (or 1 px, whichever is larger), half as large again
  // per axis along which the square lies at the window's edge (predicted by extrapolation). A
  // square that is not the grid's is off by a good part of a side. (0, 0.5].
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
// kAmbiguous (two different grids). Pure function; cost: a binarisation and labelling, O(W * H)
// (a few ms at 1280 x 720), plus O(perimeter) per dark component.
Detection DetectSquareGrid(const ImageView8& image, const Board& board,
                           const SquareGridOptions& options = {});

}  // namespace linecal

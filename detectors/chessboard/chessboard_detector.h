#pragma once
// Detector of the wide two-group chessboard (`chessboard`, docs/boards.md §1, docs/boards.md):
// two groups of three black squares touching diagonally, 4 X-corners and 16 L-corners,
// ids 0..9 on the left group and 10..19 on the right (Board::features()).
//
// Method (docs/corner-detectors.md):
//  1. Candidates: local-contrast binarisation (binarise.h; the contrast floor grows with
//     the image's own noise), 4-connected dark components, convex quads from their
//     contours (contours.h). Squares touching at an X-corner are separate 4-connected
//     components unless blur and noise bridge the vertex. When the first search finds no
//     board, every component of plausible size that gave no quad is searched for X-corners
//     (x_corners.h, on a blurred patch around it); the binary image is repainted around
//     each from the corner's two edge lines (dark sectors dark, a light band along both
//     lines), which cuts the bridge, and the search is repeated.
//  2. Groups: two quads touch when a corner of each lies within a fraction of the square
//     side of the other's and each centre is the other's reflection through that vertex. A
//     quad touching two others at two neighbouring corners is the middle square of a group
//     (the lower square of the left "V", the upper of the right "Λ"); the three give the
//     group's 12 square corners in a local grid.
//  3. Board: every pair of groups gives all 24 square corners in board coordinates; a
//     homography must fit them within a fraction of the local square side (a wrong pair is
//     off by squares). This is the coarse board homography.
//  4. Sub-pixel: every straight board edge of a group (the sides of its squares that lie on
//     one line, e.g. the five sides on the line through both X-corners) is measured along
//     its whole length (edge points across the edge, edge_lines.h) and fitted by one line;
//     L-corners are intersections of two fitted lines. X-corners are refined by the saddle
//     fit (corner_refine.h) on a blurred patch, started at their line intersection. Three
//     passes, each sampling along the homography refitted to the previous pass's corners;
//     the last undoes the edge locator's bias (gamma and blur asymmetry shift every edge
//     of a group alike; the lines whose segments alternate polarity at an X-corner measure
//     it) and takes the direction of a line of one side only (a single short square side)
//     from the previous homography.
//  5. Verification of the whole board: the homography of the 20 refined corners fits each
//     within a fraction of its local square side, and the image binarised in step 1 shows
//     the board's black and white where that homography puts them (paint_check.h), which
//     rejects checkers and other patterns that happen to hold two such groups.
//  6. Second path, when steps 1-5 (with the split) find no board, e.g. squares of 8-14 px
//     whose binarised blobs are rounded and give no quads: X-corners over the whole image
//     (x_corners.h, blur 1.5 px, ring 3 px). Each group has exactly two X-corners one square
//     side apart on a shared edge line; pairs whose edge lines agree, whose dark axes are
//     about perpendicular and whose dark sectors facing each other lie on the same side of
//     their line (the middle square) seed a group: from each corner the ends of the edge
//     lines through it (where the grey-level difference across the edge falls to half, on
//     the blurred image) give six L-corners, the pair's local homography of the eight points
//     must fit within the coarse tolerance, and every two groups whose four X-corners lie on
//     one image line (they share one board line) give, either as the left one, the coarse
//     board homography of steps 3-5.
//
// Orientation: the board is symmetric under a rotation by 180 degrees about its centre
// (the left "V" turned by 180 degrees is exactly the right "Λ", and the page is centred),
// so no image can tell a board from the board turned upside down. Like the checker
// detector for symmetric grids, the detector reports the orientation whose board +x axis
// points most nearly along the image's +u (the board as upright as possible). The ids are
// right whenever the board is rolled by less than 90 degrees in the image, which holds for
// every station camera (boards stand upright, cameras are mounted upright).
//
// Frames and units: image pixels, pixel-centre convention (docs/conventions.md); board frame in
// metres (board.h).

#include <string_view>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/detection.h"

namespace linecal {

struct ChessboardOptions {
  // Smallest local range of grey levels for an area to be binarised (and for the image not
  // to be kLowContrast); the effective floor is also noise_contrast_factor x the image's
  // estimated noise sigma. 12 is far below a lit print's contrast (about 150 levels; 40 at
  // the dark end of a 4:1 gradient) and above noise of sigma 6 averaged 2 x 2. [1, 255].
  int min_contrast = 12;
  // See MarkerDetectOptions::noise_contrast_factor: 4 sigma of 2 x 2 means is exceeded by
  // the range of 144 of them with a probability of about 1e-4. [0, 100].
  double noise_contrast_factor = 4.0;
  // Smallest bounding-box side of a square's component, pixels: the smallest squares of
  // docs/acceptance.md are 12 px, about 7.7 px foreshortened by 50 degrees. [4, 64].
  int min_square_side_px = 6;
  // Two quads touch when the centre of each is the other's reflection through their nearest
  // corners' midpoint within this fraction of the mean side (a quad of another square is at
  // least a side away), and those corners are closer than twice this fraction of the smaller
  // side plus 2 px (contours retreat from a shared vertex by the blur, more at the acute
  // corners of a strong perspective; pixel centres lie inside the square). (0, 0.5].
  double touch_fraction = 0.35;
  // Coarse board homography from contour corners: every corner within this fraction of
  // its local square side. Contour corners are off by a pixel or two; a wrong pair of
  // groups by whole squares. (0, 0.5].
  double coarse_residual_fraction = 0.3;
  // Final check: the homography of the 20 refined corners fits each within this fraction of
  // its local square side (or 0.5 px, whichever is larger): refined corners are within a
  // tenth of a pixel, lens distortion of a board over much of an image adds a few percent of
  // a square. (0, 0.5].
  double max_residual_square_fraction = 0.1;
  // Whole-board paint check: at least this fraction of the probes of each paint agree
  // (paint_check.h). Blur and the homography's error cost a few percent. [0, 1].
  double min_paint_agreement = 0.85;

  // Empty when valid, else the name of the first field out of range ("min_contrast"). O(1).
  std::string_view Validate() const;
};

// Finds the chessboard `board` (board.type() must be kChessboard, else reason kWrongBoard)
// in `image`. found = true with all 20 features ordered by id (uv_px sub-pixel), or
// found = false with a reason and no features: kBadImage (invalid view, a side below 16 px,
// or invalid options), kLowContrast, kNoCandidates (no square quads), kTooFewFeatures
// (fewer than two groups of three squares), kVerificationFailed (no pair of groups fits
// one board, or its refinement failed, e.g. a board cut by the image border), kWrongBoard
// (a board-shaped pattern whose paint is not this board's), kAmbiguous (two boards).
// Pure function. The candidate searches (steps 1-3 and 6) run coarse to fine, first on the
// image halved while its short side keeps kMinCoarseLevelSidePx (x_corners.h), refinement
// and checks always at full resolution. Cost on one core: about 2.6 ms at 1280 x 720 and
// 4.4 ms at 2448 x 2048 when the half image holds the board (squares of 20 px or more at
// 1280 x 720); a smaller board runs every path at full resolution after the coarse level,
// up to about 17 ms (docs/corner-detectors.md).
Detection DetectChessboard(const ImageView8& image, const Board& board,
                           const ChessboardOptions& options = {});

}  // namespace linecal

#pragma once
// Detector of OpenCV's ChArUco boards (docs/boards.md, ChArUco): a chessboard of cols x rows
// squares whose white squares hold the markers of one of OpenCV's predefined ArUco dictionaries
// (BoardParams::charuco_dictionary); the features are the chessboard's inner corners with
// OpenCV's charuco ids.
//
// Method: the markers are found and decoded by the project's square-marker scan
// (detectors/markers/square_markers.h, ScanMarkers). A marker is kept only when its id belongs
// to the board, is read once, and a neighbouring marker (within two squares) lies where the
// marker's own homography puts it: a marker of another board, or a misread id, has no such
// neighbour; and the board is refused when a marker lies on its page where it prints no such
// marker. A marker read where the board prints another one, whose cells still show the printed
// one's code (within the cells a placed marker may miss), is that marker misread: it is left
// out, and the board kept. Each inner corner is then predicted from the homography of the (one
// or two) kept markers in the squares that touch it — local, so that a lens that bends the
// board moves the prediction little — or, where they were not read or the fit fails from
// there, of the kept markers of the 4 x 4 squares around it; refined by the saddle fit
// (detectors/common/corner_refine.h) and kept only when the fit is a saddle within a pixel of
// the prediction and the image shows the board's paint around it: both black squares darker
// than both white ones. Where the saddle fit fails (blur and noise in the small window between
// the markers), the corner is the prediction of the markers of the 4 x 4 squares around it when
// that is an interpolation that holds: markers on every side of it, one homography through
// all their corners within MarkerDetectOptions::max_residual_cells, and the paint check.
// Markers the scan missed are read where the kept markers around them put them. Corners still
// missing are then looked for as a chessboard's: predicted by the homography of the corners
// found around them (at least four over two rows and two columns of the 5 x 5 about it),
// refined and checked as above (where the fit fails, again in a window inside the white margin,
// kept when the image about the corner is nearly point-symmetric), repeated while corners are
// added; the ids stay those the markers gave. A partial
// board whose marker cells are under 4 px (the scan's design size) is looked for again on its
// part of the image at twice the resolution, and the result with more corners is returned.
// Where the markers still leave the board incomplete (too small to read: cells of 1.5-3 px),
// and none spoke against the board, the board is read from its chessboard: about the markers
// of the board read with cells under 4 px (nothing bounds a board none of whose markers is
// read: it is not looked for), the X-corners at twice the resolution linked into grids
// (x_corners.h, as the checker detector does), each window of the board's inner-corner size
// holding three quarters of its corners a candidate; for each rotation of the window on the
// board, and for boards of the same layout with other ids (offsets of the marker count), the
// grey of every data cell of every marker (sampled through the homographies of 3 x 3 blocks
// of corners) is correlated with the bit printed there, over all markers at once. The board's
// own ids must win by 5 sigmas of the cells' noise over every other hypothesis and show their
// print with a significance of 6 sigmas (against a print unrelated to the image); the markers
// the scan read must be the ones printed where they lie and the corners they gave must agree.
// Such a board is returned only whole (its missing corners looked for from their neighbours).

#include <string_view>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/detection.h"
#include "detectors/markers/square_markers.h"

namespace linecal {

struct CharucoOptions {
  MarkerDetectOptions markers;
  // Gaussian blur of the saddle fit, pixels. Below the checker detector's 1.5: the fit's
  // window stays in the white margin between a corner and its markers (an eighth of the square
  // at OpenCV's usual 3/4 markers), and a wider blur carries the markers' black borders into
  // it (pose grid of tests/detectors/charuco: worst clean RMS 0.060 px at 1.5, 0.041 at 1.0).
  // [0.5, 4].
  double blur_sigma_px = 1.0;
  // A marker is kept when a neighbour's centre lies within this fraction of the local square
  // side of where the marker's homography puts it. A misread or foreign marker is off by a
  // square or more; noise on a 12 px marker and a strong lens over two squares move the
  // prediction by a few percent. (0, 0.5].
  double max_neighbour_error = 0.25;

  // Empty when valid, else the name of the first field out of range. O(1).
  std::string_view Validate() const;
};

// Finds `board` (type kCharuco; any other type gives kWrongBoard) in `image`. found = true with
// every inner corner (ids 0..(cols-1)(rows-1)-1, row-major from the top-left) when all pass;
// found = false, kPartial with the corners that pass, ordered by id, when some do not (part of
// the board out of view or hidden); otherwise found = false, no features, and the reason:
// kBadImage (invalid view or options), kLowContrast or kNoCandidates (the marker scan's),
// kWrongBoard (markers, but none of the board's ids; or a marker on the board's page that the
// board does not print there: another id, an id read twice, or the board seen shifted by whole
// squares, as the other layout of the legacy flag is), kAmbiguous (two groups of agreeing
// markers of the same size: two placements of the board), kTooFewFeatures (no two of the
// board's markers agree, or no corner passes). Pure function. Cost: the marker scan (about
// 3 ms at 1280 x 720) plus a small blur and fit per corner: about 5 ms for a 7 x 5 board at
// 1280 x 720 (tests/detectors/charuco); a partial board of small markers adds the detection on
// its doubled patch (4 times the patch's pixels); one still not whole adds the X-corner search
// on its doubled region.
Detection DetectCharuco(const ImageView8& image, const Board& board,
                        const CharucoOptions& options = {});

}  // namespace linecal

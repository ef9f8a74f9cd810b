#pragma once
// Detector of the circle board (`circle`, docs/boards.md §2, docs/boards.md): 30 circles of
// 50 mm (times the board's scale) on three black areas, 28 white on black and the black
// pair (ids 14, 15) on a white bar. Features: the 30 circle centres, id 6 * row + col.
//
// Method:
//  1. Candidates (circle_blobs.h): the image averaged 2 x 2 (half the pixels, half the
//     noise), classified against its local mean (a window of about a fifth of the image)
//     with an offset that is a fraction of the local range, so the threshold follows
//     illumination gradients and areas without printed contrast stay unclassified;
//     4-connected components of the light and of the dark class whose area, bounding box and
//     second moments are those of a filled ellipse are blob candidates of either polarity.
//  2. Identification: each pair of dark blobs whose distance, measured in the metric of
//     their own ellipses (which undoes the local perspective), is that of the black pair
//     and whose midpoint is light seeds a local board-to-image affine map; the grid grows
//     outwards from the pair, circle by circle in order of board distance, matching the
//     blob of the expected polarity nearest to each prediction and refitting a homography
//     as matches accumulate.
//  3. Sub-pixel (circle_edge_fit.h): every one of the 30 circles is measured from the image,
//     seeded by the ellipse the homography predicts (so circles whose blobs merged with a
//     neighbour under blur are measured too): the strongest edge of the expected polarity
//     along rays from the predicted centre (parabolic peak of the profile's derivative),
//     then a direct ellipse fit with outlier rejection, twice.
//  4. Perspective: the image of a circle's centre is not the centre of its image ellipse.
//     The offset is predicted from the board homography and the printed radius
//     (ImageOfCircle) and subtracted, and the homography is refitted to the corrected
//     centres, three times (the offset depends on H only weakly, so this converges at once).
//  5. Verification of the whole board: the homography fits every corrected centre within a
//     fraction of that circle's image radius, and the page's asymmetry fixes the
//     orientation: the circle grid alone is symmetric under 180 degrees, but the black areas
//     reach 170 mm below the last row and end 50 mm above the first, so points 75 mm below
//     the last row must be dark and their 180-degree images (in the white top margin) light,
//     measured against the bar (white) and the black between circles.
//
// Frames and units: image pixels, pixel-centre convention (docs/conventions.md); board frame in
// metres (board.h).

#include <string_view>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/detection.h"

namespace linecal {

struct CircleOptions {
  // Smallest difference between printed white and printed black, grey levels: image areas
  // with less local range are left unclassified, and an image with less range overall is
  // kLowContrast. 20 is above the spread of sensor noise of sigma 6 averaged 2 x 2 over
  // the candidate stage's neighbourhoods, and well below the contrast of a lit print
  // (about 150 levels; 60 at the dark end of a 4:1 gradient with gamma 0.6). [4, 200].
  int min_contrast = 20;
  // Rays per circle for the sub-pixel edge fit: 64 edge points average the noise of single
  // edge positions (about 0.1-0.2 px at sigma 4) down to a few hundredths of a pixel in
  // the centre, at a cost of about 10 microseconds per circle. [16, 256].
  int edge_rays = 64;
  // The board homography must fit every corrected centre within this fraction of that
  // circle's image radius: a wrong identification is off by a whole pitch (2.8 radii),
  // while the lens distortion of a board over the middle of a typical station camera stays
  // far below it. (0, 1].
  double max_residual_radius_fraction = 0.2;
  // Correct each centre for the perspective offset between the image of a circle's centre
  // and the centre of its image ellipse (step 4). Off: the features are the ellipse
  // centres (for comparison; biased by up to a pixel at strong perspective).
  bool correct_perspective = true;

  // Empty when valid, else the name of the first field out of range ("edge_rays").
  std::string_view Validate() const;
};

// Finds the circle `board` (board.type() must be kCircle, else reason kWrongBoard) in
// `image`. found = true with all 30 features ordered by id (uv_px the perspective-corrected
// image of each circle's centre), or found = false with a reason and no features:
// kBadImage (invalid view, a side below 16 px, or invalid options), kLowContrast,
// kNoCandidates (no blobs), kTooFewFeatures (no black pair with a grid around it),
// kVerificationFailed (a grid that failed the sub-pixel fit, the homography or the
// orientation test), kAmbiguous (two boards verified). Pure function, no allocation beyond
// the call. Cost on one core: about 3 ms at 1280 x 720; about 2.5 times that at
// 2448 x 2048 when the board covers a fair part of the image (coarse candidate stage),
// up to about 7 times when its circles are small (the fine stage runs too).
Detection DetectCircleBoard(const ImageView8& image, const Board& board,
                            const CircleOptions& options = {});

}  // namespace linecal

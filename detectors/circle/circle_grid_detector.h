#pragma once
// Detector of OpenCV's circle grids (`circle_grid`, docs/boards.md §8): cols x rows circles,
// symmetric or asymmetric (cv::findCirclesGrid's CALIB_CB_SYMMETRIC_GRID and
// CALIB_CB_ASYMMETRIC_GRID), and of BoofCV's hexagonal grid (`hexagonal`), dark circles on a
// light page or, when the board says so, light on dark. Features: the circle centres, id =
// cols * row + col, row 0 at the top of the print and col 0 at its left (OpenCV's order of
// object points); hexagonal: row by row from the top, left to right in a row (board.h).
//
// Method (docs/circle-detector.md, "Circle grids"):
//  1. Candidates: blobs of the board's polarity (circle_blobs.h), coarse to fine like the
//     circle board's detector.
//  2. Lattice: OpenCV's layouts are square lattices, the asymmetric one turned by 45 degrees
//     (its nearest neighbours are diagonal, spacing * sqrt(2) apart); the hexagonal grid is a
//     lattice of triangles, its basis a step along a row and one 60 degrees from it to the
//     next row (of the two reduced bases, 60 and 120 degrees apart, the first). A blob seeds
//     a lattice with the pair of its similar neighbours of which most neighbours are integer
//     combinations, reduced to the shortest, most nearly orthogonal basis in the metric of
//     the blob's own ellipse (which shows the print as seen face-on, an ellipse being the
//     image of a circle). The lattice grows breadth-first, each step predicted from the steps
//     last measured next to it, taking the similar blob nearest the prediction within 0.3 of
//     a step. Clutter that fits no prediction stays out; the predictions follow perspective
//     and real lens distortion alike.
//  3. Placements: every way the board's lattice points fit onto a grown lattice (four
//     rotations, six for the hexagonal grid; every offset) is a candidate, with at most one
//     circle in ten lacking its blob (cut by the image border, or lost to the threshold:
//     measured from a neighbour's ellipse moved by the lattice step). One whose lattice goes
//     on beyond one of its sides (three quarters of the positions there taken) belongs to a
//     larger grid and is refused (kWrongBoard).
//  4. Verification, local only (never one homography of the whole board, which a real lens
//     bends by tens of pixels): each centre against a quadratic through the other circles of
//     its 3 x 3 block of rows and columns (hexagonal: its 13 nearest circles, a circle, its
//     six neighbours and the six beyond), first the blobs' centroids (within a quarter of the
//     local pitch), then the sub-pixel centres (within max_residual_pitch_fraction of it,
//     half as much again per axis along which the circle lies at the board's edge); the page
//     between the circles (the midpoints of neighbours and the centres of lattice cells as
//     light as the page beside them: a checkerboard's squares touch at their corners;
//     hexagonal: the centroids of the lattice's triangles); every edge an ellipse's (a square
//     grid's squares are not); and the lattice square in each circle's own metric (not a
//     hexagonal or rectangular grid; hexagonal: its steps 60 degrees apart, not a square grid).
//  5. Sub-pixel: each circle's ellipse from its edge (circle_edge_fit.h), seeded by its blob;
//     its centre then from the grey levels over the ellipse and a ring of page around it
//     (ModelCentre: a blurred ellipse on a page lit by a plane, fitted by least squares; where
//     that fails, GreyCentroid: the centroid of each pixel's share of print, which a
//     point-symmetric blur leaves at the ellipse's centre), where the gap to its neighbours leaves
//     room for the ring (OpenCV's layouts; not BoofCV's hexagonal print, 0.2 diameter apart, which
//     keeps the edge fit's centre); the image of the circle's centre is not the ellipse's centre
//     under perspective, so the ellipse is taken back to the board through the homography
//     of its block, and the centre of that circle mapped forward (three rounds, each block's
//     homography refitted to the corrected centres). This needs no printed diameter.
//
// Orientation: the board's symmetries leave ids ambiguous: the symmetric grid is the same
// board turned by 180 degrees (and by 90 when cols == rows); the asymmetric grid is when rows
// is even (its first and last rows then start on opposite sides), and never when rows is odd
// (OpenCV's 4 x 11: its ids are fixed by the print); the hexagonal grid is the same turned by
// 180 degrees when cols and rows are both even or both odd (BoofCV's 28 x 24), never by 60
// or 120 (a rectangle turned so is none). Among the rotations the board allows, the
// detector chooses the one whose board x axis (along a row, towards higher col) points most
// nearly along the image's +u, as the checker detector does (the board as upright as
// possible). Use an asymmetric grid with an odd number of rows when the orientation matters.
//
// Frames and units: image pixels, pixel-centre convention (docs/conventions.md); board frame
// in metres (board.h).

#include <string_view>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/detection.h"

namespace linecal {

struct CircleGridOptions {
  // Smallest difference between printed white and black, grey levels (as CircleOptions):
  // areas with less local range are left unclassified; an image with less range overall is
  // kLowContrast. [4, 200].
  int min_contrast = 20;
  // Edge points per circle for the sub-pixel fit (circle_edge_fit.h). [16, 256].
  int edge_rays = 64;
  // Each sub-pixel centre must agree with the quadratic through the other circles of its
  // 3 x 3 block within this fraction of the local pitch (the image distance of nearest
  // neighbours), or 1 px, whichever is larger; half as much again per axis along which it
  // is extrapolated. A blob in place of a circle is off by a good part of a pitch (the
  // lattice takes blobs within 0.3 of it), while the quadratic follows perspective and a
  // fisheye's bending over three circles to a few hundredths of a pitch. (0, 0.5].
  double max_residual_pitch_fraction = 0.15;
  // Correct each centre for the perspective offset between the image of the circle's centre
  // and the centre of its image ellipse (Method, step 5). Off: the features are the ellipse
  // centres (for comparison; biased by up to a pixel at strong perspective).
  bool correct_perspective = true;
  // How each centre is measured (Method, step 5; circle_edge_fit.h), where the gap to the
  // neighbouring circles leaves room for the window of page around it (else the edge fit's):
  //  - kModelFit: a model of the window's grey levels fitted by least squares (ModelCentre:
  //    a blurred ellipse on a page lit by a plane) where the page shows noise (a grey level
  //    RMS or more about its plane), else (or where the fit fails) the grey centroid; on
  //    renders with noise 4 about a third closer than the grey centroid, the same on clean
  //    ones (docs/circle-detector.md); about 55 microseconds a circle of 18 px;
  //  - kGreyCentroid: the centroid of each pixel's share of print (GreyCentroid), about 10
  //    microseconds a circle;
  //  - kEdgeFit: the ellipse fitted to the edge points (for comparison; about 3 times the
  //    noise and 20 times the error on clean renders of the grey centroid).
  enum class Centre { kEdgeFit, kGreyCentroid, kModelFit };
  Centre centre = Centre::kModelFit;

  // Empty when valid, else the name of the first field out of range ("edge_rays").
  std::string_view Validate() const;
};

// Finds the circle grid `board` (board.type() must be kCircleGrid, else reason kWrongBoard)
// in `image`. found = true with all cols * rows features ordered by id (uv_px the
// perspective-corrected image of each circle's centre), or found = false with a reason and
// no features: kBadImage (invalid view, a side below 16 px, or invalid options),
// kLowContrast, kNoCandidates (no blobs of the board's polarity), kTooFewFeatures (no
// complete cols x rows grid of blobs), kVerificationFailed (grids that failed the local
// checks or the sub-pixel fit), kWrongBoard (every grid found is part of a larger one),
// kAmbiguous (two grids). When several reduction factors are searched, the reason is the one
// that got furthest. Pure function. Cost on one core, with the grey centroids: about 3 ms for
// a 9 x 6 board at 1280 x 720 with clutter, 4-6 ms for real 640 x 480 photos of 30-80
// circles, 9 ms for a 1280 x 720 photo of large circles; up to 30 ms for megapixel images
// with hundreds of small blobs (the lattice search grows from each). The model fit (the
// default) adds 50-170 microseconds a circle on noisy images, with the size of the circle:
// 7 ms for that 9 x 6 board.
Detection DetectCircleGrid(const ImageView8& image, const Board& board,
                           const CircleGridOptions& options = {});

}  // namespace linecal

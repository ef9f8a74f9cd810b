#pragma once
// The candidate stage shared by the circle detectors (circle_detector.h, circle_grid_detector.h):
// printed circles as blobs of a thresholded, reduced image.
//
// Method: the image averaged over factor x factor blocks (fewer pixels, less noise), classified
// against its local mean (a window of about a fifth of the image) with an offset that is a
// fraction of the local range, so that the threshold follows illumination gradients and areas
// without printed contrast stay unclassified; 4-connected components of the light and of the
// dark class whose area, bounding box and second moments are those of a filled ellipse are
// the blobs.
//
// Frames and units: full-resolution image pixels, pixel-centre convention
// (docs/conventions.md), whatever the reduction factor.

#include <Eigen/Core>
#include <vector>

#include "detectors/common/ellipse.h"
#include "detectors/core/image_view.h"

namespace linecal {

// A blob candidate: a light or dark region with the shape of a filled ellipse. Its edge is the
// threshold's, which blur and gamma move by up to about 2 px from the printed circle's
// (kMaxBlobEdgeShiftPx): a seed for an edge fit, not a measurement.
struct CircleBlob {
  Ellipse ellipse;         // from the region's moments, full-resolution pixels
  bool light = true;       // lighter than its surroundings (a white circle on black)
  double radius_px = 0.0;  // sqrt(semi_major * semi_minor)
  // The ellipse's shape matrix S: x is inside when (x - c)^T S^-1 (x - c) <= 1; px^2. It is the
  // image of the printed circle's local affine map: S = R^2 A A^T for a circle of radius R.
  Eigen::Matrix2d shape = Eigen::Matrix2d::Identity();
};

// The most a thresholded blob's edge moves from the printed circle's, full-resolution pixels:
// blur 1.5 px, gamma 0.6-1.6 and noise 6 of docs/acceptance.md's hardest renders moved the
// 12 px circles' dark blobs by up to 1.8 px.
inline constexpr double kMaxBlobEdgeShiftPx = 2.0;

struct CircleBlobSearch {
  // The reduced image has less range than min_contrast: nothing printed can be in it.
  bool low_contrast = false;
  // The light blobs (when asked), then the dark ones, each in the order of their components'
  // first pixels (top to bottom, left to right).
  std::vector<CircleBlob> blobs;
};

// The blobs of `image` (a valid view of at least 16 px a side) at reduction `factor` (1, 2, 4,
// ...; the smallest circle it keeps is about 2.5 factor px across) against `min_contrast`
// (grey levels between printed white and black, [4, 200]), of the polarities asked for.
// Blobs touching the reduced image's border are left out (they may be cut). Cost: two passes
// over the image and one over the reduced one; about 1 ms at 1280 x 720, factor 2.
CircleBlobSearch FindCircleBlobs(const ImageView8& image, int factor, int min_contrast, bool light,
                                 bool dark);

// The coarsest reduction factor worth a search: the largest power of two whose reduced image
// keeps kMinCandidatePixels (a 1280 x 720 image stays at 2, 640 x 360; 2448 x 2048 starts at
// 4), at least 2. Searching from it down to 2 costs a large image little more than a small one
// when its circles are large, and ends where the smallest circles (12 px) still make blobs.
// O(1).
int CoarsestCircleBlobFactor(const ImageView8& image);

// About 50 reduced pixels per circle of a board over a third of the image: plenty for the
// blob stage.
inline constexpr double kMinCandidatePixels = 2e5;

}  // namespace linecal

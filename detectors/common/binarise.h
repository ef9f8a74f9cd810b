#pragma once
// Binarisation of printed patterns under uneven light, shared by the marker and chessboard
// detectors: a robust noise estimate, a local-contrast threshold (halfway between the local
// minimum and maximum over tiles, as AprilTag 3 does; low-contrast areas inherit the
// threshold of their neighbours), and a one-pixel erosion that separates dark shapes
// touching at a corner.
//
// Binary images are Image8 with 1 = set (dark), 0 = unset; pixel-centre convention
// (docs/conventions.md). Pure functions, no state.

#include "detectors/core/image_view.h"

namespace linecal {

// Image noise sigma in grey levels: Immerkaer's Laplacian-difference estimate made robust
// to edges (median absolute response over a sparse pixel grid). 0 for images under 3 x 3.
// The view must be valid. Cost: O(W * H / 8), about 0.2 ms at 1280 x 720.
double EstimateNoiseSigma(const ImageView8& image);

// 1 where a pixel is darker than the local minimum plus dark_fraction (in (0, 1); halfway by
// default) of the local range (over the 3 x 3 tiles of 4 x 4 pixels around its tile, taken
// on 2 x 2 pixel means); 0 elsewhere, including areas without min_contrast grey levels of
// local range that no neighbour's threshold reaches within 64 px. *max_contrast: the largest
// local range seen. The view must be valid. Cost: O(W * H), about 1.3 ms at 1280 x 720;
// allocates one byte per pixel.
Image8 BinariseDark(const ImageView8& image, int min_contrast, int* max_contrast,
                    double dark_fraction = 0.5);

// The binary image eroded by one pixel (a set pixel stays set only when its four neighbours
// are set; off-image counts as unset). Breaks one-pixel bridges between shapes that touch
// at a corner. O(W * H).
Image8 Erode(const Image8& in);

}  // namespace linecal

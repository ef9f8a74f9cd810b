#pragma once
// The whole-board paint check of the board detectors: does the image, binarised by
// BinariseDark (binarise.h), show the board's printed black and white where a fitted
// homography puts them? A board identified on the wrong pattern (another board, clutter)
// fails it even when its features fit the homography.

#include <Eigen/Core>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"

namespace linecal {

// True when the image agrees with the board's printed paint: of a 32 x 32 grid of probes
// over the page, those clear of printed edges by 3 px and inside the image, at least
// min_agreement of the black ones are dark in `dark` (1 = dark) and of the white ones light
// (each paint checked only when it has 8 probes or more; false with fewer than 8 in all).
// H_image_board maps board metres to image pixels; px_per_m is the board's scale in the
// image (for the edge clearance). Cost: 1024 paint look-ups, about 20 microseconds.
bool PaintAgrees(const Board& board, const Eigen::Matrix3d& H_image_board, const Image8& dark,
                 double px_per_m, double min_agreement);

}  // namespace linecal

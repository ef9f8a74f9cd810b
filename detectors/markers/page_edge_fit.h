#pragma once
// A marker's sides placed by fitting the blurred printed page to the grey levels across them.
//
// Why: an edge point taken as the centroid of the grey-level gradient (common/edge_lines.h)
// is unbiased only when nothing else printed lies within the blur of the edge. A small
// marker breaks that on every side: its border is one cell wide, a dark data cell may lie
// behind it, and on the round-hole board a black board cell lies beyond a quiet zone of
// under a cell. At 4 px cells and blur 1 px the centroids of differently foreshortened
// sides move by different amounts, 0.2-0.4 px, which no homography or single dilation takes
// out (docs/detectors.md). The board knows what is printed around each side, so the model
// of the profile can hold all of it.
//
// Image coordinates: pixels, pixel-centre convention (docs/conventions.md). Pure function.

#include <Eigen/Core>
#include <array>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"

namespace linecal {

// Refines *corners_px, the image positions of a marker's four corners (a convex quad,
// clockwise in the image), whose board-frame positions are corners_board (same order), and
// whose side is `cells` cells. Per side: profiles across it, one per pixel of its length
// between its corner cells (at most 32), sampled every pixel from 3 blur sigmas past the
// border's inner edge (at most two cells) to 3 sigmas outside (at most a cell). What the
// board prints along each profile's image ray (Board::PaintAt through the homography of the
// four corners) is a set of dark intervals [a, b], averaged over rays sqrt(3) sigma to either
// side (the blur along the side: the cells behind the border change along it); the model
//   I(s) = L + (D - L) * sum over intervals of (Phi((b + delta + theta u - s) / sigma) -
//                                                 Phi((a + delta + theta u - s) / sigma))
// (s along the outward normal, u along the side from its middle, Phi the normal CDF) is
// is fitted by Levenberg-Marquardt in delta, theta, sigma, L, D. The side's line moves by
// delta + theta u; the corners are the new lines' intersections. Twice: first on every
// third profile, with sigma 1.2 px assumed for the ranges, then on all, with the first
// pass's sigma and corners. Profiles that meet a hole or the page's edge within a pixel of
// their samples are skipped (what shows there is unknown).
// Returns false and leaves *corners_px as it was when a side keeps fewer than four profiles,
// a fit fails (no convergence, sigma outside [0.3, 3] px, contrast under min_contrast grey
// levels) or a corner would move more than half a cell in a pass or three quarters of a
// cell in all (the edge-point corners of the round-hole board's markers at 4 px cells, its
// black cells within a cell of their border, start up to half a cell off). Cost:
// O(profiles x samples x fit iterations); about 0.4 ms per ArUco marker of 4 px cells
// (docs/detectors.md).
bool FitMarkerSidesToPage(const ImageView8& image, const Board& board, int cells,
                          const std::array<Eigen::Vector2d, 4>& corners_board, double min_contrast,
                          std::array<Eigen::Vector2d, 4>* corners_px);

}  // namespace linecal

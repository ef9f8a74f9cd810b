#pragma once
// Straight printed edges at sub-pixel precision: a point of an edge found across it, a line
// fitted through such points, and the intersection of two lines. Corners where two straight
// edges meet (a marker quad's corners, a board's L-corners) are refined by intersecting the
// lines fitted to their edges: unlike a saddle fit, this needs no point symmetry around the
// vertex.
//
// Image coordinates: pixels, pixel-centre convention (docs/conventions.md). Pure functions.

#include <Eigen/Core>
#include <optional>
#include <span>

#include "detectors/core/image_view.h"

namespace linecal {

// True when BilinearGrey may sample at p: p in [0, width - 1) x [0, height - 1). O(1).
bool InsideForBilinearGrey(const ImageView8& image, const Eigen::Vector2d& p);

// The bilinear interpolation of an 8-bit view at (u, v), pixel-centre convention. The caller
// keeps (u, v) inside (InsideForBilinearGrey); there is no clamping. O(1).
double BilinearGrey(const ImageView8& image, double u, double v);

struct EdgePoint {
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();  // on the edge, pixels
  double weight = 0.0;  // the largest grey-level rise over half a pixel across the edge
};

// The edge crossing the segment from q - half_window_px * n to q + half_window_px * n, where
// n is the unit normal pointing from the edge's dark side to its light side: the centroid of
// the positive derivative along n (differences of bilinear samples half a pixel apart, every
// half pixel), less a floor of a quarter of its peak (noise and the tail of another edge).
// The window must hold this edge only. nullopt when the window (plus one pixel) leaves the
// image or the grey level never rises along n. At most 24 samples (half_window_px up to
// 5.75 px). Cost: O(half_window_px) samples.
std::optional<EdgePoint> MeasureEdgePoint(const ImageView8& image, const Eigen::Vector2d& q,
                                          const Eigen::Vector2d& n, double half_window_px);

struct Line2d {
  Eigen::Vector2d point = Eigen::Vector2d::Zero();  // a point of the line, pixels
  Eigen::Vector2d dir = Eigen::Vector2d::UnitX();   // unit direction
};

// The total-least-squares line through `points`, each weighted by its weight: the weighted
// centroid and the principal axis of the weighted scatter (closed form), its direction
// oriented along `towards` (dir . towards >= 0). nullopt with fewer than two points or no
// positive weight. O(n).
std::optional<Line2d> FitWeightedLine(std::span<const EdgePoint> points,
                                      const Eigen::Vector2d& towards);

// The intersection of two lines; nullopt when they are within about 3 degrees of parallel
// (sine of their angle below 0.05), where the point is not defined to any useful precision.
// O(1).
std::optional<Eigen::Vector2d> IntersectLines(const Line2d& a, const Line2d& b);

}  // namespace linecal

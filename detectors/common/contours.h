#pragma once
// Connected components of a binary image, the outer contours of components, and quads
// (convex four-sided polygons) approximated from those contours: the candidate stage of the
// square-marker detectors (ArUco, AprilTag).
//
// A binary image here is an ImageView8 whose non-zero pixels are "set" (foreground, e.g. the
// dark pixels of a thresholded image). Coordinates are pixel indices (x right, y down); a
// contour point is the centre of a boundary pixel (docs/conventions.md: pixel centres are
// integers).

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

#include "detectors/core/image_view.h"

namespace linecal {

// One connected component of set pixels.
struct Component {
  int area_px = 0;           // number of pixels
  int min_x = 0, min_y = 0;  // bounding box, inclusive
  int max_x = 0, max_y = 0;
  int first_x = 0, first_y = 0;  // its first pixel in raster order (topmost, then leftmost)
};

// A run of set pixels of one row: x0 to x1 - 1.
struct PixelRun {
  int x0 = 0;
  int x1 = 0;  // exclusive
  int y = 0;
};

struct ComponentLabels {
  int width = 0;
  int height = 0;
  // Per pixel, row-major: 0 for unset pixels, else 1 + the index of its component. Empty
  // when labelled without the label image (LabelComponents' label_image false).
  std::vector<std::int32_t> labels;
  std::vector<Component> components;
  // Without the label image: component c's runs are runs[run_begin[c]] to
  // runs[run_begin[c + 1] - 1], in raster order. Empty with the label image.
  std::vector<PixelRun> runs;
  std::vector<int> run_begin;

  std::int32_t LabelAt(int x, int y) const {
    return labels[static_cast<std::size_t>(y) * width + x];
  }
};

// Labels the 4-connected components of the set pixels of `binary` (valid view, checked by
// the caller). 4-connectivity keeps two dark squares that touch only at a corner apart.
// Cost: one pass over the pixels with union-find over runs, O(W * H); memory 4 bytes per
// pixel for the labels. Without label_image, each component's runs instead of the label
// image (about a tenth of the cost at 1280 x 720 is writing it): enough for
// TraceOuterContour and FindQuads, which give the same contours and quads either way.
ComponentLabels LabelComponents(const ImageView8& binary, bool label_image = true);

// The outer boundary of component `index` of `labels`, traced clockwise (as seen in the
// image, y down) by Moore-neighbour tracing from the component's first pixel: each boundary
// pixel's centre, in order, without repeating the start. A one-pixel component gives one
// point. Cost: O(perimeter); labelled without the label image, O(bounding box) more (the
// component's pixels drawn from its runs).
std::vector<Eigen::Vector2i> TraceOuterContour(const ComponentLabels& labels, int index);

// Douglas-Peucker approximation of a closed contour: the indices (increasing) of the
// contour points kept as polygon vertices, so that every contour point lies within
// epsilon_px of the polygon. Contours of fewer than 3 points give all their indices.
// Cost: O(n log n) typical, O(n^2) worst case.
std::vector<int> ApproximateClosedPolygon(const std::vector<Eigen::Vector2i>& contour,
                                          double epsilon_px);

struct QuadOptions {
  // Components with a bounding box side below this many pixels are skipped (the smallest
  // marker of docs/acceptance.md is 6 cells of 4 px, 24 px; perspective shortens it).
  int min_side_px = 10;
  // Skipped above this fraction of the image's larger side (a marker never fills the
  // image).
  double max_side_fraction = 0.95;
  // Douglas-Peucker tolerance relative to the contour's length (OpenCV's ArUco uses the same
  // 3%: large enough to absorb pixel steps and blur, small enough to keep a corner).
  double polygon_epsilon_fraction = 0.03;
  // Smallest quad side relative to its longest: rejects slivers (a square seen 80 degrees
  // off-axis is not readable anyway).
  double min_side_ratio = 0.15;
  // Quads with a corner closer than this to the image border are dropped: their outline may
  // be cut by the border.
  int min_border_distance_px = 2;
  // Neighbouring polygon vertices closer together than this fraction of the contour's length
  // are merged into their midpoint before the vertices are counted (0: never, as the marker
  // detectors use it). Blur and noise cut the acute corner of a small dark square by a
  // chamfer of a few pixels that the polygon keeps as two vertices; a square's true corners
  // are a quarter of the length apart. [0, 0.1].
  double merge_vertices_fraction = 0.0;
  // Above 4 (4: never, as the marker detectors use it): vertices that the contour between
  // their neighbours leaves within the polygon tolerance are dropped (Douglas-Peucker keeps
  // every point where it split: when its first chord joins two neighbouring corners of a
  // foreshortened square, the farthest point lies anywhere on the opposite side), and
  // polygons of 5 up to this many vertices give the quad whose sides lie on their four
  // longest edges, when the others are short and the polygon fills the quad
  // (kMinQuadAreaFraction). Blur and a gamma round a small square's corners into chamfers
  // of two vertices each; a disc, a hexagon or a pentagon fills under 0.8 of such a quad.
  // When that leaves more than four (both ends of a small square's side rounded into arcs,
  // on which the vertices fall anywhere), the largest quad inscribed in the contour, when it
  // and the contour each hold kMinQuadAreaFraction of the other's area. [4, 8].
  int max_polygon_vertices = 4;
};

// The smallest share of the quad of max_polygon_vertices that its polygon must fill: a
// square whose four corners are cut by a quarter of its side fills 0.875; a disc 0.785 of
// its square, a regular hexagon 0.75, a regular pentagon 0.69.
inline constexpr double kMinQuadAreaFraction = 0.85;

// A quad: corners as contour pixel centres, clockwise in the image (y down).
struct Quad {
  std::array<Eigen::Vector2d, 4> corners_px;
  int component = 0;  // index into ComponentLabels::components
};

// The quads of the components of `labels`: components of a plausible size whose outer
// contour approximates to a convex quadrilateral. Cost: O(total perimeter of the components
// of plausible size) after labelling.
std::vector<Quad> FindQuads(const ComponentLabels& labels, const QuadOptions& options = {});

}  // namespace linecal

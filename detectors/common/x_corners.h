#pragma once
// X-corner candidates: vertices where two dark squares touch diagonally (chessboard inner
// corners), found anywhere in an image, with their sub-pixel position and local geometry.
//
// Method: the determinant of the Hessian of the Gaussian-blurred image is strongly negative
// at a saddle, so R = Ixy^2 - Ixx Iyy has a local maximum at every X-corner (and at little
// else); local maxima of R above a floor set by the smallest printed contrast are checked
// on a ring of samples around them (exactly two dark and two bright sectors, opposite
// sectors alike, the centre the mean of the sectors: an X-corner, not an L-corner, edge,
// blob or two corners with a gap), then refined by the saddle fit of corner_refine.h; a
// peak whose ring fails is tested again at its saddle. The ring also gives the directions
// of the two edge lines through the vertex and the axis of the dark sectors.

#include <Eigen/Core>
#include <array>
#include <map>
#include <optional>
#include <span>
#include <string_view>
#include <utility>
#include <vector>

#include "detectors/common/corner_refine.h"
#include "detectors/common/image_filters.h"

namespace linecal {

// Coarse-to-fine X-corner searches (the checker, vertical and chessboard detectors) first
// search the image halved (HalvingPyramid) while its short side keeps this many pixels:
// one coarse level at 1280 x 720 (640 x 360), two at 2448 x 2048 (down to 612 x 512).
// A board is found on a level when its squares there are at least about 10 px (the 4 px
// ring and the 5 x 5 maxima need that): squares of 20 px and more at 1280 x 720, 40 px at
// 2448 x 2048; smaller boards pass down to the finer levels, which adds at most a third of
// the full-resolution search to their time. A coarser level would hold only boards that
// fill most of the image.
constexpr int kMinCoarseLevelSidePx = 360;

struct XCornerOptions {
  // Radius of the test ring, pixels. It must be below the distance to the nearest other
  // vertex (the smallest square side seen: docs/boards.md's smallest squares are 12 px, 8 px
  // when foreshortened by 50 degrees) and well above the blur. 2..32.
  double ring_radius_px = 4.0;
  // The darkest and brightest ring samples differ by at least this many grey levels: a
  // printed board under the dimmest lighting of docs/acceptance.md (gamma, 4:1 gradient) keeps
  // far more than this, while noise of sigma 6 rarely makes it alone. (0, 255].
  double min_contrast = 20.0;
  // At most this many response maxima are examined (the strongest first), bounding the
  // cost on textured images. 1..1e6.
  int max_candidates = 20000;
  // Accept vertices whose centre is lighter than the sectors make it: two dark squares that
  // meet across a thin light gap, as boards printed with squares that do not touch have
  // (Kalibr's checkerboards, 2-3 px apart in its photos). Off for boards whose squares
  // touch, where such a vertex is two corners of clutter.
  bool allow_light_centre = false;
  SaddleFitOptions saddle;

  // Empty when valid, else the first field out of range, named as a member `corners` of a
  // detector's options ("corners.ring_radius_px"), for the detectors' own Validate. O(1).
  std::string_view Validate() const;
};

struct XCorner {
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();  // sub-pixel vertex, pixel-centre convention
  // Unit directions (image, u right, v down) of the two edge lines through the vertex,
  // each defined up to sign; line_b is counter-clockwise from line_a by less than 180
  // degrees in the (u, v) plane.
  Eigen::Vector2d line_a = Eigen::Vector2d::UnitX();
  Eigen::Vector2d line_b = Eigen::Vector2d::UnitY();
  // Unit direction (up to sign) bisecting the two dark sectors.
  Eigen::Vector2d dark_axis = Eigen::Vector2d::UnitX();
  float contrast = 0.0f;  // bright minus dark ring samples, grey levels
};

// Every X-corner of `image`, whose blurred copy (GaussianBlur, sigma about 1.5 px: enough to
// make the Hessian stable under noise, small enough for 8 px squares) is `blurred` — the
// caller keeps it for later refinement. Options must satisfy the ranges above. The result
// is ordered by decreasing contrast; vertices closer than 2 px are merged. Cost: two passes
// over the image plus O(ring) per local maximum; a few ms at 1280 x 720.
std::vector<XCorner> FindXCorners(const ImageF& blurred, const XCornerOptions& options = {});

// The four local directions of a corner, in cyclic order k = 0..3: +line_a, +line_b,
// -line_a, -line_b (line_b is counter-clockwise from line_a, so the order is one rotation
// sense); k is taken modulo 4. O(1).
Eigen::Vector2d XCornerDirection(const XCorner& corner, int k);

// The graph of neighbouring vertices of a printed grid of X-corners: links[i][k] is the
// corner linked to corner i along its local direction k (XCornerDirection), or -1. A link
// joins a corner to its nearest corner within 25 degrees of that direction, which must lie
// on one of its own edge lines and have its dark axis turned by about 90 degrees (the
// vertices of one square edge); only mutual links are kept, and only those at most twice
// as long as the link on from either end along the same line (when there is one): a
// board's grid does not reach out to clutter beyond its edge. Image pixels; no failure (a
// lone corner has no links). With `blurred` (the image the corners were found in), a link
// must also run along a printed edge: dark on one side of it, light on the other, all the
// way; saddles of texture inside a square (the dots of an ECoCheck board) then no longer
// stand between two vertices of one edge. Cost: O(n^2) for n corners (about 1 ms for 1000),
// plus six samples per nearer candidate with `blurred`.
std::vector<std::array<int, 4>> LinkXCorners(const std::vector<XCorner>& corners,
                                             const ImageF* blurred = nullptr);

// A connected part of the link graph with integer grid coordinates.
struct XCornerGridCorner {
  int index = 0;  // into the corner list
  int gi = 0;     // grid coordinates, axes right-handed in the image
  int gj = 0;
};
struct XCornerComponent {
  std::vector<XCornerGridCorner> corners;  // at most one on each grid point
};

// Connected components of the link graph `links` (LinkXCorners) of `corners` with grid
// coordinates: global direction g (0 = +i, 1 = +j, 2 = -i, 3 = -j) is local direction
// (rotation[c] + g) % 4 of corner c. Coordinates spread breadth-first from each component's
// strongest corner (corners come by decreasing contrast). A link that contradicts the
// coordinates already given is not followed, and of two corners on one grid point the
// stronger stays: a stray saddle linked into a board (texture in a square, clutter at its
// edge) then costs the grid nothing, and whatever it moved is for the caller's verification
// of its windows to refuse. Unlinked corners belong to no component. O(n log n).
std::vector<XCornerComponent> GridComponents(const std::vector<XCorner>& corners,
                                             const std::vector<std::array<int, 4>>& links);

// Every w x h window of `component` that holds at least min_corners of its corners: each
// placement inside the component's extent (the component itself when it is that size; a grid
// grown into clutter, or a larger board, holds several), as the corners' indices, row-major
// (i fastest), -1 where a grid point holds none. min_corners = w * h gives the complete
// windows. O(extent * w * h).
std::vector<std::vector<int>> GridWindows(const XCornerComponent& component, int w, int h,
                                          int min_corners);

// The image position of a point of a w x h window of corners (corner (i, j) at uv[j * w + i],
// i right and j down) through the homography of the 3 x 3 block of corners nearest to it (2
// along a side of two corners): local, so that the bending of a real lens over the whole
// board (tens of pixels under a fisheye) moves it little. Blocks are fitted on first use and
// kept. `uv` is only read and must outlive the map; w, h >= 2.
class GridBlockMap {
 public:
  GridBlockMap(int w, int h, std::span<const Eigen::Vector2d> uv) : w_(w), h_(h), uv_(uv) {}

  // Window point (x, y) in corner units (square centres and points beyond the outer corners
  // are any real numbers); nullopt when its block is degenerate or the point maps to
  // infinity. O(1) after the block's first use.
  std::optional<Eigen::Vector2d> Map(double x, double y);

 private:
  const std::optional<Eigen::Matrix3d>& Block(int c0, int r0);

  int w_, h_;
  std::span<const Eigen::Vector2d> uv_;
  std::map<std::pair<int, int>, std::optional<Eigen::Matrix3d>> blocks_;
};

}  // namespace linecal

#include "detectors/charuco/charuco_detector.h"

#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

#include "detectors/common/corner_refine.h"
#include "detectors/common/edge_lines.h"
#include "detectors/common/homography.h"
#include "detectors/common/image_filters.h"
#include "detectors/common/x_corners.h"

namespace linecal {
namespace {

// Where each of the board's markers is printed: its square and its corners in the board frame
// (metres; top-left, top-right, bottom-right, bottom-left as seen facing the print, the order
// of DecodedMarker::corners_px).
struct PrintedMarker {
  int row = 0;
  int col = 0;
  std::array<Eigen::Vector2d, 4> corners_board;
};

struct CharucoGeometry {
  int rows = 0;  // squares
  double square_m = 0.0;
  Eigen::Vector2d top_left_board;      // the top-left corner of the top-left square
  std::vector<PrintedMarker> markers;  // by id
  std::vector<int> marker_of_square;   // row-major over the squares, -1: black
};

CharucoGeometry GeometryOf(const Board& board) {
  const BoardParams& p = board.params();
  CharucoGeometry g;
  g.rows = p.rows;
  g.square_m = p.square_m * p.scale;
  const double half_marker = 0.5 * p.marker_m * p.scale;
  g.top_left_board = Eigen::Vector2d(-0.5 * p.cols * g.square_m, 0.5 * p.rows * g.square_m);
  g.marker_of_square.assign(p.cols * p.rows, -1);
  for (int r = 0; r < p.rows; ++r) {
    for (int c = 0; c < p.cols; ++c) {
      if (!CharucoSquareHasMarker(p, r, c)) continue;
      const Eigen::Vector2d centre =
          g.top_left_board + g.square_m * Eigen::Vector2d(c + 0.5, -(r + 0.5));
      g.marker_of_square[r * p.cols + c] = static_cast<int>(g.markers.size());
      g.markers.push_back(PrintedMarker{r,
                                        c,
                                        {centre + Eigen::Vector2d(-half_marker, half_marker),
                                         centre + Eigen::Vector2d(half_marker, half_marker),
                                         centre + Eigen::Vector2d(half_marker, -half_marker),
                                         centre + Eigen::Vector2d(-half_marker, -half_marker)}});
    }
  }
  return g;
}

Eigen::Vector2d Centre(const std::array<Eigen::Vector2d, 4>& corners) {
  return 0.25 * (corners[0] + corners[1] + corners[2] + corners[3]);
}

// The board's markers read once each, by id (nullopt: not read, or read more than once).
std::vector<std::optional<DecodedMarker>> BoardMarkers(const MarkerScan& scan, int count) {
  std::vector<std::optional<DecodedMarker>> by_id(count);
  std::vector<int> reads(count, 0);
  for (const DecodedMarker& m : scan.markers) {
    if (m.id >= count) continue;
    if (++reads[m.id] == 1) by_id[m.id] = m;
  }
  for (int id = 0; id < count; ++id) {
    if (reads[id] > 1) by_id[id].reset();
  }
  return by_id;
}

// The homography of the markers `ids` (board metres to image pixels), through their corners.
std::optional<Eigen::Matrix3d> MarkersHomography(
    const CharucoGeometry& g, const std::vector<std::optional<DecodedMarker>>& read,
    const std::vector<int>& ids) {
  std::vector<Eigen::Vector2d> src;
  std::vector<Eigen::Vector2d> dst;
  for (int id : ids) {
    for (int k = 0; k < 4; ++k) {
      src.push_back(g.markers[id].corners_board[k]);
      dst.push_back(read[id]->corners_px[k]);
    }
  }
  // Four or eight exact correspondences: the DLT is the fit; refinement adds nothing worth it.
  const std::optional<HomographyFit> fit = FitHomography(src, dst, {.refine = false});
  if (!fit) return std::nullopt;
  return fit->H;
}

// How far marker j's centre is from where marker i's own homography puts it, in local square
// sides (infinity when i's homography fails).
double PredictionError(const CharucoGeometry& g,
                       const std::vector<std::optional<DecodedMarker>>& read, int i, int j,
                       const Eigen::Vector2d& centre_j_px) {
  const std::optional<Eigen::Matrix3d> H = MarkersHomography(g, read, {i});
  if (!H) return std::numeric_limits<double>::infinity();
  const double side_px = LocalSquareSide(*H, Centre(g.markers[i].corners_board), g.square_m);
  const Eigen::Vector2d predicted = ApplyHomography(*H, Centre(g.markers[j].corners_board));
  const double error = (predicted - centre_j_px).norm() / side_px;
  return std::isfinite(error) ? error : std::numeric_limits<double>::infinity();
}

// A marker of the scan seen where the board prints one: the printed marker's id and the scanned
// quad's corners in that marker's canonical order.
struct PrintedRead {
  int id = 0;
  DecodedMarker marker;
};

// Whether scanned marker m, whose centre the homography H (board metres to pixels, from a kept
// marker near it) puts at p_board on the page, is the marker the board prints there: p_board
// within max_neighbour_error squares of the centre of a square that holds a marker, and the
// image's cells inside m's quad, turned to that marker's orientation under H, disagreeing with
// its print in at most as many cells as a marker the board places may (the larger of the
// dictionary's correction bits and a sixth of its data bits, kPlacedMarkerMaxWrongFraction of
// square_markers.cc). A different marker there differs from it in at least the dictionary's
// minimum distance, more than twice its correction bits. nullopt otherwise.
std::optional<PrintedRead> AsPrintedMarker(const ImageView8& image, const CharucoGeometry& g,
                                           const MarkerFamily& family, const Eigen::Matrix3d& H,
                                           const DecodedMarker& m, const Eigen::Vector2d& p_board,
                                           const CharucoOptions& options, int min_contrast) {
  const Eigen::Vector2d from_top_left = (p_board - g.top_left_board) / g.square_m;
  const int col = static_cast<int>(std::floor(from_top_left.x()));
  const int row = static_cast<int>(std::floor(-from_top_left.y()));
  const int cols = static_cast<int>(g.marker_of_square.size()) / g.rows;
  if (row < 0 || row >= g.rows || col < 0 || col >= cols) return std::nullopt;
  const int id = g.marker_of_square[row * cols + col];
  if (id < 0) return std::nullopt;
  const Eigen::Vector2d square_centre =
      g.top_left_board + g.square_m * Eigen::Vector2d(col + 0.5, -(row + 0.5));
  if ((p_board - square_centre).norm() > options.max_neighbour_error * g.square_m) {
    return std::nullopt;
  }
  // The turn of m's corners nearest to where H puts the printed marker's.
  int best_turn = 0;
  double best_px = std::numeric_limits<double>::infinity();
  for (int turn = 0; turn < 4; ++turn) {
    double sum_px = 0.0;
    for (int k = 0; k < 4; ++k) {
      sum_px += (m.corners_px[(turn + k) % 4] - ApplyHomography(H, g.markers[id].corners_board[k]))
                    .norm();
    }
    if (sum_px < best_px) {
      best_px = sum_px;
      best_turn = turn;
    }
  }
  PrintedRead read;
  read.id = id;
  read.marker.id = id;
  for (int k = 0; k < 4; ++k) read.marker.corners_px[k] = m.corners_px[(best_turn + k) % 4];
  const std::optional<int> wrong =
      CellsDisagreeingWithMarker(image, family, id, read.marker.corners_px, min_contrast);
  // A sixth of the data bits: kPlacedMarkerMaxWrongFraction of square_markers.cc.
  const int data_bits = static_cast<int>(family.bit_cells.size());
  if (!wrong || *wrong > std::max(family.max_correction_bits, data_bits / 6)) return std::nullopt;
  read.marker.hamming = *wrong;
  return read;
}

// The markers that agree on one placement of the board. Two markers within two squares of each
// other on the board agree when either's homography puts the other within max_neighbour_error
// square sides of where it is read; the largest connected group of at least two is the board.
// Every other marker of the scan is then judged from the marker of that group nearest to it in
// the image (local, as a lens bends the board): one of the board's ids, read once, where that
// marker puts it joins the board (the far side of an occluder); any other whose centre that
// marker places on the board's page is a marker the board does not print there. A board seen
// shifted by whole squares (the legacy and current layouts of an even row count are such a shift
// of each other, with mostly the same ids) shows such markers; so does a board of another size.
// Markers off the page (another board beside this one) do not count; nor does a marker read
// where the board prints one, whose cells show that marker's print (AsPrintedMarker): a misread
// of the board's own marker (blur, glare) is left out rather than refusing the board. kept: by
// id, nullopt where not kept. Returns kNone, kTooFewFeatures (no group of two), kAmbiguous
// (another group as large that does not join: two placements) or kWrongBoard (a marker on the
// page that the board does not print there).
// O(markers^2).
DetectReason KeepBoardMarkers(const ImageView8& image, const Board& board, const CharucoGeometry& g,
                              const MarkerFamily& family, const MarkerScan& scan,
                              const CharucoOptions& options,
                              std::vector<std::optional<DecodedMarker>>* kept) {
  const std::vector<std::optional<DecodedMarker>> read = *kept;
  const int count = static_cast<int>(read.size());
  std::vector<int> group(count);
  for (int i = 0; i < count; ++i) group[i] = i;
  const auto root = [&group](int i) {
    while (group[i] != i) i = group[i] = group[group[i]];
    return i;
  };
  for (int i = 0; i < count; ++i) {
    for (int j = i + 1; j < count && read[i]; ++j) {
      if (!read[j] || std::abs(g.markers[j].row - g.markers[i].row) > 2 ||
          std::abs(g.markers[j].col - g.markers[i].col) > 2) {
        continue;
      }
      if (PredictionError(g, read, i, j, Centre(read[j]->corners_px)) <=
              options.max_neighbour_error ||
          PredictionError(g, read, j, i, Centre(read[i]->corners_px)) <=
              options.max_neighbour_error) {
        group[root(i)] = root(j);
      }
    }
  }
  std::vector<int> size(count, 0);
  for (int i = 0; i < count; ++i) {
    if (read[i]) ++size[root(i)];
  }
  const auto largest = std::max_element(size.begin(), size.end());
  if (*largest < 2) return DetectReason::kTooFewFeatures;
  const int board_group = static_cast<int>(largest - size.begin());
  // Another group as large: it must join this one (the board's two sides of an occluder), or
  // there are two placements of the board.
  int rival_group = -1;
  for (int i = 0; i < count; ++i) {
    if (i != board_group && size[i] == *largest) rival_group = i;
  }
  for (int i = 0; i < count; ++i) {
    if (read[i] && root(i) != board_group) (*kept)[i].reset();
  }

  const Eigen::Vector2d half_page = 0.5 * board.page_size_m();
  std::vector<std::optional<DecodedMarker>> joined = *kept;
  for (const DecodedMarker& m : scan.markers) {
    if (m.id < count && (*kept)[m.id] && (*kept)[m.id]->corners_px[0] == m.corners_px[0]) continue;
    const Eigen::Vector2d centre_px = Centre(m.corners_px);
    int nearest = -1;
    double nearest_px = std::numeric_limits<double>::infinity();
    for (int id = 0; id < count; ++id) {
      if (!(*kept)[id]) continue;
      const double d = (Centre((*kept)[id]->corners_px) - centre_px).norm();
      if (d < nearest_px) {
        nearest_px = d;
        nearest = id;
      }
    }
    if (m.id < count && read[m.id] && read[m.id]->corners_px[0] == m.corners_px[0] &&
        PredictionError(g, *kept, nearest, m.id, centre_px) <= options.max_neighbour_error) {
      joined[m.id] = m;
      continue;
    }
    const std::optional<Eigen::Matrix3d> H = MarkersHomography(g, *kept, {nearest});
    if (!H) continue;
    const Eigen::Vector2d p_board = ApplyHomography(H->inverse(), centre_px);
    if (std::abs(p_board.x()) < half_page.x() && std::abs(p_board.y()) < half_page.y()) {
      const std::optional<PrintedRead> printed =
          AsPrintedMarker(image, g, family, *H, m, p_board, options, scan.min_contrast);
      if (!printed) return DetectReason::kWrongBoard;
      // The board's own marker: joined when the scan read its id (it was dropped only for
      // being read twice, by a misread elsewhere), else a misread, left out.
      if (printed->id == m.id && !joined[m.id]) joined[m.id] = printed->marker;
    }
  }
  for (int i = 0; i < count && rival_group >= 0; ++i) {
    if (read[i] && root(i) == rival_group && !joined[i]) return DetectReason::kAmbiguous;
  }
  *kept = std::move(joined);
  return DetectReason::kNone;
}

// Reads the board's markers that the scan missed (too small or foreshortened for a quad of
// their own, or joined to the dark squares by blur) where the kept markers within two squares
// of theirs put them (ReadPlacedMarker: the expected id in the board's orientation, its
// corners within a quarter cell of the prediction); repeated while markers are added, so that
// a marker beyond a placed one is placed from it. At least two markers make the prediction:
// one alone extrapolates its own corners' errors over the squares between them.
// O(passes * markers * (markers + marker side)).
void PlaceMissedMarkers(const ImageView8& image, const CharucoGeometry& g,
                        const MarkerFamily& family, int min_contrast,
                        std::vector<std::optional<DecodedMarker>>* kept) {
  const int count = static_cast<int>(kept->size());
  for (bool added = true; added;) {
    added = false;
    for (int id = 0; id < count; ++id) {
      if ((*kept)[id]) continue;
      std::vector<int> near;
      for (int j = 0; j < count; ++j) {
        if ((*kept)[j] && std::abs(g.markers[j].row - g.markers[id].row) <= 2 &&
            std::abs(g.markers[j].col - g.markers[id].col) <= 2) {
          near.push_back(j);
        }
      }
      if (near.size() < 2) continue;
      const std::optional<Eigen::Matrix3d> H = MarkersHomography(g, *kept, near);
      if (!H) continue;
      std::array<Eigen::Vector2d, 4> predicted;
      for (int k = 0; k < 4; ++k) {
        predicted[k] = ApplyHomography(*H, g.markers[id].corners_board[k]);
      }
      if (!std::all_of(predicted.begin(), predicted.end(),
                       [](const Eigen::Vector2d& uv) { return uv.allFinite(); })) {
        continue;
      }
      const std::optional<DecodedMarker> placed =
          ReadPlacedMarker(image, family, id, predicted, min_contrast);
      if (!placed) continue;
      (*kept)[id] = placed;
      added = true;
    }
  }
}

// The kept markers in the squares rows r - 1 - ring .. r + ring and cols c - 1 - ring ..
// c + ring (those touching inner corner (r, c) and `ring` squares beyond), by id.
std::vector<int> MarkersAround(const CharucoGeometry& g,
                               const std::vector<std::optional<DecodedMarker>>& kept,
                               const BoardParams& p, int r, int c, int ring) {
  std::vector<int> ids;
  for (int sr = std::max(0, r - 1 - ring); sr <= std::min(p.rows - 1, r + ring); ++sr) {
    for (int sc = std::max(0, c - 1 - ring); sc <= std::min(p.cols - 1, c + ring); ++sc) {
      const int id = g.marker_of_square[sr * p.cols + sc];
      if (id >= 0 && kept[id]) ids.push_back(id);
    }
  }
  return ids;
}

// The homography of the kept markers around inner corner (r, c) (MarkersAround); nullopt when
// none is kept there.
std::optional<Eigen::Matrix3d> CornerHomography(
    const CharucoGeometry& g, const std::vector<std::optional<DecodedMarker>>& kept,
    const BoardParams& p, int r, int c, int ring) {
  const std::vector<int> ids = MarkersAround(g, kept, p, r, c, ring);
  if (ids.empty()) return std::nullopt;
  return MarkersHomography(g, kept, ids);
}

// Inner corner (r, c) where the kept markers of the 4 x 4 squares around it put it, for a
// corner whose saddle fit failed (blur and noise can leave a corner's small window in the
// white margin without a clear saddle): nullopt unless the prediction is an interpolation that
// holds, i.e. kept markers lie on both sides of the corner along both board axes, and one
// homography (with the dilation of their print, FitDilatedHomography) carries all their corners
// within max_residual_cells marker cells (a misplaced marker corner, or a lens that bends the
// neighbourhood, would move the prediction by as much).
// The caller checks the paint around it. The error is the markers' corners' (their edges are
// fitted over their whole sides), a small fraction of a pixel. O(markers).
std::optional<Eigen::Vector2d> InterpolatedCorner(
    const CharucoGeometry& g, const std::vector<std::optional<DecodedMarker>>& kept,
    const BoardParams& p, const MarkerFamily& family, const CharucoOptions& options, int r, int c,
    const Eigen::Vector2d& corner_board) {
  const std::vector<int> ids = MarkersAround(g, kept, p, r, c, 1);
  bool above = false;
  bool below = false;
  bool left = false;
  bool right = false;
  for (int id : ids) {
    above = above || g.markers[id].row < r;
    below = below || g.markers[id].row >= r;
    left = left || g.markers[id].col < c;
    right = right || g.markers[id].col >= c;
  }
  if (!(above && below && left && right)) return std::nullopt;
  // The markers' corners in the order of PrintedMarker::corners_board (top-left, top-right,
  // bottom-right, bottom-left; board y up) and their outward diagonals.
  const std::array<Eigen::Vector2d, 4> diagonals = {Eigen::Vector2d(-1, 1), Eigen::Vector2d(1, 1),
                                                    Eigen::Vector2d(1, -1),
                                                    Eigen::Vector2d(-1, -1)};
  std::vector<Eigen::Vector2d> p_board;
  std::vector<Eigen::Vector2d> outward;
  std::vector<Eigen::Vector2d> uv;
  for (int id : ids) {
    for (int k = 0; k < 4; ++k) {
      p_board.push_back(g.markers[id].corners_board[k]);
      outward.push_back(diagonals[k]);
      uv.push_back(kept[id]->corners_px[k]);
    }
  }
  // The dilation of the markers' dark print (gamma after blur) is taken out: the chessboard's
  // corner, a saddle between two dark squares, does not move with it.
  const std::optional<DilatedHomographyFit> fit =
      FitDilatedHomography(p_board, outward, uv, ids.size());
  if (!fit) return std::nullopt;
  const double marker_side_px = LocalSquareSide(fit->fit.H, corner_board, p.marker_m * p.scale);
  if (!(fit->fit.max_residual <=
        options.markers.max_residual_cells * marker_side_px / family.cells)) {
    return std::nullopt;
  }
  return ApplyHomography(fit->fit.H, corner_board);
}

// The largest saddle-fit window (half side, pixels) whose patch around uv_px stays inside the
// image: RefineXCornerOnPatch's patch reaches the window, a pixel of movement, the blur's 3 sigma
// and 2 pixels beyond it (one more for the pixel the start falls in). Near the image border a
// smaller window still fits a corner there.
double BorderRoomPx(const ImageView8& image, const Eigen::Vector2d& uv_px, double blur_sigma_px) {
  const double room = std::min(
      {uv_px.x(), uv_px.y(), image.width - 1.0 - uv_px.x(), image.height - 1.0 - uv_px.y()});
  return room - std::ceil(3.0 * blur_sigma_px) - 4.0;
}

// The radius of the largest disc about the image of p_board inside the image of the square of
// half side half_m about it: how far from the corner a window may reach, in pixels, whatever
// the direction (under perspective the square's image is narrowest across its acute angles).
// NaN when a corner maps to infinity.
double InscribedRadiusPx(const Eigen::Matrix3d& H, const Eigen::Vector2d& p_board, double half_m) {
  const Eigen::Vector2d centre = ApplyHomography(H, p_board);
  std::array<Eigen::Vector2d, 4> corners;
  const std::array<Eigen::Vector2d, 4> steps = {Eigen::Vector2d(-1, -1), Eigen::Vector2d(1, -1),
                                                Eigen::Vector2d(1, 1), Eigen::Vector2d(-1, 1)};
  for (int k = 0; k < 4; ++k) corners[k] = ApplyHomography(H, p_board + half_m * steps[k]);
  double radius = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d edge = corners[(k + 1) % 4] - corners[k];
    const Eigen::Vector2d to_centre = centre - corners[k];
    radius = std::min(radius,
                      std::abs(edge.x() * to_centre.y() - edge.y() * to_centre.x()) / edge.norm());
  }
  return radius;
}

// The most a corner fitted in the smaller window may differ from its point reflection
// (Asymmetry over 3 px), as a share of its grey range: noise 6 and JPEG leave a corner of the
// hard set at 0.03-0.17, the foreshortening of a board turned 50 degrees at 0.20; an occluder's
// edge 3 px from the corner (the smaller window's fit then lies 0.8 px off) at 0.30.
constexpr double kMaxSmallWindowAsymmetry = 0.25;

// How far the image about `corner` is from point-symmetric: the RMS difference of the grey at
// corner + d and corner - d over the window of half side half_px (pixel steps), over the grey
// range of those samples. nullopt when a sample leaves the image.
std::optional<double> Asymmetry(const ImageView8& image, const Eigen::Vector2d& corner,
                                int half_px) {
  double sum = 0.0, lo = 255.0, hi = 0.0;
  int n = 0;
  for (int dy = 0; dy <= half_px; ++dy) {
    for (int dx = -half_px; dx <= half_px; ++dx) {
      if (dy == 0 && dx <= 0) continue;
      const Eigen::Vector2d a = corner + Eigen::Vector2d(dx, dy),
                            b = corner - Eigen::Vector2d(dx, dy);
      if (!InsideForBilinearGrey(image, a) || !InsideForBilinearGrey(image, b)) return std::nullopt;
      const double ga = BilinearGrey(image, a.x(), a.y()), gb = BilinearGrey(image, b.x(), b.y());
      sum += (ga - gb) * (ga - gb);
      lo = std::min({lo, ga, gb});
      hi = std::max({hi, ga, gb});
      ++n;
    }
  }
  if (!(hi > lo)) return std::nullopt;
  return std::sqrt(sum / n) / (hi - lo);
}

// The saddle fit of the corner predicted at `predicted` (RefineXCornerOnPatch), whose white
// margins leave a disc of reach_px about it clear of the markers (InscribedRadiusPx): with a
// window of half side reach_px, then, when that fails, one whose corners stay inside that disc
// (half side reach_px / sqrt 2). On a board turned 50 degrees the margin narrows to 3 px, and
// the larger window's corners take in the markers' black borders, which turn the fit away from
// a saddle. Those borders are point-symmetric about the corner; an occluder's edge is not, and
// a fit in the smaller window beside one lies off the corner: the smaller window's corner is
// kept only when the image about it is nearly point-symmetric (kMaxSmallWindowAsymmetry).
// nullopt when both fail.
std::optional<Eigen::Vector2d> RefineInMargin(const ImageView8& image,
                                              const Eigen::Vector2d& predicted, double reach_px,
                                              double blur_sigma_px) {
  // RefineXCornerOnPatch's window is a third of the side it is given.
  if (std::optional<Eigen::Vector2d> refined =
          RefineXCornerOnPatch(image, predicted, 3.0 * reach_px, blur_sigma_px)) {
    return refined;
  }
  const std::optional<Eigen::Vector2d> inside =
      RefineXCornerOnPatch(image, predicted, 3.0 * reach_px / std::sqrt(2.0), blur_sigma_px);
  if (!inside) return std::nullopt;
  const std::optional<double> asymmetry = Asymmetry(image, *inside, 3);
  if (!asymmetry || *asymmetry > kMaxSmallWindowAsymmetry) return std::nullopt;
  return inside;
}

// True when both black squares at the corner look darker than both white ones: probes in the
// middle of the black squares' quarter next to the corner, and in the white squares' margin
// between the corner and the marker (half way along its diagonal). A probe off the image (a
// corner at the image's border) is left out; at least one of each paint must be in it (a board
// shifted by a square shows the opposite paints there). `dark_first`: the squares up
// left and down right of the corner are the black ones.
bool CornerPaintAgrees(const ImageView8& image, const Eigen::Matrix3d& H,
                       const Eigen::Vector2d& corner_board, double square_m, double margin_m,
                       bool dark_first, int min_contrast) {
  // Quarter-square into a black square: clear of its edges by far more than the blur.
  const double black_offset = 0.25 * square_m;
  const double white_offset = 0.5 * margin_m;
  const std::array<Eigen::Vector2d, 4> diagonals = {
      Eigen::Vector2d(-1, 1), Eigen::Vector2d(1, -1),   // up left, down right
      Eigen::Vector2d(1, 1), Eigen::Vector2d(-1, -1)};  // up right, down left
  double darkest_white = 255.0;
  double lightest_black = 0.0;
  int blacks = 0;
  int whites = 0;
  for (int k = 0; k < 4; ++k) {
    const bool black = (k < 2) == dark_first;
    const Eigen::Vector2d p_board =
        corner_board + (black ? black_offset : white_offset) * diagonals[k];
    const Eigen::Vector2d uv = ApplyHomography(H, p_board);
    if (!InsideForBilinearGrey(image, uv)) continue;
    const double grey = BilinearGrey(image, uv.x(), uv.y());
    if (black) {
      lightest_black = std::max(lightest_black, grey);
      ++blacks;
    } else {
      darkest_white = std::min(darkest_white, grey);
      ++whites;
    }
  }
  if (blacks == 0 || whites == 0) return false;
  // Half the marker scan's contrast: the white probes sit in a margin a few pixels wide, which
  // the blur darkens.
  return darkest_white - lightest_black >= 0.5 * min_contrast;
}

// The homography (board metres to pixels) of the corners found among the 5 x 5 inner corners
// centred on inner corner (r, c) (`found`: by id, nullopt where not found), when they are at
// least four and span two rows and two columns; nullopt otherwise. Refined chessboard
// corners place their neighbour better than the markers' edges do where those were not read
// or their fit failed (the board's own corner squares: markers on two sides only). O(25).
std::optional<Eigen::Matrix3d> FoundCornersHomography(
    const std::vector<std::optional<DetectedFeature>>& found, const BoardParams& p, int r, int c) {
  std::vector<Eigen::Vector2d> src;
  std::vector<Eigen::Vector2d> dst;
  int rows_seen = 0;
  int cols_seen = 0;
  for (int dr = -2; dr <= 2; ++dr) {
    bool row = false;
    for (int dc = -2; dc <= 2; ++dc) {
      const int rr = r + dr, cc = c + dc;
      if (rr < 1 || rr >= p.rows || cc < 1 || cc >= p.cols) continue;
      const std::optional<DetectedFeature>& f = found[(p.cols - 1) * (rr - 1) + (cc - 1)];
      if (!f) continue;
      src.push_back(f->p_board);
      dst.push_back(f->uv_px);
      row = true;
    }
    rows_seen += row ? 1 : 0;
  }
  for (int dc = -2; dc <= 2; ++dc) {
    for (int dr = -2; dr <= 2; ++dr) {
      const int rr = r + dr, cc = c + dc;
      if (rr < 1 || rr >= p.rows || cc < 1 || cc >= p.cols) continue;
      if (found[(p.cols - 1) * (rr - 1) + (cc - 1)]) {
        ++cols_seen;
        break;
      }
    }
  }
  if (src.size() < 4 || rows_seen < 2 || cols_seen < 2) return std::nullopt;
  const std::optional<HomographyFit> fit = FitHomography(src, dst);
  if (!fit) return std::nullopt;
  return fit->H;
}

}  // namespace

std::string_view CharucoOptions::Validate() const {
  if (const std::string_view bad = markers.Validate(); !bad.empty()) return bad;
  if (!(blur_sigma_px >= 0.5 && blur_sigma_px <= 4.0)) return "blur_sigma_px";
  if (!(max_neighbour_error > 0.0 && max_neighbour_error <= 0.5)) return "max_neighbour_error";
  return {};
}

namespace {

// The inner corners not found from the markers, looked for as a chessboard's: each predicted
// by the homography of the corners found around it (FoundCornersHomography), refined by the
// saddle fit in the white margin as the others, and kept when the paint around it agrees;
// repeated while corners are added. The ids stay those the markers gave the grid. Adds to
// detection->features, ordered by id. O(passes * corners * (25 + saddle fit)).
void FindCornersFromNeighbours(const ImageView8& image, const Board& board,
                               const CharucoGeometry& g, const CharucoOptions& options,
                               double margin_m, int min_contrast, Detection* detection) {
  const BoardParams& p = board.params();
  const int count = static_cast<int>(board.features().size());
  std::vector<std::optional<DetectedFeature>> found(count);
  for (const DetectedFeature& f : detection->features) found[f.id] = f;
  for (bool added = !detection->features.empty(); added;) {
    added = false;
    for (int id = 0; id < count; ++id) {
      if (found[id]) continue;
      const int r = id / (p.cols - 1) + 1, c = id % (p.cols - 1) + 1;
      const std::optional<Eigen::Matrix3d> H = FoundCornersHomography(found, p, r, c);
      if (!H) continue;
      const BoardFeature& feature = board.features()[id];
      const Eigen::Vector2d predicted = ApplyHomography(*H, feature.p_board);
      const double reach_px = std::min(InscribedRadiusPx(*H, feature.p_board, margin_m),
                                       BorderRoomPx(image, predicted, options.blur_sigma_px));
      if (!std::isfinite(reach_px)) continue;
      const std::optional<Eigen::Vector2d> refined =
          RefineInMargin(image, predicted, reach_px, options.blur_sigma_px);
      if (!refined) continue;
      const bool dark_first = !CharucoSquareHasMarker(p, r - 1, c - 1);
      if (!CornerPaintAgrees(image, *H, feature.p_board, g.square_m, margin_m, dark_first,
                             min_contrast)) {
        continue;
      }
      found[id] = DetectedFeature{id, *refined, feature.p_board, feature.marker};
      added = true;
    }
  }
  detection->features.clear();
  for (const std::optional<DetectedFeature>& f : found) {
    if (f) detection->features.push_back(*f);
  }
}

// DetectCharuco's marker path on a view already checked; `scan_out`, when given, receives the
// marker scan.
Detection DetectOnce(const ImageView8& image, const Board& board, const CharucoOptions& options,
                     MarkerScan* scan_out = nullptr) {
  Detection detection;
  const BoardParams& p = board.params();
  const CharucoGeometry g = GeometryOf(board);
  const int marker_count = static_cast<int>(g.markers.size());
  const MarkerFamily family = ArucoFamily(p.charuco_dictionary);
  const MarkerScan scan = ScanMarkers(image, family, options.markers, marker_count);
  if (scan_out != nullptr) *scan_out = scan;
  if (scan.markers.empty()) {
    detection.reason =
        scan.reason == DetectReason::kNone ? DetectReason::kNoCandidates : scan.reason;
    return detection;
  }
  std::vector<std::optional<DecodedMarker>> read = BoardMarkers(scan, marker_count);
  if (std::none_of(read.begin(), read.end(), [](const auto& m) { return m.has_value(); })) {
    detection.reason = DetectReason::kWrongBoard;
    return detection;
  }
  detection.reason = KeepBoardMarkers(image, board, g, family, scan, options, &read);
  if (detection.reason != DetectReason::kNone) return detection;
  PlaceMissedMarkers(image, g, family, scan.min_contrast, &read);

  // The white squares are white only in their margin around the marker: the saddle fit's
  // window stays inside it, where the corner looks like a chessboard's. (What lies beyond,
  // the markers' black borders, is point-symmetric about the corner too, so its blurred edge
  // does not move the fixed point; but it turns the fit away from a saddle where it fills
  // much of the window.)
  const double margin_m = 0.5 * (p.square_m - p.marker_m) * p.scale;
  for (int r = 1; r < p.rows; ++r) {
    for (int c = 1; c < p.cols; ++c) {
      const int id = (p.cols - 1) * (r - 1) + (c - 1);
      const BoardFeature& feature = board.features()[id];
      // First from the markers in the two squares that touch the corner (the most local: a
      // lens bends them least), then, where they were not read or the fit fails from there,
      // from the kept markers of the 4 x 4 squares around it (more markers average their
      // corners' errors under hard light and blur; still local).
      std::optional<Eigen::Vector2d> refined;
      std::optional<Eigen::Matrix3d> H;
      for (const int ring : {0, 1}) {
        H = CornerHomography(g, read, p, r, c, ring);
        if (!H) continue;
        const Eigen::Vector2d predicted = ApplyHomography(*H, feature.p_board);
        const double reach_px = std::min(InscribedRadiusPx(*H, feature.p_board, margin_m),
                                         BorderRoomPx(image, predicted, options.blur_sigma_px));
        if (!std::isfinite(reach_px)) continue;
        refined = RefineXCornerOnPatch(image, predicted, 3.0 * reach_px, options.blur_sigma_px);
        if (refined) break;
      }
      if (!refined) {
        refined = InterpolatedCorner(g, read, p, family, options, r, c, feature.p_board);
        if (!refined) continue;
        H = CornerHomography(g, read, p, r, c, 1);
      }
      // The square up left of the corner is black when it holds no marker.
      const bool dark_first = !CharucoSquareHasMarker(p, r - 1, c - 1);
      if (!CornerPaintAgrees(image, *H, feature.p_board, g.square_m, margin_m, dark_first,
                             scan.min_contrast)) {
        continue;
      }
      detection.features.push_back({id, *refined, feature.p_board, feature.marker});
    }
  }
  FindCornersFromNeighbours(image, board, g, options, margin_m, scan.min_contrast, &detection);
  if (detection.features.empty()) {
    detection.reason = DetectReason::kTooFewFeatures;
    return detection;
  }
  detection.found = detection.features.size() == board.features().size();
  detection.reason = detection.found ? DetectReason::kNone : DetectReason::kPartial;
  return detection;
}

// Marker cells below this many pixels are under what the marker scan is made for (4 px cells,
// docs/acceptance.md): blur joins such a marker to the black squares around it through the
// thin white margin, and no quad of its own is found.
constexpr double kSmallCellPx = 4.0;

// The patch [x0, x0 + w) x [y0, y0 + h) of `image` at twice its resolution, by bilinear
// interpolation: output pixel (x, y) samples the input at (x0 + (x + 0.5) / 2 - 0.5, ...),
// clamped to the image. O(w * h).
Image8 DoublePatch(const ImageView8& image, int x0, int y0, int w, int h) {
  // The patch is at least 2 x 2 (the caller's check), so the image is too.
  Image8 out(2 * w, 2 * h);
  for (int y = 0; y < out.height; ++y) {
    const double v = std::clamp(y0 + 0.5 * y - 0.25, 0.0, image.height - 1.0);
    const int top = std::min(static_cast<int>(v), image.height - 2);
    const double fy = v - top;
    for (int x = 0; x < out.width; ++x) {
      const double u = std::clamp(x0 + 0.5 * x - 0.25, 0.0, image.width - 1.0);
      const int left = std::min(static_cast<int>(u), image.width - 2);
      const double fx = u - left;
      const double upper = (1.0 - fx) * image.At(left, top) + fx * image.At(left + 1, top);
      const double lower = (1.0 - fx) * image.At(left, top + 1) + fx * image.At(left + 1, top + 1);
      out.at(x, y) = static_cast<std::uint8_t>(std::lround((1.0 - fy) * upper + fy * lower));
    }
  }
  return out;
}

// A partial detection whose markers' cells are under kSmallCellPx, looked for again on the
// board's part of the image at twice the resolution, where the markers' white margins are
// wide enough for the scan: the patch is the board's page where the corners found put it (their
// homography), with two squares more around it, clipped to the image. The features found there
// are returned in the image's pixels when there are more of them; otherwise `partial` itself.
// Only a board already identified by its verified corners is looked for again, so the
// upsampled scan adds no detection where there was none. Cost: the detection on a patch of 4
// times its pixels.
Detection DetectSmallMarkersUpsampled(const ImageView8& image, const Board& board,
                                      const CharucoOptions& options, Detection partial) {
  const BoardParams& p = board.params();
  std::vector<Eigen::Vector2d> src;
  std::vector<Eigen::Vector2d> dst;
  for (const DetectedFeature& f : partial.features) {
    src.push_back(f.p_board);
    dst.push_back(f.uv_px);
  }
  const std::optional<HomographyFit> fit = FitHomography(src, dst);
  if (!fit) return partial;
  const double cell_px = LocalSquareSide(fit->H, src.front(), p.marker_m * p.scale) /
                         ArucoDictionaryInfoOf(p.charuco_dictionary).marker_cells();
  if (!(cell_px < kSmallCellPx)) return partial;
  const Eigen::Vector2d half =
      0.5 * board.page_size_m() + Eigen::Vector2d::Constant(2.0 * p.square_m * p.scale);
  Eigen::AlignedBox2d box;
  for (const Eigen::Vector2d& corner :
       {Eigen::Vector2d(-half.x(), -half.y()), Eigen::Vector2d(half.x(), -half.y()),
        Eigen::Vector2d(half.x(), half.y()), Eigen::Vector2d(-half.x(), half.y())}) {
    box.extend(ApplyHomography(fit->H, corner));
  }
  if (!box.min().allFinite() || !box.max().allFinite()) return partial;
  const int x0 = std::max(0, static_cast<int>(std::floor(box.min().x())));
  const int y0 = std::max(0, static_cast<int>(std::floor(box.min().y())));
  const int x1 = std::min(image.width, static_cast<int>(std::ceil(box.max().x())) + 1);
  const int y1 = std::min(image.height, static_cast<int>(std::ceil(box.max().y())) + 1);
  if (x1 - x0 < 2 || y1 - y0 < 2 || 2 * (x1 - x0) > kMaxImageSide ||
      2 * (y1 - y0) > kMaxImageSide) {
    return partial;
  }
  const Image8 doubled = DoublePatch(image, x0, y0, x1 - x0, y1 - y0);
  Detection again = DetectOnce(doubled.view(), board, options);
  if (again.features.size() <= partial.features.size()) return partial;
  for (DetectedFeature& f : again.features) {
    // Output pixel x samples the input at x0 + x / 2 - 0.25 (DoublePatch).
    f.uv_px = Eigen::Vector2d(x0, y0) + 0.5 * f.uv_px - Eigen::Vector2d::Constant(0.25);
  }
  return again;
}

// ---- The board read from its chessboard corners ---------------------------------------------
//
// Where the markers' cells are too small for the marker scan (1-3 px), the board's inner
// corners are still the vertices of a chessboard, found as the checker detector finds them.
// What the single markers cannot tell (which corner is which), all of them together can: for
// each way the grid can lie on the board, the grey at every data cell of every marker is
// compared with the bit the board prints there, over all markers at once.

// A window of as many inner corners as the board has, as the X-corner links give it: w x h
// corners in the grid's own axes (i right, j down, right-handed in the image).
struct CornerWindow {
  int w = 0;
  int h = 0;
  std::vector<Eigen::Vector2d> uv;  // corner (i, j) at uv[j * w + i]
  std::vector<Eigen::Vector2d> dark_axis;
  std::vector<bool> present;  // false: no X-corner there, uv predicted
  const Eigen::Vector2d& At(int i, int j) const { return uv[j * w + i]; }
};

// The step from corner (i, j) to its neighbour along i (along j when `along_j`), one-sided at
// the window's edge. O(1).
Eigen::Vector2d WindowStep(const CornerWindow& win, int i, int j, bool along_j) {
  const int n = along_j ? win.h : win.w;
  const int at = along_j ? j : i;
  const int from = std::min(at, n - 2);
  return along_j ? win.At(i, from + 1) - win.At(i, from) : win.At(from + 1, j) - win.At(from, j);
}

// The parity (si + sj) % 2 of the window's dark squares, square (si, sj) lying between corners
// si - 1 and si along i and sj - 1 and sj along j: at each corner, the dark axis lies along
// either the diagonal through squares (i, j) and (i + 1, j + 1) or the other one. nullopt
// unless three quarters of the corners agree (a window that is no chessboard's). O(w h).
std::optional<int> DarkParity(const CornerWindow& win) {
  int votes[2] = {0, 0};
  for (int j = 0; j < win.h; ++j) {
    for (int i = 0; i < win.w; ++i) {
      if (!win.present[j * win.w + i]) continue;
      const Eigen::Vector2d si = WindowStep(win, i, j, false).normalized();
      const Eigen::Vector2d sj = WindowStep(win, i, j, true).normalized();
      const Eigen::Vector2d& axis = win.dark_axis[j * win.w + i];
      const bool main =
          std::abs(axis.dot((si + sj).normalized())) > std::abs(axis.dot((si - sj).normalized()));
      ++votes[(i + j + (main ? 0 : 1)) % 2];
    }
  }
  const int n = votes[0] + votes[1];
  for (int parity : {0, 1}) {
    if (4 * votes[parity] >= 3 * n) return parity;
  }
  return std::nullopt;
}

// The grey of every data cell of every light square of a window (the squares that hold the
// markers), in the window's axes: cell (a, b) of the n x n data cells of light square q is
// grey[(q * n + b) * n + a], a along i. Each is the mean of four samples a quarter cell from
// the cell's centre (an area, not a point, under noise), and each square's cells are centred
// on their mean: the vote compares the pattern inside a marker, not the light on it.
struct WindowCells {
  int n = 0;                                // data cells per side
  std::vector<std::array<int, 2>> squares;  // (si, sj) of each light square
  std::vector<double> grey;
};

std::optional<WindowCells> SampleWindowCells(const ImageView8& image, const CornerWindow& win,
                                             int dark_parity, const MarkerFamily& family,
                                             double inset) {
  GridBlockMap map(win.w, win.h, win.uv);
  WindowCells cells;
  cells.n = family.cells - 2 * family.border_cells;
  const double cell = (1.0 - 2.0 * inset) / family.cells;  // in squares
  for (int sj = 0; sj <= win.h; ++sj) {
    for (int si = 0; si <= win.w; ++si) {
      if ((si + sj) % 2 == dark_parity) continue;
      cells.squares.push_back({si, sj});
      const std::size_t first = cells.grey.size();
      for (int b = 0; b < cells.n; ++b) {
        for (int a = 0; a < cells.n; ++a) {
          const double x = si - 1 + inset + (family.border_cells + a + 0.5) * cell;
          const double y = sj - 1 + inset + (family.border_cells + b + 0.5) * cell;
          double sum = 0.0;
          for (const auto& [dx, dy] :
               {std::pair{-0.25, -0.25}, {0.25, -0.25}, {-0.25, 0.25}, {0.25, 0.25}}) {
            const std::optional<Eigen::Vector2d> uv = map.Map(x + dx * cell, y + dy * cell);
            if (!uv || !InsideForBilinearGrey(image, *uv)) return std::nullopt;
            sum += BilinearGrey(image, uv->x(), uv->y());
          }
          cells.grey.push_back(0.25 * sum);
        }
      }
      double mean = 0.0;
      for (std::size_t k = first; k < cells.grey.size(); ++k) mean += cells.grey[k];
      mean /= static_cast<double>(cells.grey.size() - first);
      for (std::size_t k = first; k < cells.grey.size(); ++k) cells.grey[k] -= mean;
    }
  }
  return cells;
}

// One way the window lies on the board: rotation k takes window point (x, y) (corner units) to
// the board's inner-corner coordinates (X, Y) — k = 0: (x, y); 1: (y, w-1-x); 2: (w-1-x,
// h-1-y); 3: (h-1-y, x) — all keeping the axes right-handed in the image as the board's
// columns right and rows down are for a camera facing the print.
Eigen::Vector2d ToBoardInner(const CornerWindow& win, int k, double x, double y) {
  switch (k) {
    case 0:
      return {x, y};
    case 1:
      return {y, win.w - 1 - x};
    case 2:
      return {win.w - 1 - x, win.h - 1 - y};
    default:
      return {win.h - 1 - y, x};
  }
}

// The marker bit each sampled cell shows under rotation k when the board's markers carry ids
// offset by `id_offset` (a board of the same layout whose ids start there): +1 white, -1
// black, in the order of WindowCells::grey. Empty when rotation k puts a light square of the
// window where the board prints no marker (the colours do not fit, or the window's shape).
std::vector<signed char> Template(const CornerWindow& win, const WindowCells& cells, int k,
                                  int id_offset, const CharucoGeometry& g,
                                  const MarkerFamily& family, double inset) {
  const int cols = static_cast<int>(g.marker_of_square.size()) / g.rows;
  const bool swapped = k % 2 == 1;
  if ((swapped ? win.h : win.w) != cols - 1 || (swapped ? win.w : win.h) != g.rows - 1) return {};
  std::vector<int> bit_of_cell(family.cells * family.cells, -1);
  const int bits = static_cast<int>(family.bit_cells.size());
  for (int i = 0; i < bits; ++i) {
    bit_of_cell[family.bit_cells[i][0] * family.cells + family.bit_cells[i][1]] = bits - 1 - i;
  }
  const double cell = (1.0 - 2.0 * inset) / family.cells;
  std::vector<signed char> t;
  t.reserve(cells.grey.size());
  for (const auto& [si, sj] : cells.squares) {
    const Eigen::Vector2d centre = ToBoardInner(win, k, si - 0.5, sj - 0.5);
    const int col = static_cast<int>(std::lround(centre.x() + 0.5));
    const int row = static_cast<int>(std::lround(centre.y() + 0.5));
    const int id = g.marker_of_square[row * cols + col];
    if (id < 0 || id + id_offset >= static_cast<int>(family.codes.size())) return {};
    const std::uint64_t code = family.codes[id + id_offset];
    for (int b = 0; b < cells.n; ++b) {
      for (int a = 0; a < cells.n; ++a) {
        const double x = si - 1 + inset + (family.border_cells + a + 0.5) * cell;
        const double y = sj - 1 + inset + (family.border_cells + b + 0.5) * cell;
        const Eigen::Vector2d p = ToBoardInner(win, k, x, y) + Eigen::Vector2d(1 - col, 1 - row);
        const int mc = static_cast<int>(std::floor((p.x() - inset) / cell));
        const int mr = static_cast<int>(std::floor((p.y() - inset) / cell));
        const int bit = bit_of_cell[mr * family.cells + mc];
        t.push_back(((code >> bit) & 1) != 0 ? 1 : -1);
      }
    }
  }
  return t;
}

// The outcome of the vote on one window.
struct GridVote {
  int rotation = -1;          // the winner's (ToBoardInner), -1 when there is none
  double margin = 0.0;        // its least margin over every other hypothesis, in noise sigmas
  double significance = 0.0;  // its score over the score's spread for a pattern it does not
                              // predict, in sigmas
};

// The rotations of the window on the board and the id offsets of boards of the same layout
// (ids from 0, from the marker count, twice that, ... while the dictionary has them; at most
// kMaxIdOffsets) are the hypotheses; each scores S = sum of cell grey times its printed bit
// (+1 white, -1 black). The winner must hold the board's own ids and beat every other
// hypothesis by a clear margin: S_best - S_other = 2 c D + noise over the D cells where the two
// print differently (c: the cells' contrast), whose noise has spread 2 sigma sqrt(D), sigma the
// residual of the cells about the winner's print (the fit of each square's cells to its bits:
// noise and the blur's mixing of neighbouring cells alike). And it must show the board at all:
// for a print unrelated to the image, S has spread |grey| (the bits as coin flips), so the
// winner's S / |grey| is its significance. O(hypotheses * cells).
constexpr int kMaxIdOffsets = 8;

GridVote VoteOnWindow(const CornerWindow& win, const WindowCells& cells, const CharucoGeometry& g,
                      const MarkerFamily& family, double inset) {
  struct Hypothesis {
    int rotation;
    int offset;
    std::vector<signed char> t;
    double score;
  };
  const int markers = static_cast<int>(g.markers.size());
  std::vector<Hypothesis> hyps;
  for (int o = 0; o < kMaxIdOffsets; ++o) {
    for (int k = 0; k < 4; ++k) {
      std::vector<signed char> t = Template(win, cells, k, o * markers, g, family, inset);
      if (t.empty()) continue;
      double s = 0.0;
      for (std::size_t p = 0; p < t.size(); ++p) s += t[p] * cells.grey[p];
      hyps.push_back({k, o, std::move(t), s});
    }
  }
  GridVote vote;
  if (hyps.size() < 2) return vote;
  const auto best = std::max_element(
      hyps.begin(), hyps.end(), [](const auto& a, const auto& b) { return a.score < b.score; });
  // The residual about the winner's print: each square's cells fitted by a + c t.
  const int per_square = cells.n * cells.n;
  double rss = 0.0, norm2 = 0.0;
  for (std::size_t q = 0; q < cells.squares.size(); ++q) {
    double st = 0.0, stt = 0.0, sx = 0.0, sxt = 0.0, sxx = 0.0;
    for (int m = 0; m < per_square; ++m) {
      const double t = best->t[q * per_square + m], x = cells.grey[q * per_square + m];
      st += t, stt += t * t, sx += x, sxt += x * t, sxx += x * x;
    }
    const double n = per_square;
    const double var_t = stt - st * st / n;
    const double cov = sxt - sx * st / n;
    const double var_x = sxx - sx * sx / n;
    rss += var_t > 0.0 ? var_x - cov * cov / var_t : var_x;
    norm2 += sxx;
  }
  const double dof = static_cast<double>(cells.grey.size()) - 2.0 * cells.squares.size();
  if (!(dof > 0.0) || !(norm2 > 0.0)) return vote;
  const double sigma = std::sqrt(std::max(rss, 0.0) / dof);
  vote.significance = best->score / std::sqrt(norm2);
  vote.margin = std::numeric_limits<double>::infinity();
  for (const Hypothesis& other : hyps) {
    if (&other == &*best) continue;
    int differ = 0;
    for (std::size_t p = 0; p < other.t.size(); ++p) differ += other.t[p] != best->t[p];
    // Two hypotheses that print alike cannot be told apart (no ArUco layout has two).
    if (differ == 0) return GridVote{};
    vote.margin = std::min(vote.margin, (best->score - other.score) /
                                            (2.0 * std::max(sigma, 1e-9) * std::sqrt(differ)));
  }
  if (best->offset == 0) vote.rotation = best->rotation;
  return vote;
}

// A vote is accepted when the winner beats every other hypothesis by this many sigmas of its
// noise: were another hypothesis the truth, the winner's lead would exceed it with a
// probability under 3e-7 (one-sided normal). And it must show the board's print with this
// significance: for a print unrelated to the image the score is about normal with that
// spread, so a window of 16 hypotheses reaches 6 with a probability under 1e-8. Measured
// (docs/detectors.md, photos_eval, searching whole images): the 531 windows of a ChArUco
// board's size on the corpus's photos other than IMG_7413.png's board reach at most 1.6 and 3.5;
// IMG_7413.png's board 21.2 and 12.6 (of at most 13.9, the square root of its 192 cells).
constexpr double kMinVoteMargin = 5.0;
constexpr double kMinVoteSignificance = 6.0;

// Where the board may lie whose markers the scan read with cells under kSmallCellPx (the
// cells the grid path is for): the box about each such marker of the board's ids reaching the
// board's longer side plus a square beyond it in every direction, their union clipped to the
// image, as [x0, x1) x [y0, y1). Markers of larger cells are the marker path's; where no
// marker of the board is read, nothing bounds the board and the grid is not looked for (an
// image without the board pays nothing for it). nullopt when there is no such marker.
std::optional<Eigen::AlignedBox2i> SmallMarkersRegion(const ImageView8& image, const BoardParams& p,
                                                      const MarkerFamily& family,
                                                      const MarkerScan& scan, int marker_count) {
  Eigen::AlignedBox2d box;
  for (const DecodedMarker& m : scan.markers) {
    if (m.id >= marker_count) continue;
    double side_px = 0.0;
    for (int k = 0; k < 4; ++k)
      side_px += 0.25 * (m.corners_px[(k + 1) % 4] - m.corners_px[k]).norm();
    if (!(side_px / family.cells < kSmallCellPx)) continue;
    const double reach_px = (std::max(p.cols, p.rows) + 1) * side_px * p.square_m / p.marker_m;
    const Eigen::Vector2d centre = Centre(m.corners_px);
    box.extend(centre - Eigen::Vector2d::Constant(reach_px));
    box.extend(centre + Eigen::Vector2d::Constant(reach_px));
  }
  if (box.isEmpty() || !box.min().allFinite() || !box.max().allFinite()) return std::nullopt;
  const Eigen::Vector2i lo(std::max(0, static_cast<int>(std::floor(box.min().x()))),
                           std::max(0, static_cast<int>(std::floor(box.min().y()))));
  const Eigen::Vector2i hi(std::min(image.width, static_cast<int>(std::ceil(box.max().x())) + 1),
                           std::min(image.height, static_cast<int>(std::ceil(box.max().y())) + 1));
  if (hi.x() - lo.x() < 2 || hi.y() - lo.y() < 2) return std::nullopt;
  return Eigen::AlignedBox2i(lo, hi);
}

// The windows of the board's inner-corner size (either way round) among the linked X-corners
// (GridComponents, as the checker detector finds a chessboard) of `region` of the image at
// twice the resolution (the X-corner test's ring of 4 px fits the white margins of 10-20 px
// squares there, 2-3 px wide at twice the resolution, not at the image's own), that hold at
// least three quarters of their corners; a missing corner is put where the homography of the
// window's corners puts it (for sampling the cells; the caller looks for it again once the
// board is placed). Image pixels. Cost: the X-corner search on 4 times the region's pixels.
std::vector<CornerWindow> InnerCornerWindows(const ImageView8& image, const BoardParams& p,
                                             const Eigen::AlignedBox2i& region) {
  const Eigen::Vector2i size = region.max() - region.min();
  if (2 * size.x() > kMaxImageSide || 2 * size.y() > kMaxImageSide) return {};
  const Image8 doubled = DoublePatch(image, region.min().x(), region.min().y(), size.x(), size.y());
  // The checker detector's blur and X-corner test (x_corners.h: 1.5 px).
  const ImageF blurred = GaussianBlur(doubled.view(), 1.5);
  std::vector<XCorner> corners = FindXCorners(blurred);
  const std::vector<XCornerComponent> components =
      GridComponents(corners, LinkXCorners(corners, &blurred));
  // Output pixel x of DoublePatch samples the input at x0 + x / 2 - 0.25.
  for (XCorner& c : corners) {
    c.uv_px = region.min().cast<double>() + 0.5 * c.uv_px - Eigen::Vector2d::Constant(0.25);
  }
  std::vector<CornerWindow> windows;
  std::vector<std::pair<int, int>> sizes = {{p.cols - 1, p.rows - 1}};
  if (p.cols != p.rows) sizes.emplace_back(p.rows - 1, p.cols - 1);
  for (const XCornerComponent& comp : components) {
    for (const auto& [w, h] : sizes) {
      for (const std::vector<int>& indices : GridWindows(comp, w, h, (3 * w * h + 3) / 4)) {
        CornerWindow win{w, h, {}, {}, {}};
        std::vector<Eigen::Vector2d> src, dst;
        for (int k = 0; k < w * h; ++k) {
          const bool present = indices[k] >= 0;
          win.present.push_back(present);
          win.uv.push_back(present ? corners[indices[k]].uv_px : Eigen::Vector2d::Zero());
          win.dark_axis.push_back(present ? corners[indices[k]].dark_axis
                                          : Eigen::Vector2d::UnitX());
          if (!present) continue;
          src.emplace_back(k % w, k / w);
          dst.push_back(win.uv.back());
        }
        const std::optional<HomographyFit> fit = FitHomography(src, dst);
        if (!fit) continue;
        for (int k = 0; k < w * h; ++k) {
          if (!win.present[k]) win.uv[k] = ApplyHomography(fit->H, Eigen::Vector2d(k % w, k / w));
        }
        windows.push_back(std::move(win));
      }
    }
  }
  return windows;
}

// The board's inner corners from the window under rotation k: the X-corners, each refined by
// the saddle fit in its white margin (RefineInMargin; where it fails, the X-corner search's own
// saddle fit stays), then the missing ones looked for as a chessboard's from them
// (FindCornersFromNeighbours). Ordered by id; found when all are there.
Detection WindowFeatures(const ImageView8& image, const Board& board, const CharucoGeometry& g,
                         const CornerWindow& win, int k, const CharucoOptions& options,
                         int min_contrast) {
  const BoardParams& p = board.params();
  const double margin_m = 0.5 * (p.square_m - p.marker_m) * p.scale;
  std::vector<std::optional<DetectedFeature>> found(board.features().size());
  for (int j = 0; j < win.h; ++j) {
    for (int i = 0; i < win.w; ++i) {
      if (!win.present[j * win.w + i]) continue;
      const Eigen::Vector2d inner = ToBoardInner(win, k, i, j);
      const int id = (p.cols - 1) * static_cast<int>(std::lround(inner.y())) +
                     static_cast<int>(std::lround(inner.x()));
      const BoardFeature& f = board.features()[id];
      found[id] = DetectedFeature{id, win.At(i, j), f.p_board, f.marker};
    }
  }
  Detection detection;
  for (std::optional<DetectedFeature>& f : found) {
    if (!f) continue;
    DetectedFeature refined = *f;
    const std::optional<Eigen::Matrix3d> H =
        FoundCornersHomography(found, p, f->id / (p.cols - 1) + 1, f->id % (p.cols - 1) + 1);
    const double reach_px = H ? std::min(InscribedRadiusPx(*H, f->p_board, margin_m),
                                         BorderRoomPx(image, f->uv_px, options.blur_sigma_px))
                              : std::numeric_limits<double>::quiet_NaN();
    if (std::isfinite(reach_px)) {
      if (const std::optional<Eigen::Vector2d> uv =
              RefineInMargin(image, f->uv_px, reach_px, options.blur_sigma_px)) {
        refined.uv_px = *uv;
      }
    }
    detection.features.push_back(refined);
  }
  FindCornersFromNeighbours(image, board, g, options, margin_m, min_contrast, &detection);
  detection.found = detection.features.size() == board.features().size();
  detection.reason = detection.found ? DetectReason::kNone : DetectReason::kPartial;
  return detection;
}

// Whether what the marker path saw agrees with the board the vote placed (`features`): every
// marker the scan read on the board's page is the marker printed there (AsPrintedMarker: its
// id, or a misread whose cells still show that print), and every corner the markers gave lies
// within a quarter of a square of the grid's corner of the same id. O(markers + corners).
bool MarkersAgree(const ImageView8& image, const Board& board, const CharucoGeometry& g,
                  const MarkerFamily& family, const MarkerScan& scan,
                  const std::vector<DetectedFeature>& features, const Detection& from_markers,
                  const CharucoOptions& options) {
  std::vector<Eigen::Vector2d> src, dst;
  for (const DetectedFeature& f : features) {
    src.push_back(f.p_board);
    dst.push_back(f.uv_px);
  }
  const std::optional<HomographyFit> fit = FitHomography(src, dst);
  if (!fit) return false;
  const Eigen::Matrix3d H_board_px = fit->H.inverse();
  const Eigen::Vector2d half_page = 0.5 * board.page_size_m();
  for (const DecodedMarker& m : scan.markers) {
    const Eigen::Vector2d p_board = ApplyHomography(H_board_px, Centre(m.corners_px));
    if (!p_board.allFinite() || (p_board.array().abs() > half_page.array()).any()) continue;
    const std::optional<PrintedRead> read =
        AsPrintedMarker(image, g, family, fit->H, m, p_board, options, scan.min_contrast);
    if (!read) return false;
  }
  for (const DetectedFeature& f : from_markers.features) {
    const double side_px = LocalSquareSide(fit->H, f.p_board, g.square_m);
    const auto same = std::find_if(features.begin(), features.end(),
                                   [&f](const DetectedFeature& e) { return e.id == f.id; });
    if (same == features.end() || !((same->uv_px - f.uv_px).norm() <= 0.25 * side_px)) {
      return false;
    }
  }
  return true;
}

// The board read from its inner-corner grid (the section's method), for a detection the
// markers left incomplete (`from_markers`, with the scan it came from): the one window whose
// vote is accepted, with every corner, when the markers agree; `from_markers` otherwise (no
// window, none or two accepted, or markers that disagree). Cost: the X-corner search over the
// image (a few ms at 1280 x 720) and O(cells) per window.
Detection DetectFromCornerGrid(const ImageView8& image, const Board& board,
                               const CharucoOptions& options, const MarkerScan& scan,
                               Detection from_markers) {
  const BoardParams& p = board.params();
  if (p.cols < 3 || p.rows < 3) return from_markers;  // a window of 2 x 2 corners holds nothing
  const CharucoGeometry g = GeometryOf(board);
  const MarkerFamily family = ArucoFamily(p.charuco_dictionary);
  const double inset = 0.5 * (p.square_m - p.marker_m) / p.square_m;
  std::optional<std::pair<CornerWindow, int>> accepted;
  const std::optional<Eigen::AlignedBox2i> region =
      SmallMarkersRegion(image, p, family, scan, static_cast<int>(g.markers.size()));
  if (!region) return from_markers;
  for (const CornerWindow& win : InnerCornerWindows(image, p, *region)) {
    const std::optional<int> dark_parity = DarkParity(win);
    if (!dark_parity) continue;
    const std::optional<WindowCells> cells =
        SampleWindowCells(image, win, *dark_parity, family, inset);
    if (!cells) continue;
    const GridVote vote = VoteOnWindow(win, *cells, g, family, inset);
    if (vote.rotation < 0 || vote.margin < kMinVoteMargin ||
        vote.significance < kMinVoteSignificance) {
      continue;
    }
    if (accepted) return from_markers;  // two placements of the board
    accepted.emplace(win, vote.rotation);
  }
  if (!accepted) return from_markers;
  Detection detection = WindowFeatures(image, board, g, accepted->first, accepted->second, options,
                                       scan.min_contrast);
  if (!detection.found ||
      !MarkersAgree(image, board, g, family, scan, detection.features, from_markers, options)) {
    return from_markers;
  }
  return detection;
}

// Markers too small to read, or none read, leave the board to its corner grid
// (DetectFromCornerGrid); markers that speak against the board (kWrongBoard, kAmbiguous) do
// not.
bool GridMayHoldTheBoard(DetectReason reason) {
  return reason == DetectReason::kPartial || reason == DetectReason::kTooFewFeatures ||
         reason == DetectReason::kNoCandidates;
}

}  // namespace

Detection DetectCharuco(const ImageView8& image, const Board& board,
                        const CharucoOptions& options) {
  Detection detection;
  detection.reason =
      CheckDetectorInput(image, board, BoardType::kCharuco, options.Validate().empty());
  if (detection.reason != DetectReason::kNone) return detection;
  MarkerScan scan;
  detection = DetectOnce(image, board, options, &scan);
  // Four corners fix the homography that places the patch.
  if (detection.reason == DetectReason::kPartial && detection.features.size() >= 4) {
    detection = DetectSmallMarkersUpsampled(image, board, options, std::move(detection));
  }
  if (!GridMayHoldTheBoard(detection.reason)) return detection;
  return DetectFromCornerGrid(image, board, options, scan, std::move(detection));
}

}  // namespace linecal

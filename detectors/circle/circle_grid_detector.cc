#include "detectors/circle/circle_grid_detector.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <queue>
#include <utility>
#include <vector>

#include "detectors/circle/circle_blobs.h"
#include "detectors/circle/circle_edge_fit.h"
#include "detectors/common/ellipse.h"
#include "detectors/common/homography.h"

namespace linecal {
namespace {

// ---- The board ----------------------------------------------------------------------------

int Mod2(int i) { return ((i % 2) + 2) % 2; }
int FloorDiv2(int i) { return (i - Mod2(i)) / 2; }

// What the detector needs of the board: its size and layout, and per feature id its position
// in spacings (OpenCV's object point over squareSize: X along a row, Y down the rows) and its
// lattice coordinates. OpenCV's layouts are square lattices: the symmetric grid's steps are
// (1, 0) and (0, 1); the asymmetric grid's are its diagonals (1, 1) and (-1, 1), so its
// lattice coordinates are ((X + Y) / 2, (Y - X) / 2) (X + Y is always even). The hexagonal
// grid's is a lattice of triangles: its steps are a = (1, 0) along a row and b = (1/2,
// sqrt(3)/2), to the next row's circle down and right, 60 degrees from a; circle (zig-zag
// column c, row i) is lattice point (floor((c - i) / 2), i) (c - i has one parity over the
// board). Every basis keeps the handedness of (X, Y).
struct GridModel {
  int cols = 0;
  int rows = 0;
  bool asymmetric = false;
  bool hexagonal = false;
  bool light = false;                    // light circles on a dark field
  std::vector<Eigen::Vector2d> xy;       // per id, spacings
  std::vector<Eigen::Vector2i> lattice;  // per id
  // Per id, the ids one lattice step along a and along b (-1 off the board).
  std::vector<std::array<int, 2>> next;
  // Lattice neighbours on the board (pairs of ids one step apart) and lattice cells (the ids
  // at p, p + a, p + b, p + a + b; hexagonal: triangles of three mutual neighbours): the print
  // between them is the page.
  std::vector<std::array<int, 2>> pairs;
  std::vector<std::array<int, 4>> cells;
  std::vector<std::array<int, 3>> triangles;
  // Per id, the circles that predict it (itself included): the 3 x 3 block of rows and
  // columns around it (BlockIds); hexagonal: its kHexBlock nearest on the board.
  std::vector<std::vector<int>> block;
  // Per id, how many of the board's edges it lies on (a first or last row; a first or last
  // column, or circle of its row), 0 to 2: along each its block extrapolates.
  std::vector<int> edges;
  // The lattice points just beyond the board's top, bottom, left and right sides.
  std::array<std::vector<Eigen::Vector2i>, 4> beyond;
  // Two neighbours along the middle row, for the board's x axis (XAxisU).
  std::array<int, 2> middle = {0, 0};

  int Id(int i, int j) const { return cols * i + j; }
  // Row i, col j (any integers, beyond the board too) in spacings.
  Eigen::Vector2i XY(int i, int j) const { return {asymmetric ? 2 * j + Mod2(i) : j, i}; }
  Eigen::Vector2i LatticeOf(const Eigen::Vector2i& xy_spacings) const {
    if (!asymmetric) return xy_spacings;
    return {(xy_spacings.x() + xy_spacings.y()) / 2, (xy_spacings.y() - xy_spacings.x()) / 2};
  }
  // The hexagonal grid's lattice point of zig-zag column c, row i.
  static Eigen::Vector2i HexLattice(int c, int i) { return {FloorDiv2(c - i), i}; }
  // The turns that map the lattice onto itself: quarter turns, or sixth turns of the
  // triangles.
  int Rotations() const { return hexagonal ? 6 : 4; }
  // Lattice point p turned by `rotation` of those turns (right-handed, as the lattice's axes).
  Eigen::Vector2i Rotate(const Eigen::Vector2i& p, int rotation) const;
};

Eigen::Vector2i GridModel::Rotate(const Eigen::Vector2i& p, int rotation) const {
  if (hexagonal) {
    // A sixth turn takes a to b and b to b - a.
    Eigen::Vector2i q = p;
    for (int k = 0; k < rotation; ++k) q = Eigen::Vector2i(-q.y(), q.x() + q.y());
    return q;
  }
  switch (rotation) {
    case 0:
      return p;
    case 1:
      return {-p.y(), p.x()};
    case 2:
      return -p;
    default:
      return {p.y(), -p.x()};
  }
}

// The ids of the 3 x 3 block of rows and columns around (i, j), moved inside the board at its
// edges (2 along a side of two), in row-major order.
std::vector<int> BlockIds(const GridModel& m, int i, int j) {
  const int r0 = std::clamp(i - 1, 0, std::max(0, m.rows - 3));
  const int c0 = std::clamp(j - 1, 0, std::max(0, m.cols - 3));
  std::vector<int> ids;
  for (int r = r0; r < std::min(m.rows, r0 + 3); ++r) {
    for (int c = c0; c < std::min(m.cols, c0 + 3); ++c) ids.push_back(m.Id(r, c));
  }
  return ids;
}

// OpenCV's layouts: cols x rows circles, id = cols * i + j.
void AddSquareLayout(GridModel* m) {
  for (int i = 0; i < m->rows; ++i) {
    for (int j = 0; j < m->cols; ++j) {
      const Eigen::Vector2i xy = m->XY(i, j);
      m->xy.push_back(xy.cast<double>());
      m->lattice.push_back(m->LatticeOf(xy));
      m->block.push_back(BlockIds(*m, i, j));
      m->edges.push_back((i == 0 || i == m->rows - 1) + (j == 0 || j == m->cols - 1));
    }
  }
  const auto beyond = [&](int side, int i, int j) {
    m->beyond[side].push_back(m->LatticeOf(m->XY(i, j)));
  };
  for (int j = 0; j < m->cols; ++j) {
    beyond(0, -1, j);
    beyond(1, m->rows, j);
  }
  for (int i = 0; i < m->rows; ++i) {
    beyond(2, i, -1);
    beyond(3, i, m->cols);
  }
  const int i = m->rows / 2;
  const int j = std::min((m->cols - 1) / 2, m->cols - 2);
  m->middle = {m->Id(i, j), m->Id(i, j + 1)};
}

// The hexagonal grid's block: a circle and its six neighbours and the six next beyond them
// (sqrt(3) spacings away), or as near to that as the board's edge allows.
constexpr int kHexBlock = 13;

// The ids of the k circles nearest to circle `id` (itself first among them), sorted; ties
// broken by id, so that the block is the same on every call. `xy`: the circles in rows
// (row r: ids row_start[r] to row_start[r + 1] - 1, left to right, rows kRowSpacings
// apart). Only the rows and columns within `reach` of the circle are searched, `reach`
// doubled until k circles lie within it: every circle nearer than the k-th is then among
// those searched, so the result is that of a search of the whole board, in O(k) per circle
// instead of O(circles).
std::vector<int> NearestCircles(const std::vector<Eigen::Vector2d>& xy,
                                const std::vector<int>& row_start, int id, int k) {
  constexpr double kRowSpacings = 0.86602540378443865;  // sqrt(3) / 2
  const int n = static_cast<int>(xy.size());
  const int rows = static_cast<int>(row_start.size()) - 1;
  k = std::min(n, k);
  const int row = static_cast<int>(std::upper_bound(row_start.begin(), row_start.end(), id) -
                                   row_start.begin() - 1);
  std::vector<std::pair<double, int>> by_distance;
  for (double reach = 2.0;; reach *= 2.0) {
    // One row and column more than reach needs: a margin for rounding.
    const int dr = static_cast<int>(reach / kRowSpacings) + 1;
    by_distance.clear();
    int within = 0;
    for (int r = std::max(0, row - dr); r <= std::min(rows - 1, row + dr); ++r) {
      for (int other = row_start[r]; other < row_start[r + 1]; ++other) {
        if (std::abs(xy[other].x() - xy[id].x()) > reach + 1.0) continue;
        const double d2 = (xy[other] - xy[id]).squaredNorm();
        by_distance.emplace_back(d2, other);
        within += d2 <= reach * reach;
      }
    }
    if (within >= k || static_cast<int>(by_distance.size()) == n) break;
  }
  std::partial_sort(by_distance.begin(), by_distance.begin() + k, by_distance.end());
  std::vector<int> ids;
  for (int q = 0; q < k; ++q) ids.push_back(by_distance[q].second);
  std::sort(ids.begin(), ids.end());
  return ids;
}

// BoofCV's hexagonal layout (docs/boards.md §8): row i from the top on the zig-zag columns
// (rows - 1 - i) % 2, + 2, ... below cols; ids row by row, left to right.
void AddHexagonalLayout(GridModel* m) {
  constexpr double kRowSpacings = 0.86602540378443865;  // sqrt(3) / 2
  const auto first = [&](int i) { return Mod2(m->rows - 1 - i); };
  const auto last = [&](int i) { return m->cols - 1 - Mod2(m->cols - 1 - first(i)); };
  std::vector<int> row_start;
  for (int i = 0; i < m->rows; ++i) {
    row_start.push_back(static_cast<int>(m->xy.size()));
    for (int c = first(i); c < m->cols; c += 2) {
      m->xy.emplace_back(0.5 * c, kRowSpacings * i);
      m->lattice.push_back(GridModel::HexLattice(c, i));
      m->edges.push_back((i == 0 || i == m->rows - 1) + (c == first(i) || c == last(i)));
    }
  }
  // The middle row's middle circle and the next; a row of one circle (three columns) has
  // rows of two next to it.
  int middle_row = m->rows / 2;
  if (first(middle_row) == last(middle_row)) --middle_row;
  const int middle = row_start[middle_row] + (last(middle_row) - first(middle_row)) / 4;
  m->middle = {middle, middle + 1};
  for (int c = Mod2(m->rows); c < m->cols; c += 2) {
    m->beyond[0].push_back(GridModel::HexLattice(c, -1));
  }
  for (int c = 1; c < m->cols; c += 2) m->beyond[1].push_back(GridModel::HexLattice(c, m->rows));
  for (int i = 0; i < m->rows; ++i) {
    m->beyond[2].push_back(GridModel::HexLattice(first(i) - 2, i));
    m->beyond[3].push_back(GridModel::HexLattice(last(i) + 2, i));
  }
  row_start.push_back(static_cast<int>(m->xy.size()));
  for (int id = 0; id < static_cast<int>(m->xy.size()); ++id) {
    m->block.push_back(NearestCircles(m->xy, row_start, id, kHexBlock));
  }
}

GridModel MakeModel(const BoardParams& p) {
  GridModel m;
  m.cols = p.cols;
  m.rows = p.rows;
  m.asymmetric = p.asymmetric;
  m.hexagonal = p.hexagonal;
  m.light = p.light_circles;
  if (m.hexagonal) {
    AddHexagonalLayout(&m);
  } else {
    AddSquareLayout(&m);
  }
  std::map<std::pair<int, int>, int> id_at;
  for (int id = 0; id < static_cast<int>(m.lattice.size()); ++id) {
    id_at[{m.lattice[id].x(), m.lattice[id].y()}] = id;
  }
  const auto at = [&](const Eigen::Vector2i& p) {
    const auto it = id_at.find({p.x(), p.y()});
    return it == id_at.end() ? -1 : it->second;
  };
  for (int id = 0; id < static_cast<int>(m.lattice.size()); ++id) {
    const Eigen::Vector2i p = m.lattice[id];
    const int a = at(p + Eigen::Vector2i(1, 0));
    const int b = at(p + Eigen::Vector2i(0, 1));
    const int ab = at(p + Eigen::Vector2i(1, 1));
    m.next.push_back({a, b});
    if (a >= 0) m.pairs.push_back({id, a});
    if (b >= 0) m.pairs.push_back({id, b});
    if (!m.hexagonal) {
      if (a >= 0 && b >= 0 && ab >= 0) m.cells.push_back({id, a, b, ab});
      continue;
    }
    // The triangles' third neighbour direction, b - a; the two triangles of the lattice
    // cell: (p, p + a, p + b) and (p + a, p + b, p + a + b).
    if (const int ba = at(p + Eigen::Vector2i(-1, 1)); ba >= 0) m.pairs.push_back({id, ba});
    if (a >= 0 && b >= 0) m.triangles.push_back({id, a, b});
    if (a >= 0 && b >= 0 && ab >= 0) m.triangles.push_back({a, b, ab});
  }
  return m;
}

// ---- Blobs --------------------------------------------------------------------------------

// Neighbouring circles differ in size by a few percent under perspective (a third at the
// steepest views the lattice has to follow), and the threshold moves small blobs' edges by up
// to kMaxBlobEdgeShiftPx.
bool SimilarSize(const CircleBlob& a, const CircleBlob& b) {
  const double lo = std::min(a.radius_px, b.radius_px);
  const double hi = std::max(a.radius_px, b.radius_px);
  return hi <= 1.4 * lo + kMaxBlobEdgeShiftPx;
}

// Blobs sorted by u, for the nearest blobs to a point: a sweep outwards from the point's u
// that stops where |du| alone exceeds the best distance so far.
class BlobIndex {
 public:
  explicit BlobIndex(const std::vector<CircleBlob>& blobs) : blobs_(blobs) {
    for (int i = 0; i < static_cast<int>(blobs.size()); ++i) order_.push_back(i);
    std::sort(order_.begin(), order_.end(), [&](int a, int b) { return U(a) < U(b); });
    for (int i : order_) sorted_u_.push_back(U(i));
  }

  // Up to k blobs nearest to p within max_px that pass ok(blob), nearest first.
  template <typename Ok>
  std::vector<int> Nearest(const Eigen::Vector2d& p, int k, double max_px, Ok&& ok) const {
    std::vector<std::pair<double, int>> best;  // (squared distance, blob), sorted
    double limit = max_px * max_px;
    const int n = static_cast<int>(order_.size());
    const int start = static_cast<int>(std::lower_bound(sorted_u_.begin(), sorted_u_.end(), p.x()) -
                                       sorted_u_.begin());
    // Outwards on both sides in turn, each side stopping once its |du| passes the limit.
    for (int lo = start - 1, hi = start; lo >= 0 || hi < n;) {
      for (int side = 0; side < 2; ++side) {
        int& s = side == 0 ? hi : lo;
        if (s < 0 || s >= n) continue;
        const double du = sorted_u_[s] - p.x();
        if (du * du > limit) {
          s = side == 0 ? n : -1;
          continue;
        }
        const int b = order_[s];
        s += side == 0 ? 1 : -1;
        const double d2 = (blobs_[b].ellipse.centre - p).squaredNorm();
        if (d2 > limit || !ok(b)) continue;
        best.insert(std::upper_bound(best.begin(), best.end(), std::make_pair(d2, b)), {d2, b});
        if (static_cast<int>(best.size()) > k) best.pop_back();
        if (static_cast<int>(best.size()) == k) limit = best.back().first;
      }
    }
    std::vector<int> out;
    for (const auto& [d2, b] : best) out.push_back(b);
    return out;
  }

 private:
  double U(int i) const { return blobs_[i].ellipse.centre.x(); }

  const std::vector<CircleBlob>& blobs_;
  std::vector<int> order_;
  std::vector<double> sorted_u_;
};

// ---- 2. Lattice ---------------------------------------------------------------------------

// A lattice grown from a seed blob: per lattice point (a, b), the blob there and the image
// steps to the neighbours at (a + 1, b) and (a, b + 1), as last measured around it.
struct LatticePoint {
  int blob = -1;
  std::array<Eigen::Vector2d, 2> step;
};
using Lattice = std::map<std::pair<int, int>, LatticePoint>;

// Two lattice steps fit the neighbours of a blob when this many of them (the steps included)
// are integer combinations of the steps, within kLatticeFit of a step: an inner point of the
// grid has eight (its four nearest and four diagonal neighbours); three (the steps and one
// more, as at the board's corner) is the least that checks the steps at all.
constexpr int kMinFittedNeighbours = 3;
// Neighbours one or two steps away are within a fifth of a step of integer combinations: a
// steep view changes the step by up to a tenth from one circle to the next.
constexpr double kLatticeFit = 0.2;

// A blob's two lattice steps: of the pairs of its similar neighbours, the pair of which most
// neighbours are integer combinations (so that it spans the whole lattice, not every other
// point), reduced (Lagrange-Gauss) to the shortest and most nearly orthogonal basis of the
// same lattice in the metric of the blob's ellipse. That metric shows the print as seen
// face-on (an ellipse is the image of a circle, S = R^2 A A^T for the local affine map A), up
// to the threshold's edge shift, which turns a steep view of a small circle's lattice by a
// dozen degrees: far from the 30 degrees at which another basis of the same square lattice
// would be the reduced one. The second step is turned so that the two are right-handed in the
// image, as the board's X and Y are for a camera facing the print. A lattice of triangles
// (hexagonal) has two reduced bases, 60 and 120 degrees apart: the second step becomes the
// sum of the two where they are over 90 degrees apart, so that it lies 60 degrees from the
// first as the board's b does from a. nullopt when no pair fits kMinFittedNeighbours.
std::optional<std::array<Eigen::Vector2d, 2>> SeedSteps(const std::vector<CircleBlob>& blobs,
                                                        const BlobIndex& index, int seed,
                                                        bool hexagonal) {
  const CircleBlob& a = blobs[seed];
  // Eight neighbours hold an inner point's four nearest and four diagonal ones; the search
  // reaches 20 radii, beyond any printed grid's pitch (OpenCV's asymmetric grids: 3-4 radii).
  const std::vector<int> near = index.Nearest(a.ellipse.centre, 8, 20.0 * a.radius_px, [&](int b) {
    return b != seed && SimilarSize(a, blobs[b]);
  });
  if (static_cast<int>(near.size()) < kMinFittedNeighbours) return std::nullopt;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(a.shape);
  if (eig.info() != Eigen::Success || !(eig.eigenvalues().minCoeff() > 0.0)) return std::nullopt;
  const Eigen::Matrix2d rectify = eig.operatorInverseSqrt();
  std::vector<Eigen::Vector2d> v;
  for (const int b : near) v.push_back(blobs[b].ellipse.centre - a.ellipse.centre);
  int best_fitted = 0;
  std::array<Eigen::Vector2d, 2> steps;
  for (std::size_t k = 0; k < v.size(); ++k) {
    for (std::size_t l = k + 1; l < v.size(); ++l) {
      Eigen::Matrix2d basis;
      basis << v[k], v[l];
      const Eigen::Vector2d qk = rectify * v[k], ql = rectify * v[l];
      // Steps less than 30 degrees apart in the print's metric are no basis of a square
      // lattice (a square lattice's bases are at least 60 degrees apart).
      if (std::abs(qk.x() * ql.y() - qk.y() * ql.x()) < 0.5 * qk.norm() * ql.norm()) continue;
      const Eigen::Matrix2d inverse = basis.inverse();
      int fitted = 0;
      for (const Eigen::Vector2d& w : v) {
        const Eigen::Vector2d c = inverse * w;
        const Eigen::Vector2d n = c.array().round().matrix();
        fitted += (c - n).cwiseAbs().maxCoeff() <= kLatticeFit && n.cwiseAbs().maxCoeff() <= 2.0;
      }
      if (fitted > best_fitted) {
        best_fitted = fitted;
        steps = {v[k], v[l]};
      }
    }
  }
  if (best_fitted < kMinFittedNeighbours) return std::nullopt;
  // Lagrange-Gauss reduction in the print's metric; it ends within a few rounds (each one
  // shortens the longer step), 16 bounds a degenerate input.
  for (int round = 0; round < 16; ++round) {
    Eigen::Vector2d q0 = rectify * steps[0], q1 = rectify * steps[1];
    if (q1.squaredNorm() < q0.squaredNorm()) {
      std::swap(steps[0], steps[1]);
      std::swap(q0, q1);
    }
    const double mu = std::round(q0.dot(q1) / q0.squaredNorm());
    if (mu == 0.0) break;
    steps[1] -= mu * steps[0];
  }
  // Blobs nearer than two radii in the ellipse's metric overlap: not a printed grid.
  if (!((rectify * steps[0]).norm() > 2.0)) return std::nullopt;
  // u right, v down: the steps are right-handed when s0.u s1.v - s0.v s1.u > 0.
  if (steps[0].x() * steps[1].y() - steps[0].y() * steps[1].x() < 0.0) steps[1] = -steps[1];
  if (hexagonal && (rectify * steps[0]).dot(rectify * steps[1]) < 0.0) steps[1] += steps[0];
  return steps;
}

// A lattice step predicts the next point within 0.3 of a step: perspective changes a step by a
// tenth at most between neighbours of a board the blobs still see, and a fisheye turns it by a
// few degrees, while the nearest other lattice point is a whole step away.
constexpr double kGrowthTolerance = 0.3;

// Grows the lattice of `seed` breadth-first: each point's four neighbours are predicted by
// its own steps, and the similar unclaimed blob nearest each prediction within
// kGrowthTolerance of the step joins, its steps measured from the point it grew from and its
// neighbours already in the lattice (else inherited).
// *member marks the blobs taken (blob -> the stamp of the last lattice that took it), so that
// no blob joins a lattice twice.
Lattice GrowLattice(const std::vector<CircleBlob>& blobs, const BlobIndex& index, int seed,
                    const std::array<Eigen::Vector2d, 2>& steps, const std::vector<bool>& claimed,
                    int stamp, std::vector<int>* member) {
  Lattice lattice;
  lattice[{0, 0}] = LatticePoint{seed, steps};
  (*member)[seed] = stamp;
  std::queue<std::pair<int, int>> queue;
  queue.push({0, 0});
  const auto centre = [&](int blob) { return blobs[blob].ellipse.centre; };
  while (!queue.empty()) {
    const std::pair<int, int> at = queue.front();
    queue.pop();
    const LatticePoint p = lattice.at(at);
    for (int g = 0; g < 4; ++g) {
      const int axis = g % 2;
      const int sign = g < 2 ? 1 : -1;
      const std::pair<int, int> next = {at.first + (axis == 0 ? sign : 0),
                                        at.second + (axis == 1 ? sign : 0)};
      if (lattice.count(next) != 0) continue;
      const Eigen::Vector2d step = sign * p.step[axis];
      const Eigen::Vector2d predicted = centre(p.blob) + step;
      const std::vector<int> match =
          index.Nearest(predicted, 1, kGrowthTolerance * step.norm(), [&](int b) {
            return (*member)[b] != stamp && !claimed[b] && SimilarSize(blobs[p.blob], blobs[b]);
          });
      if (match.empty()) continue;
      LatticePoint q{match[0], p.step};
      q.step[axis] = sign * (centre(q.blob) - centre(p.blob));
      const int other = 1 - axis;
      for (const int s : {1, -1}) {
        const std::pair<int, int> side = {next.first + (other == 0 ? s : 0),
                                          next.second + (other == 1 ? s : 0)};
        if (const auto it = lattice.find(side); it != lattice.end()) {
          q.step[other] = s * (centre(it->second.blob) - centre(q.blob));
          break;
        }
      }
      lattice[next] = q;
      (*member)[q.blob] = stamp;
      queue.push(next);
    }
  }
  return lattice;
}

// ---- 3. Placements ------------------------------------------------------------------------

// The board on a grown lattice: lattice point = Rotate(board lattice point) + offset. A
// circle without a blob (cut by the image border, or its blob lost to the threshold) is
// measured from a seed predicted by a neighbour's step: its neighbour's ellipse moved there.
struct Placement {
  int rotation = 0;
  Eigen::Vector2i offset = Eigen::Vector2i::Zero();
  std::vector<int> blob;      // per id; -1: no blob
  std::vector<Ellipse> seed;  // per id: the blob's ellipse, or the predicted one
};

// At most one circle in ten (and one on boards of fewer than 20) may lack its blob: a
// lattice missing more is not taken for the board.
int MaxFilledCircles(std::size_t circles) { return std::max<int>(1, circles / 10); }

// A grown lattice's points in a dense array over their bounding box, for lookups in O(1):
// the placements look up every circle of the board at every rotation, anchor and offset.
class LatticeIndex {
 public:
  explicit LatticeIndex(const Lattice& lattice) : lattice_(lattice) {
    if (lattice.empty()) return;
    int a1 = a0_ = lattice.begin()->first.first;
    int b1 = b0_ = lattice.begin()->first.second;
    for (const auto& [ab, unused] : lattice) {
      a0_ = std::min(a0_, ab.first);
      a1 = std::max(a1, ab.first);
      b0_ = std::min(b0_, ab.second);
      b1 = std::max(b1, ab.second);
    }
    width_ = a1 - a0_ + 1;
    height_ = b1 - b0_ + 1;
    at_.assign(static_cast<std::size_t>(width_) * height_, nullptr);
    for (const auto& [ab, point] : lattice) at_[Index(ab.first - a0_, ab.second - b0_)] = &point;
  }

  const Lattice& lattice() const { return lattice_; }

  // The point at p, nullptr when p is not in the lattice.
  const LatticePoint* Find(const Eigen::Vector2i& p) const {
    const int a = p.x() - a0_, b = p.y() - b0_;
    if (a < 0 || b < 0 || a >= width_ || b >= height_) return nullptr;
    return at_[Index(a, b)];
  }

 private:
  std::size_t Index(int a, int b) const { return static_cast<std::size_t>(b) * width_ + a; }

  const Lattice& lattice_;
  int a0_ = 0, b0_ = 0, width_ = 0, height_ = 0;
  std::vector<const LatticePoint*> at_;
};

// The seed of a circle at lattice point p without a blob: a lattice neighbour's ellipse moved
// by that neighbour's step; nullopt when p has no neighbour in the lattice.
std::optional<Ellipse> PredictedSeed(const std::vector<CircleBlob>& blobs,
                                     const LatticeIndex& lattice, const Eigen::Vector2i& p) {
  for (int g = 0; g < 4; ++g) {
    const int axis = g % 2;
    const int sign = g < 2 ? 1 : -1;  // p = neighbour + sign * step
    const Eigen::Vector2i from = p - sign * Eigen::Vector2i(axis == 0, axis == 1);
    if (const LatticePoint* q = lattice.Find(from)) {
      Ellipse e = blobs[q->blob].ellipse;
      e.centre += sign * q->step[axis];
      return e;
    }
  }
  return std::nullopt;
}

// True when the board's circles at `turned` (their lattice points, turned), moved by
// `offset`, make a placement anchored on circle `anchor`: the circles before it have no blob
// (each placement comes once: anchored on the board's first circle with a blob), and at most
// max_filled have none, each next to one with a blob. Stops at the first circle that fails.
bool PlacementFits(const LatticeIndex& lattice, const std::vector<Eigen::Vector2i>& turned,
                   const Eigen::Vector2i& offset, int anchor, int max_filled) {
  int filled = 0;
  for (std::size_t id = 0; id < turned.size(); ++id) {
    const Eigen::Vector2i p = turned[id] + offset;
    if (lattice.Find(p) != nullptr) {
      if (static_cast<int>(id) < anchor) return false;
      continue;
    }
    if (++filled > max_filled) return false;
    for (int g = 0; g < 4; ++g) {
      const int axis = g % 2;
      const int sign = g < 2 ? 1 : -1;
      if (lattice.Find(p - sign * Eigen::Vector2i(axis == 0, axis == 1)) != nullptr) break;
      if (g == 3) return false;  // no neighbour to predict it (PredictedSeed)
    }
  }
  return true;
}

// Every placement of the board on the lattice with at most MaxFilledCircles circles
// without a blob, each next to one with a blob. Each candidate is checked first
// (PlacementFits) and only those that fit are built.
std::vector<Placement> Placements(const GridModel& m, const std::vector<CircleBlob>& blobs,
                                  const LatticeIndex& lattice) {
  std::vector<Placement> out;
  const std::size_t n = m.lattice.size();
  const int max_filled = MaxFilledCircles(n);
  std::vector<Eigen::Vector2i> turned(n);
  for (int rotation = 0; rotation < m.Rotations(); ++rotation) {
    for (std::size_t id = 0; id < n; ++id) turned[id] = m.Rotate(m.lattice[id], rotation);
    for (int anchor = 0; anchor <= max_filled; ++anchor) {
      for (const auto& [point, unused] : lattice.lattice()) {
        const Eigen::Vector2i offset = Eigen::Vector2i(point.first, point.second) - turned[anchor];
        if (!PlacementFits(lattice, turned, offset, anchor, max_filled)) continue;
        Placement pl;
        pl.rotation = rotation;
        pl.offset = offset;
        pl.blob.reserve(n);
        pl.seed.reserve(n);
        for (std::size_t id = 0; id < n; ++id) {
          const Eigen::Vector2i p = turned[id] + offset;
          if (const LatticePoint* lp = lattice.Find(p)) {
            pl.blob.push_back(lp->blob);
            pl.seed.push_back(blobs[lp->blob].ellipse);
          } else {
            pl.blob.push_back(-1);
            pl.seed.push_back(*PredictedSeed(blobs, lattice, p));
          }
        }
        out.push_back(std::move(pl));
      }
    }
  }
  return out;
}

// True when the lattice goes on beyond one side of the placed board: of the lattice
// positions next to the board beyond that side, at least three quarters (all when there are
// one or two) hold blobs of the lattice. The board is then part of a larger grid. A page's
// margin, its edge or the room behind it hold no such row.
bool LatticeContinues(const GridModel& m, const LatticeIndex& lattice, const Placement& pl) {
  for (const std::vector<Eigen::Vector2i>& side : m.beyond) {
    int taken = 0;
    for (const Eigen::Vector2i& p : side) {
      taken += lattice.Find(m.Rotate(p, pl.rotation) + pl.offset) != nullptr;
    }
    const int judged = static_cast<int>(side.size());
    if (taken >= std::max(std::min(judged, 2), (3 * judged + 3) / 4)) return true;
  }
  return false;
}

// The u component of the image direction of the board's x axis (along a row, towards higher
// col) at the middle of the board: 1 when the board stands upright.
double XAxisU(const GridModel& m, const std::vector<Eigen::Vector2d>& uv) {
  return (uv[m.middle[1]] - uv[m.middle[0]]).normalized().x();
}

// Of the placements that cover the same lattice points (the rotations of one grid that the
// board's symmetry allows, which give the same centres), the most upright (header,
// Orientation), judged by the seeds' centres; the others need no verification.
std::vector<Placement> UprightPlacements(const GridModel& m, std::vector<Placement> all) {
  std::map<std::vector<std::pair<int, int>>, std::size_t> best;  // covered points -> index
  std::vector<double> x_axis_u;
  for (std::size_t k = 0; k < all.size(); ++k) {
    std::vector<std::pair<int, int>> covered;
    std::vector<Eigen::Vector2d> uv;
    for (std::size_t id = 0; id < all[k].blob.size(); ++id) {
      const Eigen::Vector2i p = m.Rotate(m.lattice[id], all[k].rotation) + all[k].offset;
      covered.emplace_back(p.x(), p.y());
      uv.push_back(all[k].seed[id].centre);
    }
    std::sort(covered.begin(), covered.end());
    x_axis_u.push_back(XAxisU(m, uv));
    const auto [it, fresh] = best.emplace(std::move(covered), k);
    if (!fresh && x_axis_u[k] > x_axis_u[it->second]) it->second = k;
  }
  std::vector<bool> keep(all.size(), false);
  for (const auto& [covered, k] : best) keep[k] = true;
  std::vector<Placement> out;
  for (std::size_t k = 0; k < all.size(); ++k) {
    if (keep[k]) out.push_back(std::move(all[k]));
  }
  return out;
}

// ---- 4. Local verification ----------------------------------------------------------------

// A hexagonal block fits the quadratic (six terms) with this many other circles at least,
// two more than it needs; the smallest boards (below nine circles) fit an affine map, which
// needs three, and the smallest of all (3 x 3, five circles) leaves one to check.
constexpr int kHexQuadraticBlock = 8;

// Circle `id`'s image position predicted by least squares from the other circles of its
// block: each image coordinate as a + b x + c y + d xy (+ e x^2 and f y^2 along a side of
// three; hexagonal: all six terms with kHexQuadraticBlock others, else a + b x + c y), in
// spacings relative to the circle. nullopt when the block does not determine it.
std::optional<Eigen::Vector2d> PredictFromBlock(const GridModel& m,
                                                const std::vector<Eigen::Vector2d>& uv, int id) {
  const int others = static_cast<int>(m.block[id].size()) - 1;
  const bool hex_quadratic = others >= kHexQuadraticBlock;
  const bool xy_term = !m.hexagonal || hex_quadratic;
  const bool quad_x = m.hexagonal ? hex_quadratic : std::min(3, m.cols) == 3;
  const bool quad_y = m.hexagonal ? hex_quadratic : std::min(3, m.rows) == 3;
  Eigen::Matrix<double, 6, 6> AtA = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 2> Atb = Eigen::Matrix<double, 6, 2>::Zero();
  for (const int other : m.block[id]) {
    if (other == id) continue;
    const Eigen::Vector2d d = m.xy[other] - m.xy[id];  // centred: the prediction is the constant
    Eigen::Matrix<double, 6, 1> b;
    b << 1.0, d.x(), d.y(), xy_term ? d.x() * d.y() : 0.0, quad_x ? d.x() * d.x() : 0.0,
        quad_y ? d.y() * d.y() : 0.0;
    AtA += b * b.transpose();
    Atb += b * uv[other].transpose();
  }
  // Unused terms (a side of two, a small hexagonal board) have zero rows: pin them so the
  // system stays regular.
  for (int k = 3; k < 6; ++k) {
    if (AtA(k, k) == 0.0) AtA(k, k) = 1.0;
  }
  const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(AtA);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return std::nullopt;
  const Eigen::Matrix<double, 6, 2> coef = ldlt.solve(Atb);
  if (!coef.allFinite()) return std::nullopt;
  return Eigen::Vector2d(coef(0, 0), coef(0, 1));
}

// The local pitch at circle `id`: the image distance to its nearest neighbour in its block.
double LocalPitch(const GridModel& m, const std::vector<Eigen::Vector2d>& uv, int id) {
  double pitch = std::numeric_limits<double>::infinity();
  for (const int other : m.block[id]) {
    if (other != id) pitch = std::min(pitch, (uv[other] - uv[id]).norm());
  }
  return pitch;
}

// Every circle against its prediction from the others of its block, within max(1 px,
// fraction x local pitch), the fraction half as large again per edge of the board the circle
// lies on (predicted by extrapolation along it). A board of 2 x 2 has nothing to predict
// from: true.
bool LocallyConsistent(const GridModel& m, const std::vector<Eigen::Vector2d>& uv,
                       double fraction) {
  if (!m.hexagonal && m.cols < 3 && m.rows < 3) return true;
  for (int id = 0; id < static_cast<int>(uv.size()); ++id) {
    const std::optional<Eigen::Vector2d> p = PredictFromBlock(m, uv, id);
    const double tol = std::max(1.0, fraction * (1.0 + 0.5 * m.edges[id]) * LocalPitch(m, uv, id));
    if (!p || !((*p - uv[id]).norm() <= tol)) return false;
  }
  return true;
}

// The mean grey of the 3 x 3 pixels around uv (clamped to the image): a noise-robust sample.
double BoxGrey(const ImageView8& image, const Eigen::Vector2d& uv) {
  // Clamped before the conversion, which far-off points would overflow.
  const int x = static_cast<int>(std::lround(std::clamp(uv.x(), 1.0, image.width - 2.0)));
  const int y = static_cast<int>(std::lround(std::clamp(uv.y(), 1.0, image.height - 2.0)));
  int sum = 0;
  for (int dy = -1; dy <= 1; ++dy) {
    for (int dx = -1; dx <= 1; ++dx) sum += image.At(x + dx, y + dy);
  }
  return sum / 9.0;
}

// The page between the circles, judged against the page right next to each sample (the
// darker of the samples there for dark circles, so that the edge of a shadow running between
// them does not count as paint):
//   - the midpoint of two lattice neighbours must be at least kGapDepth of the way from the
//     two circles' grey to the grey a quarter pitch to either side of it: a checkerboard's
//     squares, which also make a lattice of blobs, touch at their corners, where the midpoint
//     is only half way, while blur darkens the gap between real circles by a few percent
//     (circles 12 px across, 5 px apart, blur 1.5: 11%);
//   - the centre of a lattice cell must be at least kCellDepth of the way from its circles'
//     grey to that of the midpoints of its sides: every other square of a checker, or dots
//     printed inside squares, have a square of the circles' own colour there. A hexagonal
//     grid's cells are triangles of three neighbours, their centroids the points furthest
//     from every circle, and are judged the same way.
// Both samples lie outside every circle (the nearest centre is over half a pitch away, a
// circle's radius under half; a triangle's centroid is 0.58 pitch from its corners). Also
// each circle must stand min_contrast / 2 from its page.
constexpr double kGapDepth = 0.75;
constexpr double kCellDepth = 0.5;

bool PageBetweenCircles(const ImageView8& image, const GridModel& m,
                        const std::vector<Eigen::Vector2d>& uv, int min_contrast) {
  const double sign = m.light ? -1.0 : 1.0;  // the page is lighter than dark circles
  const auto grey = [&](const Eigen::Vector2d& p) { return sign * BoxGrey(image, p); };
  const std::size_t n = uv.size();
  std::vector<double> circle(n);
  for (std::size_t id = 0; id < n; ++id) circle[id] = grey(uv[id]);
  // (depth, page reference, circles' grey) of a sample: depth must reach a fraction of the
  // reference's.
  const auto deep = [&](double sample, double reference, double circles, double fraction) {
    return reference - circles >= 0.5 * min_contrast &&
           sample - circles >= fraction * (reference - circles);
  };
  for (const auto& [a, b] : m.pairs) {
    const Eigen::Vector2d mid = 0.5 * (uv[a] + uv[b]);
    const Eigen::Vector2d d = uv[b] - uv[a];
    const Eigen::Vector2d side = 0.25 * Eigen::Vector2d(-d.y(), d.x());
    const double reference = std::min(grey(mid + side), grey(mid - side));
    if (!deep(grey(mid), reference, std::max(circle[a], circle[b]), kGapDepth)) return false;
  }
  for (const auto& c : m.cells) {
    // Sides: (p, p + a), (p, p + b), (p + a, p + a + b), (p + b, p + a + b).
    double reference = std::numeric_limits<double>::infinity();
    for (const auto& [i, j] : {std::pair{0, 1}, {0, 2}, {1, 3}, {2, 3}}) {
      reference = std::min(reference, grey(0.5 * (uv[c[i]] + uv[c[j]])));
    }
    const Eigen::Vector2d centre = 0.25 * (uv[c[0]] + uv[c[1]] + uv[c[2]] + uv[c[3]]);
    double circles = -std::numeric_limits<double>::infinity();
    for (const int id : c) circles = std::max(circles, circle[id]);
    if (!deep(grey(centre), reference, circles, kCellDepth)) return false;
  }
  for (const auto& t : m.triangles) {
    double reference = std::numeric_limits<double>::infinity();
    for (const auto& [i, j] : {std::pair{0, 1}, {0, 2}, {1, 2}}) {
      reference = std::min(reference, grey(0.5 * (uv[t[i]] + uv[t[j]])));
    }
    const Eigen::Vector2d centroid = (uv[t[0]] + uv[t[1]] + uv[t[2]]) / 3.0;
    const double circles = std::max({circle[t[0]], circle[t[1]], circle[t[2]]});
    if (!deep(grey(centroid), reference, circles, kCellDepth)) return false;
  }
  return true;
}

// ---- 5. Sub-pixel centres -----------------------------------------------------------------

// The image of the centre of the circle whose image is `ellipse`, given the homography H from
// its board plane (any unit) to the image: the ellipse taken back to the board (the conic
// H^T C H, a circle when H is right), whose centre is mapped forward. nullopt when the conic
// taken back is not a bounded curve (H far off).
std::optional<Eigen::Vector2d> ImageOfCentre(const Eigen::Matrix3d& H, const Ellipse& ellipse) {
  const Eigen::Matrix3d board = H.transpose() * ellipse.Conic() * H;
  const Eigen::Matrix2d a = board.topLeftCorner<2, 2>();
  if (!(a.determinant() > 0.0)) return std::nullopt;
  const Eigen::Vector2d centre = -a.inverse() * board.topRightCorner<2, 1>();
  const Eigen::Vector2d uv = ApplyHomography(H, centre);
  if (!uv.allFinite()) return std::nullopt;
  return uv;
}

// The distance from e's centre to its edge along the unit direction u.
double RadiusAlong(const Ellipse& e, const Eigen::Vector2d& u) {
  const double c = (u.x() * std::cos(e.angle_rad) + u.y() * std::sin(e.angle_rad)) / e.semi_major;
  const double s = (u.y() * std::cos(e.angle_rad) - u.x() * std::sin(e.angle_rad)) / e.semi_minor;
  return 1.0 / std::sqrt(c * c + s * s);
}

// The scale about circle id's ellipse at which it first reaches another circle of its block
// (along the line of their centres): the room for its grey centroid's window.
double RoomScale(const GridModel& m, const std::vector<Ellipse>& ellipses, int id) {
  const Ellipse& e = ellipses[id];
  double room = std::numeric_limits<double>::infinity();
  for (const int other : m.block[id]) {
    if (other == id) continue;
    const Eigen::Vector2d d = ellipses[other].centre - e.centre;
    const double distance = d.norm();
    if (!(distance > 0.0)) return 0.0;
    const Eigen::Vector2d u = d / distance;
    room = std::min(room, (distance - RadiusAlong(ellipses[other], -u)) / RadiusAlong(e, u));
  }
  return room;
}

// The ellipse centres corrected for perspective (header, step 5): three rounds, each fitting
// every block's homography to the current centres. The offset changes by (change of H) x
// (offset / pitch), far below a hundredth of a pixel after the first round. A block whose
// homography cannot be fitted leaves its circle's centre as it is.
std::vector<Eigen::Vector2d> CorrectPerspective(const GridModel& m,
                                                const std::vector<Ellipse>& ellipses) {
  const std::size_t n = ellipses.size();
  std::vector<Eigen::Vector2d> centres(n);
  for (std::size_t id = 0; id < n; ++id) centres[id] = ellipses[id].centre;
  const HomographyFitOptions dlt{.refine = false};
  for (int round = 0; round < 3; ++round) {
    std::vector<Eigen::Vector2d> next = centres;
    for (std::size_t id = 0; id < n; ++id) {
      std::vector<Eigen::Vector2d> src, dst;
      for (const int other : m.block[id]) {
        src.push_back(m.xy[other]);
        dst.push_back(centres[other]);
      }
      const std::optional<HomographyFit> fit = FitHomography(src, dst, dlt);
      if (!fit) continue;
      if (const std::optional<Eigen::Vector2d> c = ImageOfCentre(fit->H, ellipses[id])) {
        next[id] = *c;
      }
    }
    centres = std::move(next);
  }
  return centres;
}

// The ellipses' centres, corrected for perspective when `correct`.
std::vector<Eigen::Vector2d> Centres(const GridModel& m, const std::vector<Ellipse>& ellipses,
                                     bool correct) {
  if (correct) return CorrectPerspective(m, ellipses);
  std::vector<Eigen::Vector2d> uv;
  for (const Ellipse& e : ellipses) uv.push_back(e.centre);
  return uv;
}

// The edge of a printed circle fits its ellipse within the noise of single edge points: a
// median distance of 0.1 px in clean renders and 0.1-0.16 px in the real photos of
// docs/boards.md §8, up to 0.58 px under docs/acceptance.md's hardest effects (9768 circles of
// the evaluation grid). A square's best ellipse misses its sides and corners by about 7% of
// its half side (median; 1.1 px for the 30 px squares of a real square grid), which would
// let a square grid's squares into a lattice of blobs. The larger of kMaxEdgeResidualPx
// (1.4 times the worst circle) and kMaxEdgeResidualFraction of the mean semi-axis passes: a
// square is told apart from about 23 px across.
constexpr double kMaxEdgeResidualPx = 0.8;
constexpr double kMaxEdgeResidualFraction = 0.04;

// Smaller squares are told apart by the fourfold harmonic of their edge (EdgeShape): a
// square's is 0.14 of its radius with sharp corners and 0.12 (median; at least 0.04) with
// the evaluation's blur, holding 0.83 (median) of the departure's variance; a circle's is
// noise, and the sampling and JPEG blocks of the smallest circles: on the 19757 circles of
// two runs of the circle grid's evaluation renders, at most 0.088 of the radius (a 10 px
// circle under blur 1.5, gamma 1.6 and JPEG 80), with a share of 0.47; the share reaches 0.52
// only where the harmonic is under 0.035 of the radius. An edge with both a harmonic over
// kMaxFourfoldFraction of the radius and a share over kMaxFourfoldShare is a square's: none
// of those circles, and 21 to 54 of the squares of each square-grid render whose squares the
// circle grid measured as a whole grid (docs/detectors.md); one refused circle refuses the
// grid.
constexpr double kMaxFourfoldFraction = 0.1;
constexpr double kMaxFourfoldShare = 0.5;

bool EllipticEdge(const Ellipse& e, const EdgeShape& shape) {
  const double radius = std::sqrt(e.semi_major * e.semi_minor);
  if (shape.fourfold_px > kMaxFourfoldFraction * radius &&
      shape.fourfold_share > kMaxFourfoldShare) {
    return false;
  }
  return shape.median_residual_px <=
         std::max(kMaxEdgeResidualPx, kMaxEdgeResidualFraction * radius);
}

// The lattice of a printed grid is square in the print's metric: each circle's ellipse undoes
// the local perspective (an ellipse of shape S is the image of a circle under the local affine
// map S^1/2 up to a rotation), and in its metric the circle's two lattice steps are
// orthogonal and equally long. A hexagonal grid (60 degrees), a rectangular one (the circle
// board's 100 x 70 mm) or blobs that merely fit a sheared lattice are not. Judged by the
// medians over the circles with both steps on the board: |cos| of the angle at most
// kMaxSquareCos (78 degrees), the ratio of the lengths within kMaxSquareRatio. Measured on
// printed grids: at most 0.07 and 1.10 (the evaluation's steepest views of 12 px circles),
// 0.01 and 1.01 in the real photos; a hexagonal grid gives 0.5, the circle board 1.43.
// The hexagonal grid's steps are 60 degrees apart instead: cos within kMaxSquareCos of 0.5
// (47 to 73 degrees), where a square grid gives 0.
constexpr double kMaxSquareCos = 0.2;
constexpr double kMaxSquareRatio = 1.25;
constexpr double kHexagonalCos = 0.5;

bool LatticeAsPrinted(const GridModel& m, const std::vector<Eigen::Vector2d>& uv,
                      const std::vector<Ellipse>& ellipses) {
  std::vector<double> cosines, ratios;
  for (int id = 0; id < static_cast<int>(m.lattice.size()); ++id) {
    const int a = m.next[id][0], b = m.next[id][1];
    if (a < 0 || b < 0) continue;
    const Ellipse& e = ellipses[id];
    const Eigen::Rotation2Dd r(e.angle_rad);
    const Eigen::Matrix2d shape =
        r.toRotationMatrix() *
        Eigen::Vector2d(e.semi_major * e.semi_major, e.semi_minor * e.semi_minor).asDiagonal() *
        r.toRotationMatrix().transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(shape);
    const Eigen::Matrix2d rectify = eig.operatorInverseSqrt();
    const Eigen::Vector2d qa = rectify * (uv[a] - uv[id]);
    const Eigen::Vector2d qb = rectify * (uv[b] - uv[id]);
    const double cosine = qa.dot(qb) / (qa.norm() * qb.norm());
    cosines.push_back(m.hexagonal ? std::abs(cosine - kHexagonalCos) : std::abs(cosine));
    const double ratio = qa.norm() / qb.norm();
    ratios.push_back(std::max(ratio, 1.0 / ratio));
  }
  if (cosines.empty()) return true;
  const auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  return median(cosines) <= kMaxSquareCos && median(ratios) <= kMaxSquareRatio;
}

// ---- The search ---------------------------------------------------------------------------

// A verified placement: the corrected centre per id, and the image direction of the board's
// x axis at its middle (for the upright rule).
struct Hypothesis {
  std::vector<int> blob;            // per id
  std::vector<Eigen::Vector2d> uv;  // per id: the edge fits' centres, corrected
  std::vector<Ellipse> ellipses;    // per id: the edge fits
  double x_axis_u = 0.0;
};

// Step 5's centres from the grey levels (circle_edge_fit.h), for the grid chosen only (its
// verification needs no more than the edge fits' centres; both estimates stay within a quarter
// radius of the edge fit's centre): each circle's feature moved by the estimate's offset from
// its edge fit's centre, where the room around it allows; the model fit where it converges,
// else the grey centroid. The perspective correction's offset depends on the centre only
// through the block's homography, which such a move changes by far below a thousandth of a
// pixel, so it is kept rather than computed again.
void UseGreyLevelCentres(const ImageView8& image, const GridModel& m,
                         CircleGridOptions::Centre centre, Hypothesis* h) {
  for (std::size_t id = 0; id < h->ellipses.size(); ++id) {
    const Ellipse& e = h->ellipses[id];
    const double room = RoomScale(m, h->ellipses, static_cast<int>(id));
    const std::optional<Eigen::Vector2d> c = centre == CircleGridOptions::Centre::kModelFit
                                                 ? ModelCentre(image, e, m.light, room)
                                                 : GreyCentroid(image, e, m.light, room);
    if (c) h->uv[id] += *c - e.centre;
  }
}

// How far a search got, for the reason reported: later outcomes rank higher.
int Rank(DetectReason r) {
  switch (r) {
    case DetectReason::kLowContrast:
      return 1;
    case DetectReason::kNoCandidates:
      return 2;
    case DetectReason::kTooFewFeatures:
      return 3;
    case DetectReason::kVerificationFailed:
      return 4;
    case DetectReason::kWrongBoard:
      return 5;
    case DetectReason::kAmbiguous:
      return 6;
    default:
      return 0;
  }
}

void Note(DetectReason r, DetectReason* reason) {
  if (Rank(r) > Rank(*reason)) *reason = r;
}

class Search {
 public:
  Search(const ImageView8& image, const GridModel& m, const CircleGridOptions& options,
         const std::vector<CircleBlob>& blobs)
      : image_(image),
        m_(m),
        options_(options),
        blobs_(blobs),
        index_(blobs),
        fitter_(options.edge_rays),
        measured_(blobs.size()) {}

  // The verified hypotheses of every lattice the blobs seed; *reason: how far the others got.
  std::vector<Hypothesis> Run(DetectReason* reason) {
    std::vector<Hypothesis> found;
    // Blobs of a verified board (they join no other lattice), and blobs placed on the board
    // once, verified or not (they seed no other lattice: it would grow the same).
    std::vector<bool> claimed(blobs_.size(), false);
    std::vector<bool> placed(blobs_.size(), false);
    std::vector<int> member(blobs_.size(), -1);
    const std::size_t n = m_.lattice.size();
    for (int seed = 0; seed < static_cast<int>(blobs_.size()); ++seed) {
      if (claimed[seed] || placed[seed]) continue;
      const std::optional<std::array<Eigen::Vector2d, 2>> steps =
          SeedSteps(blobs_, index_, seed, m_.hexagonal);
      if (!steps) continue;
      const Lattice lattice = GrowLattice(blobs_, index_, seed, *steps, claimed, seed, &member);
      if (lattice.size() + MaxFilledCircles(n) < n) continue;
      const LatticeIndex lattice_index(lattice);
      std::vector<Hypothesis> verified;
      for (const Placement& pl : UprightPlacements(m_, Placements(m_, blobs_, lattice_index))) {
        for (const int b : pl.blob) {
          if (b >= 0) placed[b] = true;
        }
        if (LatticeContinues(m_, lattice_index, pl)) {
          Note(DetectReason::kWrongBoard, reason);
          continue;
        }
        if (std::optional<Hypothesis> h = Verify(pl)) {
          verified.push_back(*std::move(h));
        } else {
          Note(DetectReason::kVerificationFailed, reason);
        }
      }
      // A lattice without a placement may have grown from a poor seed (a sheared basis), so
      // its blobs stay free to seed again.
      for (const Hypothesis& h : verified) {
        for (const int b : h.blob) {
          if (b >= 0) claimed[b] = true;
        }
      }
      found.insert(found.end(), verified.begin(), verified.end());
    }
    return found;
  }

 private:
  // The sub-pixel ellipse of the circle `seed` approximates; nullopt when its edge is not
  // found or is not an ellipse's.
  std::optional<Ellipse> Measure(const Ellipse& seed) const {
    EdgeShape shape;
    std::optional<Ellipse> e =
        fitter_.Measure(image_, seed, m_.light, options_.min_contrast, &shape);
    if (e && !EllipticEdge(*e, shape)) return std::nullopt;
    return e;
  }

  // Measure() of blob b, once.
  const std::optional<Ellipse>& Measured(int b) {
    if (!measured_[b]) measured_[b] = Measure(blobs_[b].ellipse);
    return *measured_[b];
  }

  std::optional<Hypothesis> Verify(const Placement& pl) {
    const std::size_t n = pl.blob.size();
    std::vector<Eigen::Vector2d> uv(n);
    for (std::size_t id = 0; id < n; ++id) uv[id] = pl.seed[id].centre;
    // Blob centroids are biased by the threshold and perspective by a small part of the
    // radius: a quarter of the pitch separates a grid from blobs that merely fit the lattice.
    if (!LocallyConsistent(m_, uv, 0.25)) return std::nullopt;
    if (!PageBetweenCircles(image_, m_, uv, options_.min_contrast)) return std::nullopt;
    std::vector<Ellipse> ellipses(n);
    for (std::size_t id = 0; id < n; ++id) {
      const std::optional<Ellipse> e =
          pl.blob[id] >= 0 ? Measured(pl.blob[id]) : Measure(pl.seed[id]);
      if (!e) return std::nullopt;
      ellipses[id] = *e;
    }
    Hypothesis h;
    h.blob = pl.blob;
    h.uv = Centres(m_, ellipses, options_.correct_perspective);
    if (!LocallyConsistent(m_, h.uv, options_.max_residual_pitch_fraction)) return std::nullopt;
    if (!LatticeAsPrinted(m_, h.uv, ellipses)) return std::nullopt;
    h.x_axis_u = XAxisU(m_, h.uv);
    h.ellipses = std::move(ellipses);
    return h;
  }

  const ImageView8& image_;
  const GridModel& m_;
  const CircleGridOptions& options_;
  const std::vector<CircleBlob>& blobs_;
  BlobIndex index_;
  CircleEdgeFitter fitter_;
  std::vector<std::optional<std::optional<Ellipse>>> measured_;
};

// The blobs sorted, for comparing the sets of two hypotheses.
std::vector<int> SortedBlobs(const Hypothesis& h) {
  std::vector<int> b = h.blob;
  std::sort(b.begin(), b.end());
  return b;
}

struct FactorResult {
  DetectReason reason = DetectReason::kNoCandidates;
  std::optional<Hypothesis> chosen;
};

// One search at a candidate reduction factor: the one grid found (upright among the
// rotations its symmetry allows), or the reason.
FactorResult SearchAtFactor(const ImageView8& image, const GridModel& m,
                            const CircleGridOptions& options, int factor) {
  FactorResult result;
  const CircleBlobSearch blobs =
      FindCircleBlobs(image, factor, options.min_contrast, m.light, !m.light);
  if (blobs.low_contrast) {
    result.reason = DetectReason::kLowContrast;
    return result;
  }
  if (blobs.blobs.empty()) return result;
  result.reason = DetectReason::kTooFewFeatures;
  const std::size_t n = m.lattice.size();
  if (blobs.blobs.size() + MaxFilledCircles(n) < n) return result;
  Search search(image, m, options, blobs.blobs);
  std::vector<Hypothesis> found = search.Run(&result.reason);
  if (found.empty()) return result;
  // The upright rule (header) among the rotations of one grid; two grids are ambiguous.
  std::stable_sort(found.begin(), found.end(), [](const Hypothesis& a, const Hypothesis& b) {
    return a.x_axis_u > b.x_axis_u;
  });
  const std::vector<int> chosen = SortedBlobs(found.front());
  for (const Hypothesis& h : found) {
    if (SortedBlobs(h) != chosen) {
      result.reason = DetectReason::kAmbiguous;
      return result;
    }
  }
  result.reason = DetectReason::kNone;
  result.chosen = std::move(found.front());
  return result;
}

Detection NotFound(DetectReason reason) {
  Detection d;
  d.found = false;
  d.reason = reason;
  return d;
}

}  // namespace

std::string_view CircleGridOptions::Validate() const {
  if (min_contrast < 4 || min_contrast > 200) return "min_contrast";
  if (edge_rays < 16 || edge_rays > 256) return "edge_rays";
  if (!(max_residual_pitch_fraction > 0.0 && max_residual_pitch_fraction <= 0.5)) {
    return "max_residual_pitch_fraction";
  }
  return {};
}

Detection DetectCircleGrid(const ImageView8& image, const Board& board,
                           const CircleGridOptions& options) {
  if (const DetectReason r =
          CheckDetectorInput(image, board, BoardType::kCircleGrid, options.Validate().empty());
      r != DetectReason::kNone) {
    return NotFound(r);
  }
  const GridModel m = MakeModel(board.params());
  // Coarse to fine (circle_blobs.h): the first factor that finds the board decides.
  DetectReason reason = DetectReason::kNone;
  for (int factor = CoarsestCircleBlobFactor(image); factor >= 2; factor /= 2) {
    FactorResult r = SearchAtFactor(image, m, options, factor);
    if (r.chosen) {
      if (options.centre != CircleGridOptions::Centre::kEdgeFit) {
        UseGreyLevelCentres(image, m, options.centre, &*r.chosen);
      }
      Detection d;
      d.found = true;
      d.reason = DetectReason::kNone;
      for (std::size_t id = 0; id < r.chosen->uv.size(); ++id) {
        DetectedFeature f;
        f.id = static_cast<int>(id);
        f.uv_px = r.chosen->uv[id];
        f.p_board = board.features()[id].p_board;
        d.features.push_back(f);
      }
      return d;
    }
    Note(r.reason, &reason);
  }
  return NotFound(reason);
}

}  // namespace linecal

#include "detectors/round_hole/round_hole_search.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <deque>
#include <map>
#include <numbers>
#include <numeric>
#include <optional>
#include <set>
#include <unordered_map>

namespace linecal {
namespace {

// Steps 1-3 look at no more points than this of the first frame: a 16-ring rotation (30k) in
// full, every second to fourth point of a 32-128 ring one. That leaves a 64-ring LiDAR's
// points 3 cm apart along a ring at 3 m, finer than any hole chord to be seen.
constexpr std::size_t kMaxSearchPoints = 40000;
// The in-plane shift range of a candidate never exceeds 0.2 m: half the ring spacing of a
// 16-ring LiDAR (2 degrees) at 8 m, plus margin.
constexpr double kMaxShiftRangeM = 0.2;
// Median absolute deviation to sigma for Gaussian noise.
constexpr double kMadToSigma = 1.4826;
// A neighbourhood's plane: the inlier gate is 3 robust sigmas, never below 3 cm (range noise
// of 1-3 cm, docs/acceptance.md), and a neighbourhood is flat when its robust sigma is below 5 cm
// (range noise of 3 cm seen at any incidence, plus float rounding).
constexpr double kMinGateM = 0.03;
constexpr double kMaxFlatSigmaM = 0.05;
// At least this many points in a neighbourhood (two rings of a VLP-16 at 8 m over 0.75 m hold
// about 50 per rotation), and this spread across the scan lines: the in-plane minor axis's
// sigma (two rings 0.28 m apart give 0.14 m).
constexpr int kMinNeighbourhoodPoints = 12;
constexpr double kMinMinorSpreadM = 0.06;
// Neighbouring flat cubes belong to one patch when their normals agree within 12 degrees and
// each centroid lies within 6 cm of the other's plane.
constexpr double kPatchCosAngle = 0.978;
constexpr double kPatchOffsetM = 0.06;
// A patch gathers the frame's points within 8 cm of its plane (3 sigma of a 3 cm range noise
// at moderate incidence) and within 0.25 m (a cube, which its edge may have lost) of its
// cubes' extent in the plane, except those on the plane of a flat cube nearby with another
// normal: the floor meets the board's plane along a line, and the floor's rings run along it.
constexpr double kGatherDepthM = 0.08;
constexpr double kGatherMarginM = 0.25;
// Floors: a normal within 45 degrees of the spin axis.
constexpr double kMaxNormalZ = 0.7071;
// A ring crosses the page when its points span half the page's width and at most 25% more
// than the page (a wider one runs along something else in the plane, e.g. the floor along
// the plane's foot). The crossing rings' median span must be the page's width to within -25%
// (holes or ends lost at the edges, a ring's azimuth step), and they must span at most the
// page's height plus 15%.
constexpr double kMinWidthRatio = 0.75;
constexpr double kMaxWidthRatio = 1.25;
constexpr double kMaxHeightRatio = 1.15;
// Two fitted boards whose centres are within half a page of each other are the same board
// (found from two patches).
constexpr double kSameBoardPages = 0.5;
// Empty holes: points of the fitted plane (within 3 plane sigmas, at least 3 cm) inside the
// hole circles shrunk by 3 cm, against what paper of the same area holds. A real board lets
// every ray through (0, or a wall touching its back); a plain panel fills them (about 1).
constexpr double kHoleInsetM = 0.03;
constexpr double kMaxHoleFill = 0.15;
// Before the whole-board fit a patch must show as many rings crossing a hole as that fit needs
// (min_rings_through_holes) in its first frame: a gap along the ring
// of at least 4 cm (1.5 azimuth steps of a ring at 8 m) and at most the hole's diameter plus
// 4 cm.
constexpr double kMinHoleChordM = 0.04;

struct CellKey {
  int x = 0, y = 0, z = 0;
  bool operator==(const CellKey&) const = default;
};
struct CellKeyHash {
  std::size_t operator()(const CellKey& k) const {
    return static_cast<std::size_t>(k.x) * 73856093u ^ static_cast<std::size_t>(k.y) * 19349663u ^
           static_cast<std::size_t>(k.z) * 83492791u;
  }
};

struct Cell {
  std::vector<int> points;
  bool flat = false;
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // towards the sensor
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  int patch = -1;
};

double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

struct LocalPlane {
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  Eigen::Vector3d major = Eigen::Vector3d::Zero();  // eigenvalues' square roots, descending
  double gate_m = 0.0;
  std::vector<int> inliers;
  bool ok = false;
};

// Orthogonal plane through `idx` with trimming: three rounds of PCA over the points within
// 3 robust sigmas of the previous plane.
LocalPlane FitLocalPlane(const std::vector<Eigen::Vector3d>& pts, const std::vector<int>& idx) {
  LocalPlane plane;
  std::vector<int> in = idx;
  std::vector<double> abs_d;
  for (int round = 0; round < 3; ++round) {
    if (static_cast<int>(in.size()) < kMinNeighbourhoodPoints) return plane;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (int i : in) mean += pts[i];
    mean /= static_cast<double>(in.size());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (int i : in) cov += (pts[i] - mean) * (pts[i] - mean).transpose();
    cov /= static_cast<double>(in.size());
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    plane.normal = eig.eigenvectors().col(0);
    plane.centroid = mean;
    plane.major = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt().reverse();
    abs_d.clear();
    for (int i : idx) abs_d.push_back(std::abs(plane.normal.dot(pts[i] - mean)));
    const double sigma = kMadToSigma * Median(abs_d);
    plane.gate_m = std::max(3.0 * sigma, kMinGateM);
    if (round == 2) {
      if (sigma > kMaxFlatSigmaM) return plane;
      break;
    }
    in.clear();
    for (int i : idx)
      if (std::abs(plane.normal.dot(pts[i] - mean)) < plane.gate_m) in.push_back(i);
  }
  plane.inliers = std::move(in);
  plane.ok = true;
  return plane;
}

// True when p lies on the plane of a flat cube (the one `key` names or a neighbour) whose
// normal differs from n: on the floor, say, where it meets the board's plane.
bool OnAnotherPlane(const std::unordered_map<CellKey, Cell, CellKeyHash>& cells, const CellKey& key,
                    const Eigen::Vector3d& p, const Eigen::Vector3d& n) {
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz) {
        const auto it = cells.find({key.x + dx, key.y + dy, key.z + dz});
        if (it == cells.end() || !it->second.flat || it->second.normal.dot(n) >= kPatchCosAngle)
          continue;
        if (std::abs(it->second.normal.dot(p - it->second.centroid)) < kPatchOffsetM) return true;
      }
  return false;
}

// A board-sized patch: the prior pose for the whole-board fit and the in-plane shift range its
// centre needs.
struct Candidate {
  Rigid3d T_lidar_board;
  double shift_range_m = 0.0;
  double width_error = 0.0;  // |median crossing width / page width - 1|, for ordering
};

// The board's holes, for the empty-holes test of step 4.
class HoleGeometry {
 public:
  // `page`: the board's page size, metres.
  HoleGeometry(const Board& board, const Eigen::Vector2d& page) : page_(page) {
    double hole_area = 0.0;
    for (const BoardShape& s : board.shapes()) {
      if (s.paint != Paint::kHole) continue;
      centres_.push_back(s.centre_board());
      radii_.push_back(s.radius_m());
      hole_area += std::numbers::pi * std::pow(std::max(s.radius_m() - kHoleInsetM, 0.0), 2);
    }
    hole_area_ = hole_area;
    paper_area_ = page.x() * page.y() - hole_area;
  }

  // Points of the fitted plane of `d` (found) inside the holes shrunk by kHoleInsetM, as a
  // density over that of the paper away from the holes: about 0 for a board whose holes let
  // the rays through, about 1 for a plain panel. 1 when no point lies on the paper. Cost: a
  // transform per point near the board.
  double Fill(std::span<const std::span<const RoundHoleCloudPoint>> frames,
              const RoundHoleCloudDetection& d) const {
    const Rigid3d T_board_lidar = d.T_lidar_board.Inverse();
    const double depth = std::max(3.0 * d.plane_rms_m, kMinGateM);
    const Eigen::Vector3d centre = d.T_lidar_board.translation();
    const double reach2 = 0.25 * page_.squaredNorm() + depth * depth;
    int in_holes = 0, on_paper = 0;
    for (const auto& frame : frames) {
      for (const RoundHoleCloudPoint& p : frame) {
        const Eigen::Vector3d p_lidar(p.x, p.y, p.z);
        if (!((p_lidar - centre).squaredNorm() <= reach2)) continue;
        const Eigen::Vector3d q = T_board_lidar * p_lidar;
        if (!q.allFinite() || std::abs(q.z()) > depth || std::abs(q.x()) > 0.5 * page_.x() ||
            std::abs(q.y()) > 0.5 * page_.y()) {
          continue;
        }
        bool in_hole = false, near_hole = false;
        for (std::size_t h = 0; h < centres_.size(); ++h) {
          const double r = (q.head<2>() - centres_[h]).norm();
          in_hole = in_hole || r < radii_[h] - kHoleInsetM;
          near_hole = near_hole || r < radii_[h] + kHoleInsetM;
        }
        in_holes += in_hole ? 1 : 0;
        on_paper += near_hole ? 0 : 1;
      }
    }
    return on_paper > 0 ? (in_holes / hole_area_) / (on_paper / paper_area_) : 1.0;
  }

 private:
  Eigen::Vector2d page_;
  std::vector<Eigen::Vector2d> centres_;
  std::vector<double> radii_;
  double hole_area_ = 0.0;
  double paper_area_ = 0.0;
};

// Step 5: the evidence of every board kept (`boards` non-empty, found; `fills` their hole
// fills), ranked: the best fit first (smallest angular edge RMS), then the other boards
// that tie with it, then those that lost, each with its verdict (header, kClearlyWorseFit).
// fits[0].verdict is kChosen exactly when the search found a board.
// `order` receives the index in `boards` of each fit. O(n log n) in the boards.
std::vector<RoundHoleBoardFit> RankFits(const std::vector<RoundHoleCloudDetection>& boards,
                                        const std::vector<double>& fills,
                                        std::vector<std::size_t>* order) {
  std::vector<RoundHoleBoardFit> fits(boards.size());
  for (std::size_t k = 0; k < boards.size(); ++k) {
    const RoundHoleCloudDetection& d = boards[k];
    RoundHoleBoardFit& f = fits[k];
    f.centre_lidar = d.T_lidar_board.translation();
    f.edges = d.edges;
    f.edge_rms_m = d.edge_rms_m;
    f.edge_rms_rad = d.edge_rms_m / std::max(f.centre_lidar.norm(), 1e-3);
    f.hole_fill = fills[k];
    f.rings_through_holes = d.rings_through_holes;
  }
  order->resize(fits.size());
  std::iota(order->begin(), order->end(), std::size_t{0});
  std::sort(order->begin(), order->end(), [&](std::size_t a, std::size_t b) {
    return fits[a].edge_rms_rad < fits[b].edge_rms_rad;
  });
  const double best_rms = std::max(fits[order->front()].edge_rms_rad, 1e-12);
  bool tie = false;
  for (std::size_t k = 1; k < order->size(); ++k) {
    RoundHoleBoardFit& f = fits[(*order)[k]];
    f.rms_ratio = f.edge_rms_rad / best_rms;
    f.verdict = f.rms_ratio >= kClearlyWorseFit ? RoundHoleFitVerdict::kWorseFit
                                                : RoundHoleFitVerdict::kTies;
    tie = tie || f.verdict == RoundHoleFitVerdict::kTies;
  }
  fits[order->front()].verdict = tie ? RoundHoleFitVerdict::kTies : RoundHoleFitVerdict::kChosen;
  // Ties before losers, each group by fit (the sort above is kept within a group).
  std::stable_partition(order->begin() + 1, order->end(), [&](std::size_t k) {
    return fits[k].verdict == RoundHoleFitVerdict::kTies;
  });
  std::vector<RoundHoleBoardFit> ranked;
  for (std::size_t k : *order) ranked.push_back(fits[k]);
  return ranked;
}

using CellMap = std::unordered_map<CellKey, Cell, CellKeyHash>;

// The points the search looks at: every stride-th point of one frame, in range.
struct SearchPoints {
  std::vector<Eigen::Vector3d> pts;
  std::vector<int> rings;  // per point
};

// Needs the frames and the options' range; gives the first frame with points in range, every
// stride-th point of it: a denser frame than kMaxSearchPoints (a 64-ring rotation holds 115k)
// only adds cost. Empty when no frame has a point in range.
SearchPoints SelectSearchPoints(std::span<const std::span<const RoundHoleCloudPoint>> frames,
                                const RoundHoleSearchOptions& options) {
  SearchPoints points;
  for (const auto& frame : frames) {
    const std::size_t stride = frame.size() / kMaxSearchPoints + 1;
    for (std::size_t k = 0; k < frame.size(); k += stride) {
      const RoundHoleCloudPoint& p = frame[k];
      const Eigen::Vector3d q(p.x, p.y, p.z);
      const double r = q.norm();
      if (!std::isfinite(r) || r < options.min_range_m || r > options.max_range_m) continue;
      points.pts.push_back(q);
      points.rings.push_back(p.ring);
    }
    if (!points.pts.empty()) break;
  }
  return points;
}

// The cube of side cell_m that holds q.
CellKey KeyOf(const Eigen::Vector3d& q, double cell_m) {
  return CellKey{static_cast<int>(std::floor(q.x() / cell_m)),
                 static_cast<int>(std::floor(q.y() / cell_m)),
                 static_cast<int>(std::floor(q.z() / cell_m))};
}

// Step 1. Needs the search points and the cube size; gives the cubes with their points, those
// whose neighbourhood (the cube and its 26 neighbours) is flat, spread across two rings or
// more and holds most of the cube's points marked flat with the plane's normal (towards the
// sensor) and centroid. *flat_cells: how many.
CellMap FlatCells(const SearchPoints& points, double cell_m, int* flat_cells) {
  const std::vector<Eigen::Vector3d>& pts = points.pts;
  CellMap cells;
  for (std::size_t i = 0; i < pts.size(); ++i)
    cells[KeyOf(pts[i], cell_m)].points.push_back(int(i));
  std::vector<int> neighbourhood;
  for (auto& [key, cell] : cells) {
    if (cell.points.size() < 3) continue;
    neighbourhood.clear();
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = cells.find({key.x + dx, key.y + dy, key.z + dz});
          if (it != cells.end())
            neighbourhood.insert(neighbourhood.end(), it->second.points.begin(),
                                 it->second.points.end());
        }
    const LocalPlane plane = FitLocalPlane(pts, neighbourhood);
    if (!plane.ok || plane.major(1) < kMinMinorSpreadM) continue;
    std::set<int> plane_rings;
    for (int i : plane.inliers) plane_rings.insert(points.rings[i]);
    if (plane_rings.size() < 2) continue;
    const auto own_on_plane = std::count_if(cell.points.begin(), cell.points.end(), [&](int i) {
      return std::abs(plane.normal.dot(pts[i] - plane.centroid)) < plane.gate_m;
    });
    if (2 * own_on_plane < static_cast<std::ptrdiff_t>(cell.points.size())) continue;
    cell.flat = true;
    cell.normal = plane.normal.dot(plane.centroid) > 0.0 ? -plane.normal : plane.normal;
    cell.centroid = plane.centroid;
    ++*flat_cells;
  }
  return cells;
}

// Step 2. Needs the cubes of step 1; gives the patches, flat cubes joined breadth-first through
// flat neighbours on the same plane (kPatchCosAngle, kPatchOffsetM), and sets each cube's
// patch.
std::vector<std::vector<Cell*>> JoinPatches(CellMap* cells) {
  std::vector<std::vector<Cell*>> patches;
  for (auto& [key, cell] : *cells) {
    if (!cell.flat || cell.patch >= 0) continue;
    const int id = static_cast<int>(patches.size());
    std::vector<Cell*>& patch = patches.emplace_back();
    std::deque<std::pair<CellKey, Cell*>> queue = {{key, &cell}};
    cell.patch = id;
    while (!queue.empty()) {
      const auto [k, c] = queue.front();
      queue.pop_front();
      patch.push_back(c);
      for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dz = -1; dz <= 1; ++dz) {
            const CellKey nk{k.x + dx, k.y + dy, k.z + dz};
            const auto it = cells->find(nk);
            if (it == cells->end() || !it->second.flat || it->second.patch >= 0) continue;
            Cell& n = it->second;
            if (n.normal.dot(c->normal) < kPatchCosAngle ||
                std::abs(c->normal.dot(n.centroid - c->centroid)) > kPatchOffsetM ||
                std::abs(n.normal.dot(c->centroid - n.centroid)) > kPatchOffsetM) {
              continue;
            }
            n.patch = id;
            queue.push_back({nk, &n});
          }
    }
  }
  return patches;
}

// A patch's plane with the axes of an upright board facing the sensor on it, and the extent
// of its inliers along them from the centroid.
struct PatchFrame {
  LocalPlane plane;
  Eigen::Vector3d n, ex, ey;  // z towards the sensor, y up the spin axis, x = y cross z
  double lo_x = 1e9, hi_x = -1e9, lo_y = 1e9, hi_y = -1e9;
};

// Needs a patch and the page size; gives its plane and axes, or nothing for a patch whose plane
// fails, a floor (kMaxNormalZ), one far larger than the page (a wall) or far narrower.
std::optional<PatchFrame> FramePatch(const std::vector<Cell*>& patch,
                                     const std::vector<Eigen::Vector3d>& pts,
                                     const Eigen::Vector2d& page) {
  std::vector<int> members;
  for (const Cell* c : patch) members.insert(members.end(), c->points.begin(), c->points.end());
  PatchFrame f;
  f.plane = FitLocalPlane(pts, members);
  const LocalPlane& plane = f.plane;
  if (!plane.ok) return std::nullopt;
  f.n = plane.normal.dot(plane.centroid) > 0.0 ? -plane.normal : plane.normal;
  if (std::abs(f.n.z()) > kMaxNormalZ) return std::nullopt;
  // Board axes of an upright board facing the sensor: y up the spin axis projected onto the
  // plane, z the normal towards the sensor, x = y cross z.
  f.ey = (Eigen::Vector3d::UnitZ() - f.n.z() * f.n).normalized();
  f.ex = f.ey.cross(f.n);
  for (int i : plane.inliers) {
    const Eigen::Vector3d d = pts[i] - plane.centroid;
    f.lo_x = std::min(f.lo_x, d.dot(f.ex));
    f.hi_x = std::max(f.hi_x, d.dot(f.ex));
    f.lo_y = std::min(f.lo_y, d.dot(f.ey));
    f.hi_y = std::max(f.hi_y, d.dot(f.ey));
  }
  // A patch far larger than the page is a wall or a floor; skip the gathering.
  // One far narrower than its rings' span on the page is not a board either.
  if (f.hi_x - f.lo_x > 2.0 * page.x() || f.hi_y - f.lo_y > 2.0 * page.y() ||
      f.hi_x - f.lo_x < 0.5 * page.x()) {
    return std::nullopt;
  }
  return f;
}

// One ring's points near a patch's plane, in its axes.
struct RingOnPlane {
  std::vector<double> x, y;
};

// Needs a patch's frame, the search points and the cubes; gives every point of the frame near
// the plane (kGatherDepthM) and the patch (kGatherMarginM), per ring, but those on another
// plane (OnAnotherPlane).
std::map<int, RingOnPlane> GatherRings(const PatchFrame& f, const SearchPoints& points,
                                       const CellMap& cells, double cell_m) {
  const std::vector<Eigen::Vector3d>& pts = points.pts;
  std::map<int, RingOnPlane> ring_points;
  const double reach2 = std::pow(f.hi_x - f.lo_x + f.hi_y - f.lo_y + 2.0 * kGatherMarginM, 2);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const Eigen::Vector3d d = pts[i] - f.plane.centroid;
    if (d.squaredNorm() > reach2) continue;
    if (OnAnotherPlane(cells, KeyOf(pts[i], cell_m), pts[i], f.n)) continue;
    const double x = d.dot(f.ex), y = d.dot(f.ey);
    if (std::abs(d.dot(f.n)) > kGatherDepthM || x < f.lo_x - kGatherMarginM ||
        x > f.hi_x + kGatherMarginM || y < f.lo_y - kGatherMarginM || y > f.hi_y + kGatherMarginM) {
      continue;
    }
    RingOnPlane& ring = ring_points[points.rings[i]];
    ring.x.push_back(x);
    ring.y.push_back(y);
  }
  return ring_points;
}

// The rings that cross the page: each one's width, mid-point across and median height, and how
// many show a hole's chord.
struct RingCrossings {
  std::vector<double> widths, mids, ys;
  int rings_with_gap = 0;
};

// Needs a patch's rings (their x sorted here), the page and the widest hole chord; gives the
// rings whose span is the page's width (kMaxWidthRatio) and which of them show a gap a hole
// would leave.
RingCrossings CrossingRings(std::map<int, RingOnPlane>* ring_points, const Eigen::Vector2d& page,
                            double max_hole_chord) {
  RingCrossings out;
  for (auto& [ring, on_plane] : *ring_points) {
    std::sort(on_plane.x.begin(), on_plane.x.end());
    const double width = on_plane.x.back() - on_plane.x.front();
    // Wider than the page: not the board's (the floor's rings along the plane's foot).
    if (width < 0.5 * page.x() || width > kMaxWidthRatio * page.x()) continue;
    out.widths.push_back(width);
    out.mids.push_back(0.5 * (on_plane.x.front() + on_plane.x.back()));
    out.ys.push_back(Median(on_plane.y));
    // A hole's chord: a gap along the ring wider than 2.5 of its point spacings (and 4 cm),
    // narrower than a hole.
    std::vector<double> spacing(on_plane.x.size() - 1);
    for (std::size_t k = 1; k < on_plane.x.size(); ++k)
      spacing[k - 1] = on_plane.x[k] - on_plane.x[k - 1];
    const double min_gap = std::max(2.5 * Median(spacing), kMinHoleChordM);
    out.rings_with_gap += std::any_of(spacing.begin(), spacing.end(),
                                      [&](double g) { return g > min_gap && g < max_hole_chord; })
                              ? 1
                              : 0;
  }
  return out;
}

// Step 3 for one patch. Needs the patch, the search points, the cubes, the page and the widest
// hole chord (plus kMinHoleChordM); gives the candidate when the patch is board-sized (its
// crossing rings as wide as the page, no taller) with enough rings crossing a hole, and sets
// *board_sized when it is board-sized at all.
std::optional<Candidate> CandidateOfPatch(const std::vector<Cell*>& patch,
                                          const SearchPoints& points, const CellMap& cells,
                                          const Eigen::Vector2d& page, double max_hole_chord,
                                          const RoundHoleSearchOptions& options,
                                          bool* board_sized) {
  *board_sized = false;
  const std::optional<PatchFrame> f = FramePatch(patch, points.pts, page);
  if (!f.has_value()) return std::nullopt;
  std::map<int, RingOnPlane> ring_points = GatherRings(*f, points, cells, options.cell_m);
  const RingCrossings crossing = CrossingRings(&ring_points, page, max_hole_chord);
  if (crossing.widths.size() < 2) return std::nullopt;
  const double width = Median(crossing.widths);
  if (width < kMinWidthRatio * page.x() || width > kMaxWidthRatio * page.x()) return std::nullopt;
  const auto [y_lo, y_hi] = std::minmax_element(crossing.ys.begin(), crossing.ys.end());
  const double height = *y_hi - *y_lo;
  if (height > kMaxHeightRatio * page.y()) return std::nullopt;
  *board_sized = true;
  // Fewer rings cross a hole than the whole-board fit needs: a plain panel, not worth it.
  if (crossing.rings_with_gap < options.fit.min_rings_through_holes) return std::nullopt;
  // The centre: the crossing rings' mid-points across, the middle of the outermost crossing
  // rings up; the page's true top and bottom lie up to a ring spacing beyond them, which is
  // what the vertical shift range must cover.
  const Eigen::Vector3d centre =
      f->plane.centroid + Median(crossing.mids) * f->ex + 0.5 * (*y_lo + *y_hi) * f->ey;
  Eigen::Matrix3d R;
  R << f->ex, f->ey, f->n;
  Candidate c;
  c.T_lidar_board = Rigid3d(R, centre);
  c.shift_range_m =
      std::max(options.fit.max_in_plane_shift_m,
               std::min(0.5 * std::max(page.y() - height, 0.0) + 0.04, kMaxShiftRangeM));
  c.width_error = std::abs(width / page.x() - 1.0);
  return c;
}

// Step 4's result: the distinct boards found with empty holes, and the failure that got
// furthest.
struct FittedBoards {
  std::vector<RoundHoleCloudDetection> boards;
  std::vector<double> fills;  // per board: HoleGeometry::Fill
  RoundHoleCloudDetection best_failure;
  bool have_failure = false;
};

// Step 4. Needs the candidates; gives the whole-board fit from each, kept when found with
// empty holes (kMaxHoleFill); a board found twice (kSameBoardPages) keeps its better fit. The
// failure kept is the one with most edges fitted.
FittedBoards FitCandidates(const Board& board,
                           std::span<const std::span<const RoundHoleCloudPoint>> frames,
                           const std::vector<Candidate>& candidates,
                           const RoundHoleSearchOptions& options, const Eigen::Vector2d& page) {
  const HoleGeometry holes(board, page);
  FittedBoards out;
  std::vector<RoundHoleCloudDetection>& boards = out.boards;
  for (const Candidate& c : candidates) {
    RoundHoleCloudOptions fit = options.fit;
    fit.max_in_plane_shift_m = c.shift_range_m;
    RoundHoleCloudDetection d = DetectRoundHoleBoardInCloud(board, frames, c.T_lidar_board, fit);
    if (d.found) {
      const double fill = holes.Fill(frames, d);
      if (fill <= kMaxHoleFill) {
        const auto same = std::find_if(boards.begin(), boards.end(), [&](const auto& b) {
          return (b.T_lidar_board.translation() - d.T_lidar_board.translation()).norm() <
                 kSameBoardPages * page.x();
        });
        if (same == boards.end()) {
          boards.push_back(std::move(d));
          out.fills.push_back(fill);
        } else if (d.edge_rms_m < same->edge_rms_m) {
          *same = std::move(d);
          out.fills[same - boards.begin()] = fill;
        }
        continue;
      }
      d.found = false;
      d.reason = RoundHoleCloudReason::kFitFailed;
    }
    // The failure that got furthest: most edges fitted.
    if (!out.have_failure || d.edges > out.best_failure.edges) {
      out.best_failure = std::move(d);
      out.have_failure = true;
    }
  }
  return out;
}
}  // namespace

bool RoundHoleSearchOptions::Valid() const {
  return std::isfinite(min_range_m) && min_range_m >= 0.0 && std::isfinite(max_range_m) &&
         max_range_m > min_range_m && std::isfinite(cell_m) && cell_m > 0.0 &&
         max_candidates >= 1 && fit.Valid();
}

const char* RoundHoleFitVerdictName(RoundHoleFitVerdict verdict) {
  switch (verdict) {
    case RoundHoleFitVerdict::kChosen:
      return "chosen";
    case RoundHoleFitVerdict::kTies:
      return "ties";
    case RoundHoleFitVerdict::kWorseFit:
      return "worse_fit";
  }
  return "unknown";
}

const char* RoundHoleSearchReasonName(RoundHoleSearchReason reason) {
  switch (reason) {
    case RoundHoleSearchReason::kNone:
      return "";
    case RoundHoleSearchReason::kBadInput:
      return "bad_input";
    case RoundHoleSearchReason::kNoPoints:
      return "no_points";
    case RoundHoleSearchReason::kNoPlane:
      return "no_plane";
    case RoundHoleSearchReason::kBoardNotFound:
      return "board_not_found";
    case RoundHoleSearchReason::kAmbiguous:
      return "ambiguous";
  }
  return "unknown";
}

int AssignRingsByElevation(std::span<std::vector<RoundHoleCloudPoint>> frames, double gap_rad) {
  constexpr double kMinRangeM = 0.3;
  std::vector<double> elevations;
  const auto elevation = [](const RoundHoleCloudPoint& p) {
    return std::atan2(static_cast<double>(p.z), std::hypot(static_cast<double>(p.x), p.y));
  };
  const auto usable = [&](const RoundHoleCloudPoint& p) {
    const double r = std::sqrt(double(p.x) * p.x + double(p.y) * p.y + double(p.z) * p.z);
    return std::isfinite(r) && r >= kMinRangeM;
  };
  for (const auto& frame : frames)
    for (const RoundHoleCloudPoint& p : frame)
      if (usable(p)) elevations.push_back(elevation(p));
  if (elevations.empty()) return 0;
  std::sort(elevations.begin(), elevations.end());
  // The lower bound of each ring's cluster.
  std::vector<double> starts = {elevations.front()};
  for (std::size_t i = 1; i < elevations.size(); ++i)
    if (elevations[i] - elevations[i - 1] > gap_rad) starts.push_back(elevations[i]);
  for (auto& frame : frames) {
    for (RoundHoleCloudPoint& p : frame) {
      p.ring = 0;
      if (!usable(p)) continue;
      const auto it = std::upper_bound(starts.begin(), starts.end(), elevation(p));
      p.ring =
          static_cast<std::uint16_t>(std::clamp<std::ptrdiff_t>(it - starts.begin() - 1, 0, 65535));
    }
  }
  return static_cast<int>(starts.size());
}

RoundHoleSearchResult SearchRoundHoleBoardInCloud(
    const Board& board, std::span<const std::span<const RoundHoleCloudPoint>> frames,
    const RoundHoleSearchOptions& options) {
  RoundHoleSearchResult out;
  if (board.type() != BoardType::kRoundHole || !options.Valid()) return out;
  const Eigen::Vector2d page = board.page_size_m();
  const SearchPoints points = SelectSearchPoints(frames, options);
  out.reason = RoundHoleSearchReason::kNoPoints;
  if (points.pts.empty()) return out;

  // 1. Cubes and their neighbourhoods' planes.
  CellMap cells = FlatCells(points, options.cell_m, &out.planar_cells);

  // 2. Patches: flat cubes joined through flat neighbours on the same plane.
  const std::vector<std::vector<Cell*>> patches = JoinPatches(&cells);

  // 3. Board-sized patches.
  double max_hole_chord = 0.0;
  for (const BoardShape& s : board.shapes())
    if (s.paint == Paint::kHole) max_hole_chord = std::max(max_hole_chord, 2.0 * s.radius_m());
  max_hole_chord += kMinHoleChordM;
  std::vector<Candidate> candidates;
  for (const std::vector<Cell*>& patch : patches) {
    bool board_sized = false;
    const std::optional<Candidate> c =
        CandidateOfPatch(patch, points, cells, page, max_hole_chord, options, &board_sized);
    if (board_sized) ++out.board_sized_patches;
    if (c.has_value()) candidates.push_back(*c);
  }
  out.reason = out.board_sized_patches > 0 ? RoundHoleSearchReason::kBoardNotFound
                                           : RoundHoleSearchReason::kNoPlane;
  if (candidates.empty()) return out;
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.width_error < b.width_error; });
  if (static_cast<int>(candidates.size()) > options.max_candidates)
    candidates.resize(options.max_candidates);
  out.candidates = static_cast<int>(candidates.size());

  // 4. The whole-board fit from each candidate, and the empty-holes test.
  FittedBoards fitted = FitCandidates(board, frames, candidates, options, page);
  out.boards_fitted = static_cast<int>(fitted.boards.size());
  if (fitted.boards.empty()) {
    out.reason = RoundHoleSearchReason::kBoardNotFound;
    out.detection = std::move(fitted.best_failure);
    return out;
  }

  // 5. Ranking.
  std::vector<std::size_t> order;
  out.fits = RankFits(fitted.boards, fitted.fills, &order);
  const std::size_t best = order.front();
  out.found = out.fits.front().verdict == RoundHoleFitVerdict::kChosen;
  out.reason = out.found ? RoundHoleSearchReason::kNone : RoundHoleSearchReason::kAmbiguous;
  out.detection = std::move(fitted.boards[best]);
  if (!out.found) {
    out.detection.found = false;
    out.detection.holes.clear();
  }
  return out;
}

}  // namespace linecal

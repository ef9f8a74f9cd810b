#pragma once
// Finding the round-hole board (docs/boards.md section 6) in point clouds without knowing where it
// is: `linecal detect --cloud` and any caller with no expected pose. The method
// (docs/lidar-radar.md, "Finding the board without a prior"):
//
//  1. Local planes: the first frame's points are hashed into cubes of `cell_m`; each cube's
//     neighbourhood (the 3x3x3 cubes around it) gets a robust orthogonal plane fit, kept when
//     it is flat (robust sigma), spans two rings or more (not a single scan line) and most of
//     the cube's own points lie on it.
//  2. Patches: flat cubes are grown into patches through neighbours with the same plane.
//  3. Board-sized patches: each patch's plane gathers the frame's points near it; the rings
//     that cross it (at least half the page wide) must be as wide as the page and span no
//     more than its height. Floors (a normal within 45 degrees of the spin axis), walls and
//     anything else too large or too small are dropped, and so is a patch that fewer than
//     two rings cross with a gap the size of a hole's chord (a plain panel).
//  4. Each remaining patch is a prior pose for DetectRoundHoleBoardInCloud (upright: board y
//     along the spin axis projected onto the plane, z towards the sensor, the centre from the
//     crossing rings), which fits the whole board over every frame. A fit is kept when its
//     holes are empty: hardly any point of the fitted plane lies inside the hole circles
//     (a plain panel the size of the board fills them).
//  5. The boards kept are ranked by how well the board's outline and holes explain their
//     ring edges, as an angle (the edges' RMS residual over the range: a genuine board keeps it
//     near the LiDAR's azimuth step at any range). One board: found. Several: the best is
//     found when every other fits at least kClearlyWorseFit times worse; otherwise ambiguous.
//     Either way every board kept is listed with its evidence and why it lost, so that a
//     technician can tell what to move or cover. None: a reason.
//
// Pure functions over plain point arrays (no PCL). Frames and units as in round_hole_cloud.h.

#include <Eigen/Core>
#include <cstdint>
#include <span>
#include <vector>

#include "detectors/boards/board.h"
#include "detectors/round_hole/round_hole_cloud.h"

namespace linecal {

struct RoundHoleSearchOptions {
  // Points nearer or farther than this from the sensor are not searched (the sensor's own
  // car and housing; boards at 3-8 m, docs/acceptance.md), metres.
  double min_range_m = 1.0;
  double max_range_m = 20.0;
  // Edge of the cubes of step 1, metres: a quarter of the page, so that a neighbourhood
  // (three cubes) lies within the board and still spans two rings of a 16-ring LiDAR at 8 m.
  double cell_m = 0.25;
  // At most this many board-sized patches go to the whole-board fit (the best-sized first).
  int max_candidates = 24;
  // The whole-board fit of each candidate. Its in-plane shift range is widened per candidate
  // to the uncertainty of the candidate's centre (about half a ring spacing vertically); its
  // rotation range (2 degrees) is how far the board's edges may be from level with the
  // LiDAR's spin plane.
  RoundHoleCloudOptions fit;
  // OK when every field is finite and in range. O(1).
  bool Valid() const;
};

// How a board kept by the search fared in the ranking of step 5.
enum class RoundHoleFitVerdict : std::uint8_t {
  kChosen,    // the board found
  kTies,      // fits about as well as the best: together they make the search ambiguous
  kWorseFit,  // its edges fit kClearlyWorseFit times worse than the best's, or more
};

// "chosen", "ties", "worse_fit".
const char* RoundHoleFitVerdictName(RoundHoleFitVerdict verdict);

// Ranking thresholds of step 5. Between two genuine boards the angular edge RMS differs by
// the spread of a few hundred edges' quantisation and the incidence (measured in the
// closed-loop tests: ratios up to 1.3); a look-alike (a board of another size, a shelf with
// gaps) fits its edges two to several times worse.
inline constexpr double kClearlyWorseFit = 2.0;

// One board that passed the whole-board fit and the empty-holes test: its evidence.
struct RoundHoleBoardFit {
  Eigen::Vector3d centre_lidar = Eigen::Vector3d::Zero();  // the fitted board's centre, m
  int edges = 0;                                           // ring edges the in-plane fit kept
  double edge_rms_m = 0.0;                                 // their RMS residual
  double edge_rms_rad = 0.0;    // edge_rms_m over the range of the centre
  double hole_fill = 0.0;       // density in the holes over that on the paper (0: empty)
  int rings_through_holes = 0;  // distinct rings crossing a hole
  RoundHoleFitVerdict verdict = RoundHoleFitVerdict::kTies;
  // edge_rms_rad over the best board's (1 for the best itself).
  double rms_ratio = 1.0;
};

enum class RoundHoleSearchReason : std::uint8_t {
  kNone = 0,       // found
  kBadInput,       // not a round-hole board, or invalid options
  kNoPoints,       // no finite point within the search range
  kNoPlane,        // no planar patch of the board's size
  kBoardNotFound,  // board-sized patches, but none fits the board with empty holes
  kAmbiguous,      // two or more boards apart fit alike (step 5; see `fits`)
};

// "", "bad_input", "no_points", "no_plane", "board_not_found", "ambiguous".
const char* RoundHoleSearchReasonName(RoundHoleSearchReason reason);

struct RoundHoleSearchResult {
  bool found = false;
  RoundHoleSearchReason reason = RoundHoleSearchReason::kBadInput;
  // The board's detection when found; otherwise that of the best-fitting candidate (so its
  // fit quality and reason say how far it got), empty when there was none.
  RoundHoleCloudDetection detection;
  int planar_cells = 0;         // cubes of step 1 with a flat neighbourhood
  int board_sized_patches = 0;  // patches of step 3 of the board's size
  int candidates = 0;           // those with a ring crossing a hole, tried by the whole-board fit
  int boards_fitted = 0;        // distinct boards that passed the whole-board fit
  // Those boards, ranked (step 5): the chosen or tying ones first, best fit first.
  std::vector<RoundHoleBoardFit> fits;
};

// Searches `frames` (one or more rotations of one LiDAR, the board still) for `board` (must be
// BoardType::kRoundHole, any scale). Rings must be set (AssignRingsByElevation when the data
// has none). Never throws, never asserts on the data. Cost: linear in the first frame's points
// for steps 1-3 (a few ms for 100k points), then one DetectRoundHoleBoardInCloud per
// candidate.
RoundHoleSearchResult SearchRoundHoleBoardInCloud(
    const Board& board, std::span<const std::span<const RoundHoleCloudPoint>> frames,
    const RoundHoleSearchOptions& options = {});

// Sets every point's ring from its elevation angle (atan2(z, hypot(x, y)), the LiDAR frame)
// for data without a ring field: a spinning LiDAR's beams each keep one elevation, so the
// elevations of all points of all frames, sorted, fall into one tight cluster per beam.
// Clusters are split where consecutive elevations differ by more than `gap_rad` (0.05 degree:
// a third of the finest beam spacing of the supported 16-128 beam models); ring 0 is the
// lowest. Points nearer than 0.3 m (no sensor returns there) keep ring 0. Returns the number
// of rings. O(n log n).
int AssignRingsByElevation(std::span<std::vector<RoundHoleCloudPoint>> frames,
                           double gap_rad = 0.05 * 3.14159265358979323846 / 180.0);

}  // namespace linecal

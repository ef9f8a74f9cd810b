// Closed-loop tests of the prior-free round-hole board search: the station simulator scans a
// board on its stand with the floor, a wall behind it and a plain box of the board's size
// beside it, with the reference car's Pandar64 and VLP-16 beam tables at 3-8 m and several
// headings; the search must find the board (hole centres within docs/acceptance.md's bars) and
// never report the box; two boards are ambiguous; empty and board-less clouds (including the
// real reference scans of docs/external-data.md) give their reasons.
#include "detectors/round_hole/round_hole_search.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "station/sensors/lidar/pcd.h"
#include "tests/detectors/round_hole/round_hole_scene.h"
#include "tests/support/external_data.h"

namespace linecal {
namespace {

// How much larger the look-alike of TheBoardBeatsALookAlike is printed.
constexpr double kLookAlikeScale = 1.08;

RoundHoleSearchResult Search(const Scene& scene, double* ms_per_frame = nullptr) {
  return TimedPerFrame(scene, ms_per_frame,
                       [&](auto views) { return SearchRoundHoleBoardInCloud(scene.board, views); });
}

TEST(RoundHoleSearchTest, FindsTheBoardAmongFloorWallAndABox) {
  constexpr double kNormalBarRad = 0.1 * kDegToRad;
  const Case cases[] = {
      {"roof_lidar", 3.0, 0.0, 0.0, 0.02, 0.01},
      {"roof_lidar", 5.0, 120.0, 30.0, 0.03, 0.01},
      {"roof_lidar", 8.0, -70.0, -35.0, 0.02, 0.01},
      {"bumper_lidar", 3.0, 200.0, 25.0, 0.02, 0.02},
      {"bumper_lidar", 5.0, -30.0, -20.0, 0.02, 0.02},
      {"bumper_lidar", 8.0, 60.0, 10.0, 0.02, 0.02},
  };
  for (const Case& c : cases) {
    const Scene scene = SimulateLayout(Beams(c.sensor), BoardWallAndBox(c), c.sigma_m, 10);
    double ms = 0.0;
    const RoundHoleSearchResult r = Search(scene, &ms);
    const std::string what = std::string(c.sensor) + " at " + std::to_string(c.distance_m) +
                             " m, bearing " + std::to_string(c.bearing_deg);
    ASSERT_TRUE(r.found) << what << ": " << RoundHoleSearchReasonName(r.reason) << " ("
                         << RoundHoleCloudReasonName(r.detection.reason) << ", " << r.candidates
                         << " candidates)";
    EXPECT_EQ(r.boards_fitted, 1) << what;
    ASSERT_EQ(r.detection.holes.size(), 5u);
    const double worst = WorstHoleError(scene, r.detection);
    const double normal_error =
        std::acos(std::clamp(r.detection.T_lidar_board.RotationMatrix().col(2).dot(
                                 scene.T_lidar_board.RotationMatrix().col(2)),
                             -1.0, 1.0));
    const bool bar_reachable = 3.0 * r.detection.normal_sigma_rad <= kNormalBarRad;
    std::printf(
        "%-12s %3.0f m bearing %4.0f heading %4.0f: %d candidates, worst hole %4.1f mm, "
        "normal %.3f deg (1-sigma %.3f), %5.2f ms/frame\n",
        c.sensor, c.distance_m, c.bearing_deg, c.heading_deg, r.candidates, 1e3 * worst,
        normal_error / kDegToRad, r.detection.normal_sigma_rad / kDegToRad, ms);
    EXPECT_LT(worst, c.bar_m) << what;
    EXPECT_LT(normal_error, bar_reachable ? kNormalBarRad : 4.0 * r.detection.normal_sigma_rad)
        << what;
    // The box's sides are board-sized planes too: seen and refused.
    EXPECT_GE(r.board_sized_patches, 2) << what;
  }
}

TEST(RoundHoleSearchTest, APlainBoxIsNotABoard) {
  for (const char* sensor : {"roof_lidar", "bumper_lidar"}) {
    StationLayout layout;
    layout.name = "box_only";
    // The layout needs a board for the scene's truth: put it behind the LiDAR, out of range.
    layout.boards.push_back(RoundHoleAt(FacingPose(40.0, 180.0, 0.0)));
    AddBox(layout, 4.0, 0.0);
    AddBox(layout, 6.0, 100.0);
    const Scene scene = SimulateLayout(Beams(sensor), layout, 0.02, 5);
    const RoundHoleSearchResult r = Search(scene);
    EXPECT_FALSE(r.found) << sensor;
    EXPECT_EQ(r.reason, RoundHoleSearchReason::kBoardNotFound)
        << sensor << ": " << RoundHoleSearchReasonName(r.reason);
    EXPECT_GE(r.board_sized_patches, 2) << sensor;
  }
}

TEST(RoundHoleSearchTest, TwoBoardsAreAmbiguous) {
  StationLayout layout;
  layout.name = "two_boards";
  layout.boards.push_back(RoundHoleAt(FacingPose(4.0, 0.0, 0.0), 1.0, "a"));
  layout.boards.push_back(RoundHoleAt(FacingPose(5.0, 60.0, 10.0), 1.0, "b"));
  const Scene scene = SimulateLayout(Beams("roof_lidar"), layout, 0.02, 3);
  const RoundHoleSearchResult r = Search(scene);
  EXPECT_FALSE(r.found);
  EXPECT_EQ(r.reason, RoundHoleSearchReason::kAmbiguous) << RoundHoleSearchReasonName(r.reason);
  EXPECT_EQ(r.boards_fitted, 2);
  EXPECT_TRUE(r.detection.holes.empty());
  // Both genuine boards fit their edges alike: listed, best first, both tying.
  ASSERT_EQ(r.fits.size(), 2u);
  for (const RoundHoleBoardFit& f : r.fits) {
    std::printf("board at %.2f m: %d edges, %.2f mrad (x%.2f), fill %.2f: %s\n",
                f.centre_lidar.norm(), f.edges, 1e3 * f.edge_rms_rad, f.rms_ratio, f.hole_fill,
                RoundHoleFitVerdictName(f.verdict));
    EXPECT_EQ(f.verdict, RoundHoleFitVerdict::kTies);
    EXPECT_LE(f.hole_fill, 0.15);
  }
  EXPECT_LE(r.fits[0].edge_rms_rad, r.fits[1].edge_rms_rad);
  EXPECT_LT(r.fits[1].rms_ratio, kClearlyWorseFit);
}

// A look-alike beside the board: a round-hole board printed 8% larger (its holes and outline
// off the true board's by 2-4 cm) passes the whole-board fit and the empty-holes test, but
// fits its edges far worse; the search finds the true board and says why the other lost.
TEST(RoundHoleSearchTest, TheBoardBeatsALookAlike) {
  for (const char* sensor : {"roof_lidar", "bumper_lidar"}) {
    StationLayout layout;
    layout.name = "board_and_look_alike";
    layout.boards.push_back(RoundHoleAt(FacingPose(4.5, 0.0, 0.0), 1.0, "board"));
    layout.boards.push_back(RoundHoleAt(FacingPose(4.5, 50.0, 0.0), kLookAlikeScale, "other"));
    const Scene scene = SimulateLayout(Beams(sensor), layout, 0.02, 5);
    const RoundHoleSearchResult r = Search(scene);
    for (const RoundHoleBoardFit& f : r.fits) {
      std::printf("%s: board at %.2f m: %d edges, %.2f mrad (x%.2f), fill %.2f: %s\n", sensor,
                  f.centre_lidar.norm(), f.edges, 1e3 * f.edge_rms_rad, f.rms_ratio, f.hole_fill,
                  RoundHoleFitVerdictName(f.verdict));
    }
    ASSERT_TRUE(r.found) << sensor << ": " << RoundHoleSearchReasonName(r.reason);
    EXPECT_LT(WorstHoleError(scene, r.detection), 0.03) << sensor;
    ASSERT_EQ(r.fits.size(), 2u) << sensor;
    EXPECT_EQ(r.fits[0].verdict, RoundHoleFitVerdict::kChosen) << sensor;
    EXPECT_EQ(r.fits[1].verdict, RoundHoleFitVerdict::kWorseFit) << sensor;
    EXPECT_GE(r.fits[1].rms_ratio, kClearlyWorseFit) << sensor;
    // The chosen board is the true one, the look-alike the other.
    EXPECT_LT((r.fits[0].centre_lidar - scene.T_lidar_board.translation()).norm(), 0.05) << sensor;
  }
}

TEST(RoundHoleSearchTest, EmptyAndBoardlessClouds) {
  const Board board = *Board::Create({.type = BoardType::kRoundHole});
  EXPECT_EQ(SearchRoundHoleBoardInCloud(board, {}).reason, RoundHoleSearchReason::kNoPoints);
  const std::vector<RoundHoleCloudPoint> empty;
  const std::span<const RoundHoleCloudPoint> empty_view(empty);
  EXPECT_EQ(SearchRoundHoleBoardInCloud(board, {&empty_view, 1}).reason,
            RoundHoleSearchReason::kNoPoints);
  // The floor only: no plane of the board's size.
  StationLayout layout;
  layout.name = "floor_only";
  layout.boards.push_back(RoundHoleAt(FacingPose(40.0, 180.0, 0.0)));
  const Scene floor = SimulateLayout(Beams("bumper_lidar"), layout, 0.02, 2);
  const RoundHoleSearchResult r = Search(floor);
  EXPECT_FALSE(r.found);
  EXPECT_EQ(r.reason, RoundHoleSearchReason::kNoPlane) << RoundHoleSearchReasonName(r.reason);
  // Another board type and invalid options.
  const Board aruco = *Board::Create({.type = BoardType::kAruco});
  EXPECT_EQ(SearchRoundHoleBoardInCloud(aruco, {&empty_view, 1}).reason,
            RoundHoleSearchReason::kBadInput);
  RoundHoleSearchOptions bad;
  bad.cell_m = 0.0;
  EXPECT_EQ(SearchRoundHoleBoardInCloud(board, {&empty_view, 1}, bad).reason,
            RoundHoleSearchReason::kBadInput);
  EXPECT_STREQ(RoundHoleSearchReasonName(RoundHoleSearchReason::kAmbiguous), "ambiguous");
}

// The real scans of docs/external-data.md (a VLP-16 and a Pandar64 in ordinary surroundings, no
// board): never a false board.
TEST(RoundHoleSearchTest, RealScansWithoutABoard) {
  const Board board = *Board::Create({.type = BoardType::kRoundHole});
  for (const char* model : {"vlp16", "pandar64"}) {
    LINECAL_EXTERNAL_OR_SKIP(path, std::string("lidar/") + model + "/reference_scan.pcd");
    const absl::StatusOr<PcdCloud> cloud = ReadPcd(path);
    ASSERT_TRUE(cloud.ok()) << cloud.status();
    std::vector<std::vector<RoundHoleCloudPoint>> frames(1);
    for (const LidarPoint& p : cloud->points) frames[0].push_back({p.x, p.y, p.z, p.ring});
    // nebula names its rings "channel", which ReadPcd does not take for a ring.
    if (!cloud->has_ring) AssignRingsByElevation(frames);
    const std::vector<RoundHoleCloudPoint>& points = frames[0];
    const std::span<const RoundHoleCloudPoint> view(points);
    const RoundHoleSearchResult r = SearchRoundHoleBoardInCloud(board, {&view, 1});
    std::printf("%s: %zu points, %d flat cells, %d candidates: %s\n", model, points.size(),
                r.planar_cells, r.candidates, RoundHoleSearchReasonName(r.reason));
    EXPECT_FALSE(r.found) << model;
    EXPECT_NE(r.reason, RoundHoleSearchReason::kNone) << model;
    EXPECT_GT(r.planar_cells, 0) << model;  // it did look: the scans are full of planes
  }
}

// Without a ring field the rings come from the elevations: the same partition of the points
// as the beams', and the board is found as well.
TEST(RoundHoleSearchTest, RingsFromElevation) {
  for (const char* sensor : {"roof_lidar", "bumper_lidar"}) {
    Scene scene = Simulate(Beams(sensor), 5.0, 20.0, 15.0, 0.02, 3);
    std::vector<std::vector<RoundHoleCloudPoint>> stripped = scene.frames;
    for (auto& f : stripped)
      for (RoundHoleCloudPoint& p : f) p.ring = 999;
    const int rings = AssignRingsByElevation(stripped);
    std::map<int, int> true_to_derived;
    std::map<int, int> derived_to_true;
    bool consistent = true;
    for (std::size_t f = 0; f < stripped.size(); ++f) {
      for (std::size_t i = 0; i < stripped[f].size(); ++i) {
        const int t = scene.frames[f][i].ring, d = stripped[f][i].ring;
        consistent = consistent && true_to_derived.try_emplace(t, d).first->second == d &&
                     derived_to_true.try_emplace(d, t).first->second == t;
      }
    }
    EXPECT_TRUE(consistent) << sensor;
    EXPECT_EQ(rings, static_cast<int>(true_to_derived.size())) << sensor;
    scene.frames = stripped;
    const RoundHoleSearchResult r = Search(scene);
    ASSERT_TRUE(r.found) << sensor << ": " << RoundHoleSearchReasonName(r.reason);
    EXPECT_LT(WorstHoleError(scene, r.detection), 0.02) << sensor;
  }
}

}  // namespace
}  // namespace linecal

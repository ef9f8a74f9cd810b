// The planner's geometry and checks (station/planner/planner.h): feature sizes, field of
// view, LiDAR rings through holes, occlusion, keep-out zones, radar fields of view, and the
// floor limits file.
#include "station/planner/planner.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>

#include "station/model/pose_json.h"
#include "station/sensors/lidar/lidar_format.h"

namespace linecal {
namespace {

constexpr double kDeg = std::numbers::pi / 180;

// One sensor of the given kind at xyz looking along +x (yaw 0, level).
SensorModel Sensor(SensorKind kind, const std::string& model, const Eigen::Vector3d& xyz,
                   const std::vector<std::string>& targets) {
  SensorModel s;
  s.name = "s";
  s.kind = kind;
  s.model = model;
  s.T_car_sensor_nominal = Rigid3d(MountingRotation({0, 0, 0}, SensorBaseRotation(kind)), xyz);
  s.tolerance = {1 * kDeg, 1 * kDeg, 1 * kDeg, Eigen::Vector3d(0.03, 0.03, 0.03)};
  if (kind == SensorKind::kCamera) {
    CameraIntrinsics k;
    k.width = 1920;
    k.height = 1080;
    k.fx = k.fy = 1000;
    k.cx = 959.5;
    k.cy = 539.5;
    s.intrinsics = k;
  }
  s.targets = targets;
  return s;
}

// A station layout from its boards' and reflectors' JSON.
StationLayout Layout(const std::string& boards, const std::string& reflectors = "") {
  const std::string text =
      R"({"format": "linecal.station", "version": 1, "name": "t", "boards": [)" + boards +
      R"(], "reflectors": [)" + reflectors + "]}";
  absl::StatusOr<StationLayout> layout = ParseStationLayout(text, "test");
  EXPECT_TRUE(layout.ok()) << layout.status();
  return layout.ok() ? *layout : StationLayout{};
}

std::string BoardJson(const std::string& id, const std::string& type, double x, double y, double z,
                      double yaw_deg, double scale = 1.0) {
  return "{\"id\": \"" + id + "\", \"type\": \"" + type +
         "\", \"scale\": " + std::to_string(scale) + ", \"pose\": {\"xyz_m\": [" +
         std::to_string(x) + ", " + std::to_string(y) + ", " + std::to_string(z) +
         "], \"ypr_deg\": [" + std::to_string(yaw_deg) + ", 0, 0]}}";
}

SensorAssessment AssessOrDie(const SensorModel& s, const StationLayout& layout,
                             const FloorLimits* floor = nullptr, bool predict = false,
                             const PlannerOptions& o = {}) {
  absl::StatusOr<SensorAssessment> a = AssessSensor(s, layout, floor, o, predict);
  EXPECT_TRUE(a.ok()) << a.status();
  return a.ok() ? *a : SensorAssessment{};
}

using Reasons = std::vector<std::string>;

TEST(SmallestCell, CatalogueBoards) {
  const auto cell = [](BoardType type, int border_bits = 2) {
    BoardParams p;
    p.type = type;
    p.apriltag_border_bits = border_bits;
    return SmallestCellM(*Board::Create(p));
  };
  EXPECT_NEAR(cell(BoardType::kChessboard), 0.150, 1e-9);  // the 150 mm squares
  EXPECT_NEAR(cell(BoardType::kAruco), 0.040, 1e-9);       // one marker bit of 40 mm
  EXPECT_NEAR(cell(BoardType::kRoundHole), 0.040, 1e-9);   // its ArUco markers' bits
  EXPECT_NEAR(cell(BoardType::kApriltag, 2), 0.0088, 1e-9);
  EXPECT_NEAR(cell(BoardType::kApriltag, 1), 0.011, 1e-9);
  EXPECT_NEAR(cell(BoardType::kChecker), 0.025, 1e-9);
  BoardParams twice;
  twice.type = BoardType::kAruco;
  twice.scale = 2;
  EXPECT_NEAR(SmallestCellM(*Board::Create(twice)), 0.080, 1e-9);
}

TEST(SmallestCellPx, FaceOnIsFOverDistanceAndObliqueIsSmaller) {
  const SensorModel s = Sensor(SensorKind::kCamera, "pinhole", {0, 0, 1.2}, {"b"});
  const CameraModel camera = *CameraModel::Create(*s.intrinsics);
  const StationLayout face_on = Layout(BoardJson("b", "chessboard", 10, 0, 1.2, 0));
  const Rigid3d T_camera_station = s.T_car_sensor_nominal.Inverse();
  // A fronto-parallel 150 mm square 10 m away is 1000 * 0.15 / 10 = 15 px anywhere in the image.
  EXPECT_NEAR(SmallestCellPx(camera, T_camera_station * face_on.boards[0].T_station_board,
                             face_on.boards[0].board),
              15.0, 1e-6);
  const StationLayout turned = Layout(BoardJson("b", "chessboard", 10, 0, 1.2, 60));
  const double oblique = SmallestCellPx(camera, T_camera_station * turned.boards[0].T_station_board,
                                        turned.boards[0].board);
  EXPECT_GT(oblique, 6.0);  // about 15 cos(60°), the nearer end a little larger
  EXPECT_LT(oblique, 8.0);
}

TEST(AssessCamera, FieldOfViewAndFeatureSize) {
  const SensorModel s = Sensor(SensorKind::kCamera, "pinhole", {0, 0, 1.2}, {"b"});
  EXPECT_EQ(AssessOrDie(s, Layout(BoardJson("b", "chessboard", 6, 0, 1.2, 0))).reasons, Reasons{});
  // 45° to the left: outside the ±44° horizontal view of f = 1000 px on 1920 px.
  EXPECT_EQ(AssessOrDie(s, Layout(BoardJson("b", "chessboard", 6, 6, 1.2, 45))).reasons,
            Reasons{"board_outside_fov"});
  // Turned away: the camera sees its back.
  EXPECT_EQ(AssessOrDie(s, Layout(BoardJson("b", "chessboard", 6, 0, 1.2, 180))).reasons,
            Reasons{"board_outside_fov"});
  // 15 m: 10 px squares, below the 15 px default; at 9 m they are 16.7 px.
  EXPECT_EQ(AssessOrDie(s, Layout(BoardJson("b", "chessboard", 15, 0, 1.2, 0))).reasons,
            Reasons{"features_too_small"});
  EXPECT_EQ(AssessOrDie(s, Layout(BoardJson("b", "chessboard", 9, 0, 1.2, 0))).reasons, Reasons{});
  PlannerOptions fine;
  fine.min_feature_px = 9;
  EXPECT_EQ(
      AssessOrDie(s, Layout(BoardJson("b", "chessboard", 15, 0, 1.2, 0)), nullptr, false, fine)
          .reasons,
      Reasons{});
}

TEST(AssessCamera, PredictedSigmaIsLinearInTheCornerNoiseAndTightensWithFrames) {
  const SensorModel s = Sensor(SensorKind::kCamera, "pinhole", {0, 0, 1.2}, {"b"});
  const StationLayout layout = Layout(BoardJson("b", "chessboard", 5, 0, 1.2, 0));
  PlannerOptions o;
  o.corner_noise_px = 0.1;
  const SensorAssessment a = AssessOrDie(s, layout, nullptr, true, o);
  ASSERT_TRUE(a.sigma_valid);
  o.corner_noise_px = 0.2;
  const SensorAssessment b = AssessOrDie(s, layout, nullptr, true, o);
  o.corner_noise_px = 0.1;
  o.camera_frames = 4;
  const SensorAssessment c = AssessOrDie(s, layout, nullptr, true, o);
  for (int i = 0; i < 6; ++i) {
    EXPECT_GT(a.sigma[i], 0);
    EXPECT_NEAR(b.sigma[i], 2 * a.sigma[i], 1e-9 * a.sigma[i] + 1e-15) << i;
    EXPECT_NEAR(c.sigma[i], 0.5 * a.sigma[i], 1e-6 * a.sigma[i]) << i;
  }
  // 5 px corners: far beyond a third of 1° / 3 cm.
  o.camera_frames = 1;
  o.corner_noise_px = 5;
  EXPECT_EQ(AssessOrDie(s, layout, nullptr, true, o).reasons,
            Reasons{"uncertainty_above_tolerance"});
}

TEST(SegmentHitsBoard, ThroughThePageOnly) {
  const StationLayout layout = Layout(BoardJson("b", "aruco", 5, 0, 1, 0));  // 1.1 m square
  const StationBoard& b = layout.boards[0];
  EXPECT_TRUE(SegmentHitsBoard({0, 0, 1}, {10, 0, 1}, b));
  EXPECT_TRUE(SegmentHitsBoard({0, 0.5, 1}, {10, 0.5, 1}, b));
  EXPECT_FALSE(SegmentHitsBoard({0, 0.6, 1}, {10, 0.6, 1}, b));  // beside the page
  EXPECT_FALSE(SegmentHitsBoard({0, 0, 1}, {4.9, 0, 1}, b));     // ends before it
  EXPECT_FALSE(SegmentHitsBoard({0, 0, 1}, {5, 0.2, 1.1}, b));   // ends on it (its own feature)
}

TEST(AssessCamera, OccludedByAnotherBoardNamesIt) {
  const SensorModel s = Sensor(SensorKind::kCamera, "pinhole", {0, 0, 1.2}, {"b"});
  // The chessboard's left group (board x -1.2..-0.75 m, i.e. station y +0.75..+1.2) behind
  // an ArUco board halfway.
  const std::string target = BoardJson("b", "chessboard", 8, 0, 1.2, 0);
  const SensorAssessment hidden =
      AssessOrDie(s, Layout(target + ", " + BoardJson("stray", "aruco", 4, 0.5, 1.2, 0)));
  EXPECT_EQ(hidden.reasons, Reasons{"occluded_by_board"});
  ASSERT_EQ(hidden.targets.size(), 1u);
  EXPECT_NE(hidden.targets[0].detail.find("'stray'"), std::string::npos)
      << hidden.targets[0].detail;
  // Between the two groups it hides no feature.
  EXPECT_EQ(
      AssessOrDie(s, Layout(target + ", " + BoardJson("stray", "vertical", 4, 0, 1.2, 0))).reasons,
      Reasons{});
  // Behind the target it hides nothing.
  EXPECT_EQ(
      AssessOrDie(s, Layout(target + ", " + BoardJson("stray", "aruco", 10, 0.5, 1.2, 0))).reasons,
      Reasons{});
}

// The hidden share of a page counts its 24 x 24 samples behind other boards and surfaces. The
// round-hole board (1.1 m, markers within 420 mm of its centre) at 8 m, an ArUco board (1.1 m)
// halfway: its edge 229 mm off the line of sight casts a shadow edge 458 mm off the target's
// centre, hiding the two outer sample columns (481 and 527 mm) of the margin and no feature;
// 150 mm off, 300 mm on the target, it hides the outer five columns and the side marker.
TEST(AssessCamera, HiddenShareOfThePageNamesTheOccluder) {
  const SensorModel s = Sensor(SensorKind::kCamera, "pinhole", {0, 0, 1.2}, {"b"});
  const std::string target = BoardJson("b", "round_hole", 8, 0, 1.2, 0);
  PlannerOptions o;
  o.min_feature_px = 1;  // the 40 mm marker bits are 5 px at 8 m: not what is tested here
  const auto assess = [&](const StationLayout& layout) {
    return AssessOrDie(s, layout, nullptr, false, o);
  };
  const SensorAssessment margin =
      assess(Layout(target + ", " + BoardJson("front", "aruco", 4, -(0.229 + 0.55), 1.2, 0)));
  EXPECT_EQ(margin.reasons, Reasons{});
  ASSERT_EQ(margin.targets.size(), 1u);
  EXPECT_DOUBLE_EQ(margin.targets[0].hidden_share, 2.0 / 24.0);
  EXPECT_EQ(margin.targets[0].hidden_by, "front");
  EXPECT_NE(
      margin.targets[0].detail.find("8% of the page hidden, most behind 'front', no feature;"),
      std::string::npos)
      << margin.targets[0].detail;

  const SensorAssessment marker =
      assess(Layout(target + ", " + BoardJson("front", "aruco", 4, 0.15 + 0.55, 1.2, 0)));
  EXPECT_EQ(marker.reasons, Reasons{"occluded_by_board"});
  EXPECT_DOUBLE_EQ(marker.targets[0].hidden_share, 5.0 / 24.0);
  EXPECT_EQ(marker.targets[0].hidden_by, "front");
  EXPECT_NE(marker.targets[0].detail.find(
                "hidden behind 'front'; 21% of the page hidden, most behind 'front';"),
            std::string::npos)
      << marker.targets[0].detail;

  // A surface of the layout (a screen) in the same place hides the same.
  const absl::StatusOr<StationLayout> screened = ParseStationLayout(
      R"({"format": "linecal.station", "version": 1, "name": "t", "boards": [)" + target +
          R"(], "surfaces": [{"id": "screen", "size_m": [1.1, 1.1],
                              "pose": {"xyz_m": [4, 0.7, 1.2], "ypr_deg": [0, 0, 0]}}]})",
      "test");
  ASSERT_TRUE(screened.ok()) << screened.status();
  const SensorAssessment behind_screen = assess(*screened);
  EXPECT_EQ(behind_screen.reasons, Reasons{"occluded_by_surface"});
  EXPECT_DOUBLE_EQ(behind_screen.targets[0].hidden_share, 5.0 / 24.0);
  EXPECT_EQ(behind_screen.targets[0].hidden_by, "screen");
  // Nothing in front: nothing hidden.
  const SensorAssessment clear = assess(Layout(target));
  EXPECT_EQ(clear.targets[0].hidden_share, 0.0);
  EXPECT_EQ(clear.targets[0].hidden_by, "");
}

TEST(RingsThroughHole, CountsTheElevationsInsideTheHole) {
  std::vector<double> beams;
  for (int e = -15; e <= 15; ++e) beams.push_back(e * kDeg);
  beams.push_back(0.0);  // a second beam at 0°: the same ring
  const Eigen::Vector3d facing(0, -1,
                               0);  // LiDAR frame: azimuth 0 is +y; the hole faces the sensor
  // A 0.12 m hole 5 m away spans ±1.375°: rings -1°, 0°, +1°.
  EXPECT_EQ(RingsThroughHole(beams, {0, 5, 0}, facing, 0.12), 3);
  // 10 m: ±0.69°, only 0°.
  EXPECT_EQ(RingsThroughHole(beams, {0, 10, 0}, facing, 0.12), 1);
  // Centred at +0.5° elevation (5 m): -0.875°..1.875°, rings 0° and 1°.
  EXPECT_EQ(RingsThroughHole(beams, {0, 5, 5 * std::tan(0.5 * kDeg)}, facing, 0.12), 2);
  // Above every beam.
  EXPECT_EQ(RingsThroughHole(beams, {0, 5, 5}, facing, 0.12), 0);
}

TEST(AssessLidar, TooFewRingsThroughTheHolesOfAFarBoard) {
  // VLP-16: rings 2° apart; a 0.24 m hole spans 4.6° at 3 m (two rings or more), 1.4° at 10 m.
  const SensorModel s = Sensor(SensorKind::kLidar, "vlp16", {0, 0, 1.0}, {"b"});
  const SensorAssessment near = AssessOrDie(s, Layout(BoardJson("b", "round_hole", 3, 0, 1.0, 0)));
  EXPECT_EQ(near.reasons, Reasons{});
  EXPECT_GE(near.targets[0].fewest_rings, 2);
  const SensorAssessment far = AssessOrDie(s, Layout(BoardJson("b", "round_hole", 10, 0, 1.0, 0)));
  EXPECT_EQ(far.reasons, Reasons{"too_few_rings"});
  EXPECT_LE(far.targets[0].fewest_rings, 1);
  // A chessboard is no LiDAR target.
  EXPECT_EQ(AssessOrDie(s, Layout(BoardJson("b", "chessboard", 3, 0, 1.0, 0))).reasons,
            Reasons{"wrong_target_type"});
  // Turned away.
  EXPECT_EQ(AssessOrDie(s, Layout(BoardJson("b", "round_hole", 3, 0, 1.0, 180))).reasons,
            Reasons{"board_outside_fov"});
}

TEST(AssessLidar, PredictedSigmaFromTheSimulatedDetector) {
  const SensorModel s = Sensor(SensorKind::kLidar, "vlp16", {0, 0, 1.0}, {"l", "r"});
  const StationLayout layout = Layout(BoardJson("l", "round_hole", 3, 1.2, 1.0, 22, 1.5) + ", " +
                                      BoardJson("r", "round_hole", 3, -1.2, 1.0, -22, 1.5));
  const SensorAssessment a = AssessOrDie(s, layout, nullptr, true);
  ASSERT_TRUE(a.sigma_valid) << a.reasons.size();
  for (int i = 0; i < 6; ++i) {
    EXPECT_GT(a.sigma[i], 0) << i;
    EXPECT_LT(a.sigma[i], i < 3 ? 0.5 * kDeg : 0.03) << i;
  }
}

FloorLimits TestFloor() {
  absl::StatusOr<FloorLimits> f =
      ParseFloorLimits(R"({"format": "linecal.floor", "version": 1, "name": "t",
      "usable_area_m": [[-2, -5], [12, -5], [12, 5], [-2, 5]],
      "height_limits_m": [0, 2.5],
      "walls": [{"id": "w", "from_m": [12, -5], "to_m": [12, 5]}],
      "keep_out": [{"id": "aligner", "polygon_m": [[5, 1], [6, 1], [6, 3], [5, 3]]}]})",
                       "floor.json");
  EXPECT_TRUE(f.ok()) << f.status();
  return f.ok() ? *f : FloorLimits{};
}

TEST(AssessFloor, KeepOutUsableAreaAndHeight) {
  const FloorLimits floor = TestFloor();
  const SensorModel s = Sensor(SensorKind::kCamera, "pinhole", {0, 0, 1.2}, {"b"});
  PlannerOptions o;
  o.min_feature_px = 1;  // the floor checks alone
  EXPECT_EQ(AssessOrDie(s, Layout(BoardJson("b", "aruco", 6, 0, 1.2, 0)), &floor, false, o).reasons,
            Reasons{});
  // The 1.1 m wide board at y = 1.3 reaches into the aligner zone (y 1..3, x 5..6).
  const SensorAssessment in_zone =
      AssessOrDie(s, Layout(BoardJson("b", "aruco", 5.5, 0.8, 1.2, 0)), &floor, false, o);
  EXPECT_EQ(in_zone.reasons, Reasons{"in_keep_out"});
  EXPECT_NE(in_zone.targets[0].detail.find("'aligner'"), std::string::npos);
  // Through the wall at x = 12 (turned, so that its footprint crosses it).
  EXPECT_EQ(
      AssessOrDie(s, Layout(BoardJson("b", "aruco", 12, 0, 1.2, 60)), &floor, false, o).reasons,
      Reasons{"outside_usable_area"});
  // Its top at 2.55 m, above the 2.5 m limit.
  EXPECT_EQ(AssessOrDie(s, Layout(BoardJson("b", "aruco", 9, 0, 2.0, 0)), &floor, false, o).reasons,
            Reasons{"outside_height_limits"});
}

TEST(FloorGeometry, PolygonsAndSegments) {
  const FloorPolygon square = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  EXPECT_TRUE(PointInPolygon({0.5, 0.5}, square));
  EXPECT_FALSE(PointInPolygon({1.5, 0.5}, square));
  EXPECT_TRUE(SegmentsIntersect({0, 0}, {1, 1}, {0, 1}, {1, 0}));
  EXPECT_FALSE(SegmentsIntersect({0, 0}, {1, 0}, {0, 1}, {1, 1}));
  EXPECT_TRUE(SegmentsIntersect({0, 0}, {1, 0}, {1, 0}, {2, 5}));  // touching
  EXPECT_TRUE(PolygonsOverlap(square, {{0.5, 0.5}, {3, 3}}));      // a segment poking in
  EXPECT_TRUE(PolygonsOverlap(square, {{0.2, 0.2}, {0.4, 0.2}, {0.3, 0.4}}));  // inside
  EXPECT_FALSE(PolygonsOverlap(square, {{2, 2}, {3, 2}, {3, 3}}));
}

TEST(AssessRadar, FieldOfViewAndLineOfSight) {
  // ESR: ±45°, 60 m.
  const SensorModel s = Sensor(SensorKind::kRadar, "esr", {0, 0, 0.5}, {"a", "b", "c"});
  const std::string reflectors =
      R"({"id": "a", "xyz_m": [10, -3, 0.5]}, {"id": "b", "xyz_m": [10, 3, 0.5]},
                                    {"id": "c", "xyz_m": [5, 8, 0.5]})";
  const SensorAssessment a = AssessOrDie(s, Layout("", reflectors), nullptr, true);
  EXPECT_EQ(a.reasons, Reasons{"reflector_outside_fov"});  // c at 58°
  EXPECT_TRUE(a.sigma_valid);                              // a and b still give a yaw
  EXPECT_TRUE(a.observed[0]);
  EXPECT_FALSE(a.observed[1]);
  const SensorAssessment blocked = AssessOrDie(
      s, Layout(BoardJson("wall", "aruco", 5, 1.5, 0.6, 0), reflectors), nullptr, false);
  EXPECT_EQ(blocked.reasons, (Reasons{"occluded_by_board", "reflector_outside_fov"}));
  EXPECT_EQ(blocked.targets[1].reasons, Reasons{"occluded_by_board"});
}

TEST(ValidRegion, AroundThePlannedPoseAndBoundedByFeatureSize) {
  // Geometry alone bounds this region: 5 px corners make the uncertainty bar irrelevant
  // (a 100x looser fraction), and the squares reach 15 px at 10 m.
  const SensorModel s = Sensor(SensorKind::kCamera, "pinhole", {0, 0, 1.2}, {"b"});
  const StationLayout layout = Layout(BoardJson("b", "chessboard", 6, 0, 1.2, 0));
  PlannerOptions o;
  o.max_sigma_fraction_of_tolerance = 10;
  absl::StatusOr<ValidRegion> r = ValidRegionOf(s, "b", layout, nullptr, o);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_LE(r->distance_min_m, 6.0);
  EXPECT_NEAR(r->distance_max_m, 10.0, 0.25 + 1e-9);  // 0.25 m steps; 15 px at exactly 10 m
  // Nearer than 1.26 m its outer corners (1.2 m off centre) image beyond 951.5 px from the
  // centre, out of the image with the 8 px margin; the steps from 6 m stop at 1.5 m.
  EXPECT_GE(r->distance_min_m, 1.26);
  EXPECT_LE(r->distance_min_m, 1.26 + 0.25);
  EXPECT_LT(r->lateral_min_m, 0);
  EXPECT_GT(r->lateral_max_m, 0);
  EXPECT_TRUE(PointInPolygon({6, 0}, r->polygon));
  EXPECT_FALSE(PointInPolygon({12, 0}, r->polygon));
  EXPECT_FALSE(ValidRegionOf(s, "none", layout, nullptr, o).ok());
}

TEST(FloorLimitsFile, ReferenceFloorAndErrorsNamingTheField) {
  absl::StatusOr<FloorLimits> f =
      ReadFloorLimits(std::string(LINECAL_SOURCE_DIR) + "/deploy/stations/reference-floor.json");
  ASSERT_TRUE(f.ok()) << f.status();
  EXPECT_EQ(f->name, "reference");
  EXPECT_EQ(f->walls.size(), 4u);
  EXPECT_EQ(f->keep_outs.size(), 5u);
  EXPECT_EQ(f->keep_outs[0].id, "car_path");
  EXPECT_DOUBLE_EQ(f->max_height_m, 3.0);
  EXPECT_TRUE(PointInPolygon({0, 0}, f->keep_outs[0].polygon));  // the car stands in its path

  const auto error = [](const std::string& body) {
    absl::StatusOr<FloorLimits> r = ParseFloorLimits(
        R"({"format": "linecal.floor", "version": 1, "name": "t", )" + body + "}", "floor.json");
    return r.ok() ? std::string("ok") : std::string(r.status().message());
  };
  EXPECT_EQ(error(R"("usable_area_m": [[0, 0], [1, 0], [1, 1]])"), "ok");
  EXPECT_NE(error(R"("usable_area_m": [[0, 0], [1, 0]])").find("floor.json: usable_area_m"),
            std::string::npos);
  EXPECT_NE(error(R"("usable_area_m": [[0, 0], [1, 0], [1]])").find("usable_area_m[2]"),
            std::string::npos);
  EXPECT_NE(error(R"("usable_area_m": [[0, 0], [1, 0], [1, 1]], "height_limits_m": [2, 1])")
                .find("height_limits_m"),
            std::string::npos);
  EXPECT_NE(error(R"("usable_area_m": [[0, 0], [1, 0], [1, 1]], "keep_out": [{"id": "k"}])")
                .find("keep_out[0].polygon_m"),
            std::string::npos);
  EXPECT_NE(
      error(
          R"("usable_area_m": [[0, 0], [1, 0], [1, 1]], "walls": [{"id": "w", "from_m": [0, 0], "to_m": [0, 0]}])")
          .find("walls[0].to_m"),
      std::string::npos);
  EXPECT_NE(error(R"("usable_area_m": [[0, 0], [1, 0], [1, 1]], "keepout": [])").find("keepout"),
            std::string::npos);
}

}  // namespace
}  // namespace linecal

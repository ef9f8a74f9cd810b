// Station layout, car model, aligner and pose files: the shipped reference files load, and
// every kind of broken file is rejected with a message that names the file and the field.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>

#include "station/model/aligner.h"
#include "station/model/car_model.h"
#include "station/model/pose_json.h"
#include "station/model/station_layout.h"

namespace linecal {
namespace {

const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
constexpr double kDeg = std::numbers::pi / 180.0;

TEST(StationLayoutTest, ReferenceStationLoads) {
  absl::StatusOr<StationLayout> s = ReadStationLayout(kDeploy + "/stations/reference.json");
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->name, "reference");
  EXPECT_EQ(s->boards.size(), 19u);
  EXPECT_EQ(s->reflectors.size(), 12u);
  const StationBoard* chess = s->FindBoard("front_chessboard");
  ASSERT_NE(chess, nullptr);
  EXPECT_EQ(chess->params.type, BoardType::kChessboard);
  // At zero angles a board faces the car: its normal (z) points along -x_station.
  const Eigen::Vector3d n_station = chess->T_station_board.rotation() * Eigen::Vector3d::UnitZ();
  EXPECT_TRUE(n_station.isApprox(-Eigen::Vector3d::UnitX(), 1e-12));
  // Its top (y) is up.
  EXPECT_TRUE((chess->T_station_board.rotation() * Eigen::Vector3d::UnitY())
                  .isApprox(Eigen::Vector3d::UnitZ(), 1e-12));
  // A floor board with pitch 90 faces up.
  const StationBoard* floor = s->FindBoard("left_floor_grid");
  ASSERT_NE(floor, nullptr);
  EXPECT_TRUE((floor->T_station_board.rotation() * Eigen::Vector3d::UnitZ())
                  .isApprox(Eigen::Vector3d::UnitZ(), 1e-12));
}

TEST(CarModelTest, ReferenceCarLoadsAndMatchesStation) {
  absl::StatusOr<CarModel> car = ReadCarModel(kDeploy + "/cars/reference.json");
  ASSERT_TRUE(car.ok()) << car.status();
  EXPECT_EQ(car->sensors.size(), 10u);
  const SensorModel* front = car->FindSensor("front_camera");
  ASSERT_NE(front, nullptr);
  ASSERT_TRUE(front->intrinsics.has_value());
  EXPECT_EQ(front->intrinsics->width, 1920);
  EXPECT_EQ(front->intrinsics->type, CameraModelType::kPinhole);
  // Nominal pitch 1.5 degrees down: the optical axis points forward and slightly down.
  const Eigen::Vector3d axis = front->T_car_sensor_nominal.rotation() * Eigen::Vector3d::UnitZ();
  EXPECT_NEAR(std::atan2(-axis.z(), axis.x()), 1.5 * kDeg, 1e-12);
  const SensorModel* roof = car->FindSensor("roof_lidar");
  ASSERT_NE(roof, nullptr);
  EXPECT_NE(roof->angles_file.find("Pandar64.csv"), std::string::npos);
  absl::StatusOr<StationLayout> s = ReadStationLayout(kDeploy + "/stations/reference.json");
  ASSERT_TRUE(s.ok());
  EXPECT_TRUE(CheckTargetsExist(*car, *s).ok());
}

TEST(CarModelTest, JsonRoundTripKeepsEverything) {
  absl::StatusOr<CarModel> car = ReadCarModel(kDeploy + "/cars/reference.json");
  ASSERT_TRUE(car.ok());
  absl::StatusOr<CarModel> again =
      ParseCarModel(CarModelToJson(*car).dump(), kDeploy + "/cars/copy.json");
  ASSERT_TRUE(again.ok()) << again.status();
  ASSERT_EQ(again->sensors.size(), car->sensors.size());
  for (size_t i = 0; i < car->sensors.size(); ++i) {
    EXPECT_EQ(again->sensors[i].name, car->sensors[i].name);
    EXPECT_TRUE(again->sensors[i].T_car_sensor_nominal.Matrix().isApprox(
        car->sensors[i].T_car_sensor_nominal.Matrix(), 1e-15));
    EXPECT_DOUBLE_EQ(again->sensors[i].tolerance.yaw_rad, car->sensors[i].tolerance.yaw_rad);
  }
}

TEST(StationLayoutTest, JsonRoundTripKeepsPoses) {
  absl::StatusOr<StationLayout> s = ReadStationLayout(kDeploy + "/stations/reference.json");
  ASSERT_TRUE(s.ok());
  absl::StatusOr<StationLayout> again = ParseStationLayout(StationLayoutToJson(*s).dump(), "copy");
  ASSERT_TRUE(again.ok()) << again.status();
  ASSERT_EQ(again->boards.size(), s->boards.size());
  for (size_t i = 0; i < s->boards.size(); ++i) {
    EXPECT_EQ(again->boards[i].id, s->boards[i].id);
    EXPECT_TRUE(again->boards[i].T_station_board.Matrix().isApprox(
        s->boards[i].T_station_board.Matrix(), 1e-15));
  }
}

TEST(StationLayoutTest, CircleGridParametersRoundTrip) {
  const std::string json = R"({"format": "linecal.station", "version": 1, "name": "x", "boards": [
      {"id": "g", "type": "circle_grid", "cols": 4, "rows": 11, "spacing_m": 0.02,
       "diameter_m": 0.015, "asymmetric": true, "light_circles": true,
       "pose": {"xyz_m": [1, 0, 1], "ypr_deg": [0, 0, 0]}}]})";
  absl::StatusOr<StationLayout> s = ParseStationLayout(json, "st.json");
  ASSERT_TRUE(s.ok()) << s.status();
  absl::StatusOr<StationLayout> again = ParseStationLayout(StationLayoutToJson(*s).dump(), "copy");
  ASSERT_TRUE(again.ok()) << again.status();
  const BoardParams& p = again->boards.at(0).params;
  EXPECT_EQ(p.type, BoardType::kCircleGrid);
  EXPECT_EQ(p.cols, 4);
  EXPECT_EQ(p.rows, 11);
  EXPECT_EQ(p.spacing_m, 0.02);
  EXPECT_EQ(p.diameter_m, 0.015);
  EXPECT_TRUE(p.asymmetric);
  EXPECT_TRUE(p.light_circles);
  EXPECT_EQ(again->boards.at(0).board.features().size(), 44u);
}

TEST(StationLayoutTest, HexagonalCircleGridRoundTrip) {
  // BoofCV's hexagonal grid of the corpus: 24 rows on 28 zig-zag columns, 14 circles a row.
  const std::string json = R"({"format": "linecal.station", "version": 1, "name": "x", "boards": [
      {"id": "h", "type": "circle_grid", "cols": 28, "rows": 24, "spacing_m": 0.012,
       "diameter_m": 0.01, "hexagonal": true,
       "pose": {"xyz_m": [1, 0, 1], "ypr_deg": [0, 0, 0]}}]})";
  absl::StatusOr<StationLayout> s = ParseStationLayout(json, "st.json");
  ASSERT_TRUE(s.ok()) << s.status();
  const nlohmann::json written = StationLayoutToJson(*s);
  EXPECT_TRUE(written.at("boards").at(0).at("hexagonal").get<bool>());
  absl::StatusOr<StationLayout> again = ParseStationLayout(written.dump(), "copy");
  ASSERT_TRUE(again.ok()) << again.status();
  const BoardParams& p = again->boards.at(0).params;
  EXPECT_TRUE(p.hexagonal);
  EXPECT_FALSE(p.asymmetric);
  EXPECT_EQ(p.cols, 28);
  EXPECT_EQ(p.rows, 24);
  EXPECT_EQ(again->boards.at(0).board.features().size(), 336u);
}

TEST(StationLayoutTest, SquareGridParametersRoundTrip) {
  const std::string json = R"({"format": "linecal.station", "version": 1, "name": "x", "boards": [
      {"id": "g", "type": "square_grid", "cols": 3, "rows": 4, "square_m": 0.03, "gap_m": 0.02,
       "pose": {"xyz_m": [1, 0, 1], "ypr_deg": [0, 0, 0]}}]})";
  absl::StatusOr<StationLayout> s = ParseStationLayout(json, "st.json");
  ASSERT_TRUE(s.ok()) << s.status();
  absl::StatusOr<StationLayout> again = ParseStationLayout(StationLayoutToJson(*s).dump(), "copy");
  ASSERT_TRUE(again.ok()) << again.status();
  const BoardParams& p = again->boards.at(0).params;
  EXPECT_EQ(p.type, BoardType::kSquareGrid);
  EXPECT_EQ(p.cols, 3);
  EXPECT_EQ(p.rows, 4);
  EXPECT_EQ(p.square_m, 0.03);
  EXPECT_EQ(p.gap_m, 0.02);
  EXPECT_EQ(again->boards.at(0).board.features().size(), 48u);
}

TEST(StationLayoutTest, CharucoParametersRoundTrip) {
  const std::string json = R"({"format": "linecal.station", "version": 1, "name": "x", "boards": [
      {"id": "c", "type": "charuco", "cols": 5, "rows": 4, "square_m": 0.03, "marker_m": 0.022,
       "legacy_pattern": true, "dictionary": "DICT_5X5_1000",
       "pose": {"xyz_m": [1, 0, 1], "ypr_deg": [0, 0, 0]}}]})";
  absl::StatusOr<StationLayout> s = ParseStationLayout(json, "st.json");
  ASSERT_TRUE(s.ok()) << s.status();
  absl::StatusOr<StationLayout> again = ParseStationLayout(StationLayoutToJson(*s).dump(), "copy");
  ASSERT_TRUE(again.ok()) << again.status();
  const BoardParams& p = again->boards.at(0).params;
  EXPECT_EQ(p.type, BoardType::kCharuco);
  EXPECT_EQ(p.cols, 5);
  EXPECT_EQ(p.rows, 4);
  EXPECT_EQ(p.square_m, 0.03);
  EXPECT_EQ(p.marker_m, 0.022);
  EXPECT_TRUE(p.charuco_legacy);
  EXPECT_EQ(p.charuco_dictionary, ArucoDictionary::k5x5_1000);
  EXPECT_EQ(again->boards.at(0).board.features().size(), 12u);
  // An unknown dictionary, or one with fewer markers than the board's white squares, is
  // refused naming the key.
  for (const auto& [dictionary, message] :
       {std::pair{"\"DICT_5X5_60\"", "unknown ArUco dictionary 'DICT_5X5_60'"},
        std::pair{"7", "dictionary"}}) {
    std::string bad = json;
    bad.replace(bad.find("\"DICT_5X5_1000\""), 15, dictionary);
    const absl::StatusOr<StationLayout> refused = ParseStationLayout(bad, "st.json");
    ASSERT_FALSE(refused.ok());
    EXPECT_NE(refused.status().message().find(message), std::string::npos) << refused.status();
  }
  std::string too_many = json;
  too_many.replace(too_many.find("\"cols\": 5"), 9, "\"cols\": 15");
  too_many.replace(too_many.find("\"rows\": 4"), 9, "\"rows\": 14");
  too_many.replace(too_many.find("DICT_5X5_1000"), 13, "DICT_5X5_100");
  const absl::StatusOr<StationLayout> refused = ParseStationLayout(too_many, "st.json");
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("dictionary"), std::string::npos) << refused.status();
}

TEST(StationLayoutTest, AprilGridParametersRoundTrip) {
  const std::string json = R"({"format": "linecal.station", "version": 1, "name": "x", "boards": [
      {"id": "a", "type": "apriltag", "scale": 0.5, "tag_cols": 4, "tag_rows": 3,
       "tag_spacing": 0.25, "start_id": 100, "border_bits": 1,
       "pose": {"xyz_m": [1, 0, 1], "ypr_deg": [0, 0, 0]}}]})";
  absl::StatusOr<StationLayout> s = ParseStationLayout(json, "st.json");
  ASSERT_TRUE(s.ok()) << s.status();
  absl::StatusOr<StationLayout> again = ParseStationLayout(StationLayoutToJson(*s).dump(), "copy");
  ASSERT_TRUE(again.ok()) << again.status();
  const BoardParams& p = again->boards.at(0).params;
  EXPECT_EQ(p.type, BoardType::kApriltag);
  EXPECT_EQ(p.apriltag_cols, 4);
  EXPECT_EQ(p.apriltag_rows, 3);
  EXPECT_EQ(p.apriltag_spacing, 0.25);
  EXPECT_EQ(p.apriltag_start_id, 100);
  EXPECT_EQ(p.apriltag_border_bits, 1);
  const std::vector<BoardFeature>& f = again->boards.at(0).board.features();
  ASSERT_EQ(f.size(), 48u);
  EXPECT_EQ(f.front().marker, 100);
  EXPECT_EQ(f.back().marker, 111);
}

// `allow_partial` is off unless a board says so, survives a round trip, and is refused for a
// board without ids, naming the key and the board type.
TEST(StationLayoutTest, AllowPartialOnlyForBoardsWithIds) {
  const std::string json = R"({"format": "linecal.station", "version": 1, "name": "x", "boards": [
      {"id": "v", "type": "vertical", "allow_partial": true,
       "pose": {"xyz_m": [1, 0, 1], "ypr_deg": [0, 0, 0]}},
      {"id": "a", "type": "aruco", "pose": {"xyz_m": [1, 1, 1], "ypr_deg": [0, 0, 0]}}]})";
  absl::StatusOr<StationLayout> s = ParseStationLayout(json, "st.json");
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_TRUE(s->boards.at(0).allow_partial);
  EXPECT_FALSE(s->boards.at(1).allow_partial);
  const nlohmann::json written = StationLayoutToJson(*s);
  EXPECT_TRUE(written.at("boards").at(0).at("allow_partial").get<bool>());
  EXPECT_FALSE(written.at("boards").at(1).contains("allow_partial"));
  absl::StatusOr<StationLayout> again = ParseStationLayout(written.dump(), "copy");
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_TRUE(again->boards.at(0).allow_partial);
  EXPECT_FALSE(again->boards.at(1).allow_partial);
  for (const char* type : {"chessboard", "circle", "checker", "circle_grid", "square_grid"}) {
    SCOPED_TRACE(type);
    std::string bad = json;
    bad.replace(bad.find("\"vertical\""), 10, std::string("\"") + type + "\"");
    const absl::StatusOr<StationLayout> refused = ParseStationLayout(bad, "st.json");
    ASSERT_FALSE(refused.ok());
    EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(refused.status().message().find(std::string("st.json: boards[0].allow_partial: a '") +
                                              type + "' board has no ids"),
              std::string::npos)
        << refused.status();
  }
  for (BoardType t : kAllBoardTypes) {
    const bool with_ids = t == BoardType::kVertical || t == BoardType::kAruco ||
                          t == BoardType::kApriltag || t == BoardType::kRoundHole ||
                          t == BoardType::kCharuco;
    EXPECT_EQ(BoardAllowsPartial(t), with_ids) << BoardTypeName(t);
  }
}

// Each broken document must fail with a message containing `expected`.
struct BrokenCase {
  const char* name;
  const char* json;
  const char* expected;
};

class BrokenStationTest : public ::testing::TestWithParam<BrokenCase> {};

TEST_P(BrokenStationTest, RejectedNamingTheField) {
  absl::StatusOr<StationLayout> s = ParseStationLayout(GetParam().json, "st.json");
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(std::string(s.status().message()).find(GetParam().expected), std::string::npos)
      << s.status().message();
}

#define HDR R"("format": "linecal.station", "version": 1, "name": "x")"
#define POSE R"("pose": {"xyz_m": [1, 0, 1], "ypr_deg": [0, 0, 0]})"

INSTANTIATE_TEST_SUITE_P(
    Cases, BrokenStationTest,
    ::testing::Values(
        BrokenCase{"syntax", R"({"format": )", "st.json:1:"},
        BrokenCase{"wrong_format", R"({"format": "linecal.car", "version": 1, "name": "x"})",
                   "st.json: format: expected 'linecal.station'"},
        BrokenCase{"future_version", R"({"format": "linecal.station", "version": 9, "name": "x"})",
                   "version: unsupported version 9"},
        BrokenCase{"missing_name", R"({"format": "linecal.station", "version": 1})",
                   "st.json: name: missing"},
        BrokenCase{"unknown_board",
                   "{" HDR R"(, "boards": [{"id": "a", "type": "chess", )" POSE "}]}",
                   "boards[0].type: unknown board type 'chess'"},
        BrokenCase{"bad_scale",
                   "{" HDR R"(, "boards": [{"id": "a", "type": "aruco", "scale": -1, )" POSE "}]}",
                   "boards[0].scale: bad_scale"},
        BrokenCase{"wrong_type",
                   "{" HDR R"(, "boards": [{"id": "a", "type": "aruco", "scale": "big", )" POSE
                   "}]}",
                   "boards[0].scale: expected a number"},
        BrokenCase{"bad_diameter",
                   "{" HDR
                   R"(, "boards": [{"id": "a", "type": "circle_grid", "diameter_m": 0.03, )" POSE
                   "}]}",
                   "boards[0].diameter_m: bad_diameter"},
        BrokenCase{"bad_layout",
                   "{" HDR R"(, "boards": [{"id": "a", "type": "circle_grid", )"
                   R"("hexagonal": true, "asymmetric": true, )" POSE "}]}",
                   "boards[0].hexagonal: bad_layout"},
        BrokenCase{"bad_gap",
                   "{" HDR R"(, "boards": [{"id": "a", "type": "square_grid", "gap_m": 0, )" POSE
                   "}]}",
                   "boards[0].gap_m: bad_gap"},
        BrokenCase{"bad_marker",
                   "{" HDR R"(, "boards": [{"id": "a", "type": "charuco", "marker_m": 0.03, )" POSE
                   "}]}",
                   "boards[0].marker_m: bad_marker"},
        BrokenCase{"bad_tag_grid",
                   "{" HDR R"(, "boards": [{"id": "a", "type": "apriltag", "tag_cols": 0, )" POSE
                   "}]}",
                   "boards[0].tag_cols: bad_tag_grid"},
        BrokenCase{"bad_start_id",
                   "{" HDR R"(, "boards": [{"id": "a", "type": "apriltag", "start_id": 560, )" POSE
                   "}]}",
                   "boards[0].start_id: bad_start_id"},
        BrokenCase{"missing_pose", "{" HDR R"(, "boards": [{"id": "a", "type": "aruco"}]})",
                   "boards[0].pose: missing"},
        BrokenCase{
            "short_xyz",
            "{" HDR
            R"(, "boards": [{"id": "a", "type": "aruco", "pose": {"xyz_m": [1, 2], "ypr_deg": [0, 0, 0]}}]})",
            "boards[0].pose.xyz_m: expected 3 numbers, got 2"},
        BrokenCase{"typo_field",
                   "{" HDR R"(, "boards": [{"id": "a", "type": "aruco", "scael": 2, )" POSE "}]}",
                   "boards[0].scael: unknown field"},
        BrokenCase{
            "not_a_rotation",
            "{" HDR
            R"(, "boards": [{"id": "a", "type": "aruco", "pose": {"matrix": [2,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}}]})",
            "boards[0].pose.matrix: rotation part is not a rotation"},
        BrokenCase{"allow_partial_not_bool",
                   "{" HDR R"(, "boards": [{"id": "a", "type": "aruco", "allow_partial": 1, )" POSE
                   "}]}",
                   "boards[0].allow_partial: expected"},
        BrokenCase{"duplicate_id",
                   "{" HDR R"(, "boards": [{"id": "a", "type": "aruco", )" POSE
                   R"(}, {"id": "a", "type": "circle", )" POSE "}]}",
                   "boards[1].id: duplicate id 'a'"},
        BrokenCase{"bad_rcs",
                   "{" HDR R"(, "reflectors": [{"id": "r", "xyz_m": [1, 2, 3], "rcs_dbsm": 500}]})",
                   "reflectors[0].rcs_dbsm: must be within -20..60"}),
    [](const auto& info) { return std::string(info.param.name); });

class BrokenCarTest : public ::testing::TestWithParam<BrokenCase> {};

TEST_P(BrokenCarTest, RejectedNamingTheField) {
  absl::StatusOr<CarModel> c = ParseCarModel(GetParam().json, "car.json");
  ASSERT_FALSE(c.ok());
  EXPECT_NE(std::string(c.status().message()).find(GetParam().expected), std::string::npos)
      << c.status().message();
}

#define CAR R"("format": "linecal.car", "version": 1, "id": "c", "sensors": )"
#define TOL \
  R"("nominal": {"xyz_m": [1, 0, 1], "ypr_deg": [0, 0, 0]}, "tolerance": {"ypr_deg": [1, 1, 1], "xyz_m": [0.1, 0.1, 0.1]}, "targets": ["t"])"
#define K \
  R"("intrinsics": {"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240})"

INSTANTIATE_TEST_SUITE_P(
    Cases, BrokenCarTest,
    ::testing::Values(
        BrokenCase{"bad_kind",
                   "{" CAR R"([{"name": "s", "kind": "sonar", "model": "x", )" TOL "}]}",
                   "sensors[0].kind: must be camera, lidar or radar, got 'sonar'"},
        BrokenCase{"bad_lidar_model",
                   "{" CAR R"([{"name": "s", "kind": "lidar", "model": "hdl64", )" TOL "}]}",
                   "sensors[0].model: lidar model must be"},
        BrokenCase{"missing_intrinsics",
                   "{" CAR R"([{"name": "s", "kind": "camera", "model": "pinhole", )" TOL "}]}",
                   "sensors[0].intrinsics: missing"},
        BrokenCase{
            "negative_focal",
            "{" CAR
            R"([{"name": "s", "kind": "camera", "model": "pinhole", "intrinsics": {"width": 640, "height": 480, "fx": -5, "fy": 500, "cx": 320, "cy": 240}, )" TOL
            "}]}",
            "sensors[0].intrinsics: fx"},
        BrokenCase{
            "huge_image",
            "{" CAR
            R"([{"name": "s", "kind": "camera", "model": "pinhole", "intrinsics": {"width": 20000, "height": 480, "fx": 5, "fy": 500, "cx": 320, "cy": 240}, )" TOL
            "}]}",
            "sensors[0].intrinsics.width: must be within 1..16384, got 20000"},
        BrokenCase{
            "fisheye_with_p1",
            "{" CAR
            R"([{"name": "s", "kind": "camera", "model": "fisheye", "intrinsics": {"width": 640, "height": 480, "fx": 300, "fy": 300, "cx": 320, "cy": 240, "p1": 0.1}, )" TOL
            "}]}",
            "sensors[0].intrinsics.p1: unknown field"},
        BrokenCase{
            "zero_tolerance",
            "{" CAR
            R"([{"name": "s", "kind": "radar", "model": "esr", "nominal": {"xyz_m": [1, 0, 1], "ypr_deg": [0, 0, 0]}, "tolerance": {"ypr_deg": [0, 1, 1], "xyz_m": [0.1, 0.1, 0.1]}, "targets": ["t"]}]})",
            "sensors[0].tolerance.ypr_deg[0]: must be within (0, 45], got 0"},
        BrokenCase{
            "no_targets",
            "{" CAR
            R"([{"name": "s", "kind": "radar", "model": "esr", "nominal": {"xyz_m": [1, 0, 1], "ypr_deg": [0, 0, 0]}, "tolerance": {"ypr_deg": [1, 1, 1], "xyz_m": [0.1, 0.1, 0.1]}, "targets": []}]})",
            "sensors[0].targets: a sensor needs at least one target"},
        BrokenCase{
            "radar_id",
            "{" CAR
            R"([{"name": "s", "kind": "radar", "model": "ars408", "radar_sensor_id": 9, )" TOL
            "}]}",
            "sensors[0].radar_sensor_id: must be within 0..7, got 9"},
        BrokenCase{"intrinsics_on_radar",
                   "{" CAR R"([{"name": "s", "kind": "radar", "model": "esr", )" K ", " TOL "}]}",
                   "sensors[0].intrinsics: only cameras have intrinsics"},
        BrokenCase{
            "missing_angles_file",
            "{" CAR
            R"([{"name": "s", "kind": "lidar", "model": "pandar64", "angles_file": "nope.csv", )" TOL
            "}]}",
            "sensors[0].angles_file: no such file"},
        BrokenCase{"duplicate_name",
                   "{" CAR R"([{"name": "s", "kind": "radar", "model": "esr", )" TOL
                   R"(}, {"name": "s", "kind": "radar", "model": "esr", )" TOL "}]}",
                   "sensors[1].name: duplicate sensor name 's'"}),
    [](const auto& info) { return std::string(info.param.name); });

TEST(CarModelTest, MissingTargetIsNamed) {
  absl::StatusOr<CarModel> car = ParseCarModel(
      "{" CAR R"([{"name": "s", "kind": "radar", "model": "esr", )" TOL "}]}", "car.json");
  ASSERT_TRUE(car.ok()) << car.status();
  StationLayout layout;
  layout.name = "st";
  const absl::Status s = CheckTargetsExist(*car, layout);
  EXPECT_EQ(s.message(), "station 'st' has no reflector 't' (sensor 's' of car 'c' targets it)");
}

TEST(AlignerTest, TransformPutsCarOnTheFloor) {
  absl::StatusOr<JsonDocument> doc = JsonDocument::FromText(
      R"({"a": {"longitudinal_offset_m": 0.05, "lateral_offset_m": -0.02, "thrust_angle_deg": 0.3}})",
      "req");
  ASSERT_TRUE(doc.ok());
  absl::StatusOr<AlignerMeasurement> a = ReadAligner(*doc->Root(), "a");
  ASSERT_TRUE(a.ok()) << a.status();
  const Rigid3d t = a->T_station_car();
  // The car origin lands at the offsets, on the floor.
  EXPECT_TRUE(t.translation().isApprox(Eigen::Vector3d(0.05, -0.02, 0.0)));
  // Its x axis is turned by the thrust angle about z.
  const Eigen::Vector3d x = t.rotation() * Eigen::Vector3d::UnitX();
  EXPECT_NEAR(std::atan2(x.y(), x.x()), 0.3 * kDeg, 1e-15);
  EXPECT_NEAR(x.z(), 0.0, 1e-15);
}

TEST(AlignerTest, ImplausibleValuesAreRejected) {
  absl::StatusOr<JsonDocument> doc = JsonDocument::FromText(
      R"({"a": {"longitudinal_offset_m": 50, "lateral_offset_m": 0, "thrust_angle_deg": 0}})",
      "req");
  ASSERT_TRUE(doc.ok());
  absl::StatusOr<AlignerMeasurement> a = ReadAligner(*doc->Root(), "a");
  ASSERT_FALSE(a.ok());
  EXPECT_EQ(a.status().message(), "req: a.longitudinal_offset_m: must be within +-1 m, got 50");
}

TEST(PoseJsonTest, AnglesAndMatrixFormsAgree) {
  const Rigid3d pose(MountingRotation({0.1, -0.2, 0.05}, CameraBaseRotation()),
                     Eigen::Vector3d(1, 2, 3));
  const nlohmann::json j = {{"p", PoseToJson(pose, CameraBaseRotation())}};
  // Drop the matrix to read the angle form alone.
  nlohmann::json angles_only = j;
  angles_only["p"].erase("matrix");
  for (const nlohmann::json& doc_json : {j, angles_only}) {
    absl::StatusOr<JsonDocument> doc = JsonDocument::FromText(doc_json.dump(), "p");
    ASSERT_TRUE(doc.ok());
    absl::StatusOr<Rigid3d> back = ReadPose(*doc->Root(), "p", CameraBaseRotation());
    ASSERT_TRUE(back.ok()) << back.status();
    EXPECT_TRUE(back->Matrix().isApprox(pose.Matrix(), 1e-14));
  }
}

}  // namespace
}  // namespace linecal

#pragma once
// Cycles for the plant database's tests (tests/daemon/plant, tests/tools/cmd_plant_test.cc):
// one cycle with every field set, and a small plant whose first-pass yield is worked out by
// hand below.

#include <cstdint>
#include <string>
#include <vector>

#include "daemon/plant/plant_cycle.h"

namespace linecal::testing_support {

// 2026-11-02T08:00:00Z: the data set's --since.
inline constexpr int64_t kPlantT0Ns = 1793606400LL * 1000000000LL;
inline constexpr int64_t kHourNs = 3600LL * 1000000000LL;

// A sensor result with every field set (values that need all 17 digits, optional ones set).
inline StoredSensorResult FullSensor(const std::string& name, const std::string& kind,
                                     Verdict verdict, const std::string& reason) {
  StoredSensorResult s;
  s.sensor = name;
  s.kind = ParseSensorKind(kind).value();  // the test names a kind by its word
  s.verdict = verdict;
  s.reason = reason;
  s.message = reason.empty() ? "" : "it's \"out\", see the ranging check";
  for (int i = 0; i < 16; ++i) s.T_car_sensor.push_back(i / 3.0 - 1e-300 * i);
  s.measured = {0.1, -1.25, 2.0 / 3.0, 1.5e-9, -0.3, 1e300};
  s.deviation = {0.2, 0.1 + 0.2, -0.0, 4.0, 5.5, -6.25};
  s.sigma = {0.01, 0.02, 0.03, 0.001, 0.002, 0.003};
  s.residual_rms = 0.123456789012345678;
  s.features_used = 88;
  if (kind == "camera") {
    s.vanishing_point_u_px = 960.5;
    s.vanishing_point_v_px = -1.0 / 7.0;
    s.ground_homography = {1, 0, 0.5, 0, 1, -0.25, 1e-5, 2e-5, 1};
    s.ranging_json = R"({"board_m": 5.0, "ok": true, "note": "naïve"})";
  }
  if (kind != "radar") {  // by board id, as the station's store keeps them
    s.boards = {{"board_a", 3, 2, 1, 1.0 / 3.0}, {"board_b", 3, 0, 0, std::nullopt}};
  }
  s.elapsed_ns = 1234567891;
  return s;
}

// An ended cycle at `started_ns` (it ends 90 s later) with the given sensors and two events.
inline PlantCycle MakePlantCycle(int64_t id, const std::string& vin, const std::string& model,
                                 int64_t started_ns, std::vector<StoredSensorResult> sensors) {
  PlantCycle p;
  StoredCycle& c = p.cycle;
  c.id = id;
  c.vin = vin;
  c.car_model_id = model;
  c.state = CycleState::kDone;
  c.verdict = Verdict::kPass;
  for (const StoredSensorResult& s : sensors) {
    if (s.verdict != Verdict::kPass) {
      c.verdict = Verdict::kFail;
      if (c.reason.empty()) c.reason = s.reason;
    }
  }
  c.started_ns = started_ns;
  c.ended_ns = started_ns + 90LL * 1000000000LL + 7;
  c.request_json = "{\"vin\": \"" + vin + "\", \"aligner\": {\"ok\": true}}";
  c.capture_path = "captures/" + vin + "/" + std::to_string(id);
  c.sensors = std::move(sensors);
  p.events = {{id, 0, started_ns, EventType::kStarted, "", "aligner ok", std::nullopt},
              {id, 1, c.ended_ns, EventType::kCycleEnded, "", c.reason, c.verdict}};
  return p;
}

struct StationBatch {
  std::string station_id;
  std::vector<PlantCycle> cycles;
};

// Two stations, two car models, a camera and a LiDAR. Since kPlantT0Ns, the first attempts
// of each VIN at each station are eol-1 #2, #4, #5 and eol-2 #1, #2 (eol-1 #1 is older and
// #3, #6 are retries), so:
//   eol-1 model-a: cycle 1/3 passed, front_camera 1/3, roof_lidar 2/3
//   eol-2 model-a: cycle 1/1, front_camera 1/1, roof_lidar 1/1
//   eol-2 model-b: cycle 0/1, front_camera 0/1, roof_lidar 1/1
//   reasons: front_camera yaw_out_of_tolerance 2, board_not_found 1; roof_lidar
//            too_few_points 1
// VIN1's attempts, newest first: eol-2 #1, eol-1 #3, eol-1 #2.
inline std::vector<StationBatch> PlantDataSet() {
  auto camera = [](Verdict v, const std::string& reason = "") {
    return FullSensor("front_camera", "camera", v, reason);
  };
  auto lidar = [](Verdict v, const std::string& reason = "") {
    return FullSensor("roof_lidar", "lidar", v, reason);
  };
  const Verdict pass = Verdict::kPass, fail = Verdict::kFail;
  const int64_t t0 = kPlantT0Ns;
  return {
      {"eol-1",
       {MakePlantCycle(1, "VIN5", "model-a", t0 - 24 * kHourNs, {camera(pass), lidar(pass)}),
        MakePlantCycle(2, "VIN1", "model-a", t0 + 1 * kHourNs,
                       {camera(fail, "yaw_out_of_tolerance"), lidar(pass)}),
        MakePlantCycle(3, "VIN1", "model-a", t0 + 2 * kHourNs, {camera(pass), lidar(pass)}),
        MakePlantCycle(4, "VIN2", "model-a", t0 + 3 * kHourNs, {camera(pass), lidar(pass)}),
        MakePlantCycle(5, "VIN3", "model-a", t0 + 4 * kHourNs,
                       {camera(fail, "board_not_found"), lidar(fail, "too_few_points")}),
        MakePlantCycle(6, "VIN5", "model-a", t0 + 5 * kHourNs,
                       {camera(fail, "yaw_out_of_tolerance"), lidar(pass)})}},
      {"eol-2",
       {MakePlantCycle(1, "VIN1", "model-a", t0 + 6 * kHourNs, {camera(pass), lidar(pass)}),
        MakePlantCycle(2, "VIN4", "model-b", t0 + 7 * kHourNs,
                       {camera(fail, "yaw_out_of_tolerance"), lidar(pass)})}},
  };
}

// The first-pass yield of PlantDataSet() per station, car model and sensor ("" for the whole
// cycle), as "station model sensor passed/first_attempts", in the order the reports give:
// worked out by hand from the data set above, the expectation of both the client's and the
// command line's yield tests.
inline std::vector<std::string> PlantDataSetYieldRows() {
  return {"eol-1 model-a  1/3", "eol-1 model-a front_camera 1/3", "eol-1 model-a roof_lidar 2/3",
          "eol-2 model-a  1/1", "eol-2 model-a front_camera 1/1", "eol-2 model-a roof_lidar 1/1",
          "eol-2 model-b  0/1", "eol-2 model-b front_camera 0/1", "eol-2 model-b roof_lidar 1/1"};
}

}  // namespace linecal::testing_support

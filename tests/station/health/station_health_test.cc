// Station health (station/health/station_health.h): charts, the moved-target alarm and its
// bars over series with the noise of the real pipeline (docs/console.md, "Noise model").
#include "station/health/station_health.h"

#include <gtest/gtest.h>

#include <random>

namespace linecal {
namespace {

// The reference car's sensors as measured on 30 simulated cycles of linecald (seeds = cycle
// ids 1-30, aligner values of tools/health-noise-model), each cycle also run with
// `bumper_lidar_left` turned 0.3° in yaw (source.moved_boards) for the paired shift:
// σ of each deviation axis (deg, m), the residual's mean and σ, and the residual's mean shift.
struct SensorNoise {
  const char* name;
  std::array<double, 6> deviation_sigma;
  double residual_mean, residual_sigma, residual_shift;
};
constexpr SensorNoise kReference[] = {
    {"front_camera", {0.238, 0.298, 0.281, 0.00579, 0.00609, 0.00569}, 0.1362, 0.00693, 0.00843},
    {"surround_front", {0.285, 0.298, 0.322, 0.00487, 0.00602, 0.00514}, 0.09914, 0.0084, 0.000256},
    {"surround_left", {0.247, 0.268, 0.255, 0.00573, 0.00572, 0.0056}, 0.1297, 0.00681, 0},
    {"bumper_lidar", {0.276, 0.292, 0.324, 0.006, 0.00646, 0.00733}, 0.001279, 0.000392, 0.000336},
    {"roof_lidar", {0.308, 0.312, 0.26, 0.00548, 0.00519, 0.0054}, 0.0009877, 0.000437, 0},
};

// A car model of the measured sensors with the reference car's targets (deploy/cars).
CarModel ReferenceLike() {
  CarModel car;
  car.id = "reference";
  auto add = [&](const char* name, SensorKind kind, std::vector<std::string> targets) {
    SensorModel m;
    m.name = name;
    m.kind = kind;
    m.targets = std::move(targets);
    m.tolerance.yaw_rad = m.tolerance.pitch_rad = m.tolerance.roll_rad = 1.5 * M_PI / 180;
    m.tolerance.xyz_m = Eigen::Vector3d::Constant(0.03);
    car.sensors.push_back(m);
  };
  add("front_camera", SensorKind::kCamera,
      {"front_chessboard", "front_circle", "front_vertical", "bumper_lidar_left",
       "bumper_lidar_right"});
  add("surround_front", SensorKind::kCamera,
      {"front_chessboard", "front_vertical", "bumper_lidar_left", "bumper_lidar_right",
       "left_front_board"});
  add("surround_left", SensorKind::kCamera,
      {"left_floor_grid", "left_front_board", "left_rear_board"});
  add("bumper_lidar", SensorKind::kLidar, {"bumper_lidar_left", "bumper_lidar_right"});
  add("roof_lidar", SensorKind::kLidar, {"roof_lidar_left", "roof_lidar_right"});
  return car;
}

// Cars with the measured noise; those with id >= moved_from see bumper_lidar_left moved.
class Line {
 public:
  explicit Line(std::uint64_t seed) : rng_(seed) {}
  HealthCycle Car(int64_t id, int64_t moved_from) {
    HealthCycle c{id, id * 60'000'000'000, "reference", {}};
    for (const SensorNoise& n : kReference) {
      HealthResult r{n.name, {}};
      for (int k = 0; k < 6; ++k) r.values[k] = n.deviation_sigma[k] * normal_(rng_);
      r.values[kResidualSeries] = n.residual_mean + n.residual_sigma * normal_(rng_) +
                                  (id >= moved_from ? n.residual_shift : 0.0);
      c.results.push_back(r);
    }
    return c;
  }

 private:
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_;
};

// The alarms at each new car, judged over the last kHealthWindow cars as the daemon does.
constexpr size_t kWindow = 200;

std::vector<TargetAlarm> AlarmsAt(const CarModel& car, const std::vector<HealthCycle>& all) {
  const size_t from = all.size() > kWindow ? all.size() - kWindow : 0;
  std::vector<HealthCycle> window(all.begin() + static_cast<long>(from), all.end());
  absl::StatusOr<StationHealth> h = ComputeStationHealth({car}, window);
  EXPECT_TRUE(h.ok()) << h.status();
  return h.ok() ? h->alarms : std::vector<TargetAlarm>{};
}

TEST(StationHealth, ChartsHaveBaselineLimitsAndTolerances) {
  const CarModel car = ReferenceLike();
  Line line(1);
  std::vector<HealthCycle> cycles;
  for (int64_t id = 1; id <= 50; ++id) cycles.push_back(line.Car(id, 1000));
  absl::StatusOr<StationHealth> h = ComputeStationHealth({car}, cycles);
  ASSERT_TRUE(h.ok()) << h.status();
  ASSERT_EQ(h->trends.size(), 5u);
  const SensorTrend& t = h->trends[0];
  EXPECT_EQ(t.sensor, "front_camera");
  EXPECT_EQ(t.kind, "camera");
  ASSERT_EQ(t.series.size(), static_cast<size_t>(kHealthSeries));
  const HealthSeries& yaw = t.series[0];
  EXPECT_EQ(yaw.name, "yaw_deg");
  ASSERT_EQ(yaw.values.size(), 50u);
  EXPECT_EQ(yaw.cycle_ids.front(), 1);
  EXPECT_EQ(yaw.cycle_ids.back(), 50);
  EXPECT_NEAR(yaw.tolerance, 1.5, 1e-12);
  EXPECT_EQ(t.series[kResidualSeries].tolerance, 0.0);
  // Baseline: the 30 points before the last 20.
  double mean = 0;
  for (int i = 0; i < 30; ++i) mean += yaw.values[i];
  mean /= 30;
  EXPECT_NEAR(yaw.mean, mean, 1e-12);
  ASSERT_EQ(yaw.upper.size(), 50u);
  // The limits widen to 3 σ sqrt(λ / (2 − λ)) = 1 σ (λ = 0.2).
  EXPECT_NEAR(yaw.upper.back() - yaw.mean, 3 * yaw.sigma * std::sqrt(0.2 / 1.8), 1e-9);
  EXPECT_NEAR(yaw.upper.front() - yaw.mean, 3 * yaw.sigma * 0.2, 1e-9);
  EXPECT_NEAR(yaw.ewma[0], 0.2 * yaw.values[0] + 0.8 * yaw.mean, 1e-12);
  // Counts: bumper_lidar_left is used by three sensors, all solved in every cycle.
  bool found = false;
  for (const TargetCounts& c : h->counts) {
    if (c.target != "bumper_lidar_left") continue;
    found = true;
    EXPECT_EQ(c.sensors, 3);
    ASSERT_EQ(c.solved.size(), 50u);
    EXPECT_EQ(c.solved[7], 3);
  }
  EXPECT_TRUE(found);
}

TEST(StationHealth, AlarmNamesTargetsSensorsShiftAndStart) {
  // A shift of 3 σ in the residuals of the bumper boards' three sensors from cycle 41.
  const CarModel car = ReferenceLike();
  Line line(2);
  std::vector<HealthCycle> cycles;
  for (int64_t id = 1; id <= 50; ++id) {
    HealthCycle c = line.Car(id, 1000);
    if (id >= 41) {
      for (HealthResult& r : c.results) {
        for (const SensorNoise& n : kReference) {
          const bool user = r.sensor == std::string("front_camera") ||
                            r.sensor == std::string("surround_front") ||
                            r.sensor == std::string("bumper_lidar");
          if (user && r.sensor == std::string(n.name))
            r.values[kResidualSeries] += 3 * n.residual_sigma;
        }
      }
    }
    cycles.push_back(c);
  }
  absl::StatusOr<StationHealth> h = ComputeStationHealth({car}, cycles);
  ASSERT_TRUE(h.ok()) << h.status();
  ASSERT_EQ(h->alarms.size(), 1u);
  const TargetAlarm& a = h->alarms[0];
  EXPECT_EQ(a.car_model, "reference");
  EXPECT_EQ(a.targets, (std::vector<std::string>{"bumper_lidar_left", "bumper_lidar_right"}));
  ASSERT_EQ(a.sensors.size(), 3u);
  EXPECT_EQ(a.sensors[0].sensor, "front_camera");
  EXPECT_EQ(a.sensors[1].sensor, "surround_front");
  EXPECT_EQ(a.sensors[2].sensor, "bumper_lidar");
  for (const ShiftedSensor& s : a.sensors) EXPECT_GT(s.shift_sigmas, 1.5) << s.sensor;
  EXPECT_GE(a.since_cycle, 38);
  EXPECT_LE(a.since_cycle, 41);
  EXPECT_EQ(a.last_cycle, 50);
  EXPECT_GT(a.statistic_sigmas, a.alarm_sigmas);
}

TEST(StationHealth, RefusesBadInput) {
  StationHealthOptions o;
  o.lambda = 0;
  EXPECT_EQ(ComputeStationHealth({}, {}, o).status().message(), "lambda: must be in (0, 1]");
  std::vector<HealthCycle> cycles{{2, 0, "x", {}}, {2, 0, "x", {}}};
  EXPECT_EQ(ComputeStationHealth({}, cycles).status().message(),
            "cycles: ids must increase, got 2 then 2");
}

// The bar of issue 23 that the residual statistic meets, over the noise model: a still
// station never raises the alarm in 1,000 cars (five lines of cars).
TEST(StationHealth, StillStationNeverAlarmsInAThousandCars) {
  const CarModel car = ReferenceLike();
  for (std::uint64_t seed = 1; seed <= 5; ++seed) {
    Line line(seed);
    std::vector<HealthCycle> cycles;
    for (int64_t id = 1; id <= 1000; ++id) {
      cycles.push_back(line.Car(id, 1'000'000));
      ASSERT_TRUE(AlarmsAt(car, cycles).empty())
          << "seed " << seed << ": false alarm at car " << id;
    }
  }
}

// The bar it does not meet yet (docs/console.md, "Moved-target alarm: measured"):
// bumper_lidar_left turned 0.3° raises the alarm within 20 cars in 18 of these 20 lines. A
// measurement run by hand (--gtest_also_run_disabled_tests), kept to show the next step's gain.
TEST(StationHealth, DISABLED_MovedBoardAlarmWithinTwentyCars) {
  const CarModel car = ReferenceLike();
  int late = 0;
  for (std::uint64_t seed = 101; seed <= 120; ++seed) {
    Line line(seed);
    std::vector<HealthCycle> cycles;
    int64_t found_after = 0;
    for (int64_t id = 1; id <= 220 && found_after == 0; ++id) {
      cycles.push_back(line.Car(id, 201));
      if (id >= 201 && !AlarmsAt(car, cycles).empty()) found_after = id - 200;
    }
    std::printf("seed %lu: alarm after %ld moved cars (0: none within 20)\n", seed, found_after);
    if (found_after == 0) ++late;
  }
  EXPECT_EQ(late, 0);
}

}  // namespace
}  // namespace linecal

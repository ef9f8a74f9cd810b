// Reflector association: gates, RCS and range-rate tests, nearest-in-range against ghosts,
// robust averaging, and every reason a reflector is not found.
#include "station/solvers/reflector_association.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "tests/station/solvers/radar_test_scene.h"

namespace linecal {
namespace {

using radar_test::kDeg;

// Standard errors of a mean over ~50 detections: 4 of them bound a Gaussian estimate with a
// false-failure chance of 6e-5 per assertion.
constexpr double kSeBound = 4.0;

std::vector<ExpectedReflector> Expected(const SensorModel& s, const StationLayout& layout,
                                        const Rigid3d& T_station_car = Rigid3d()) {
  absl::StatusOr<std::vector<ExpectedReflector>> e = ExpectedReflectors(s, layout, T_station_car);
  EXPECT_TRUE(e.ok()) << e.status();
  return e.ok() ? *e : std::vector<ExpectedReflector>{};
}

ReflectorAssociationOptions OptionsFor(const SensorModel& s) {
  absl::StatusOr<ReflectorAssociationOptions> o = ReflectorAssociationOptions::ForSensor(s);
  EXPECT_TRUE(o.ok()) << o.status();
  EXPECT_TRUE(o->Validate().ok());
  return *o;
}

RadarDetection Detection(double range_m, double azimuth_rad, double rate_mps,
                         std::optional<double> rcs) {
  RadarDetection d;
  d.range_m = range_m;
  d.azimuth_rad = azimuth_rad;
  d.range_rate_mps = rate_mps;
  d.rcs_dbsm = rcs;
  return d;
}

TEST(ExpectedReflectorsTest, NominalGeometryAndErrors) {
  const StationLayout layout = radar_test::TestLayout();
  SensorModel s = radar_test::TestRadar("ars408");
  s.targets = {"left", "behind"};
  // The car 0.1 m to the left in the station: the left reflector is 2.4 m to the left of the
  // radar, 8 m ahead.
  const Rigid3d T_station_car = Rigid3d::Translation(Eigen::Vector3d(0, 0.1, 0));
  const std::vector<ExpectedReflector> e = Expected(s, layout, T_station_car);
  ASSERT_EQ(e.size(), 2u);
  EXPECT_EQ(e[0].reflector_id, "left");
  EXPECT_NEAR(e[0].range_m, std::hypot(8.0, 2.4), 1e-12);
  EXPECT_NEAR(e[0].azimuth_rad, std::atan2(2.4, 8.0), 1e-12);
  EXPECT_TRUE(e[0].in_view);
  EXPECT_TRUE(e[0].p_car.isApprox(Eigen::Vector3d(12.0, 2.4, 0.45), 1e-12));
  EXPECT_FALSE(e[1].in_view);

  s.targets = {"nowhere"};
  EXPECT_EQ(ExpectedReflectors(s, layout, Rigid3d()).status().code(), absl::StatusCode::kNotFound);
  s.kind = SensorKind::kLidar;
  EXPECT_EQ(ExpectedReflectors(s, layout, Rigid3d()).status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(ReflectorAssociationOptionsTest, GatesCoverTwiceTheToleranceAndTheNoise) {
  const ReflectorAssociationOptions o = OptionsFor(radar_test::TestRadar("esr"));
  EXPECT_GE(o.azimuth_gate_rad, 2 * 1.0 * kDeg + 3 * o.detection_azimuth_sigma_rad);
  EXPECT_GE(o.range_gate_m, std::sqrt(3.0) * 0.05 + 3 * o.detection_range_sigma_m);
  EXPECT_DOUBLE_EQ(o.resolution.azimuth_step_rad, 0.1 * kDeg);
  EXPECT_DOUBLE_EQ(o.resolution.range_step_m, 0.1);
  EXPECT_DOUBLE_EQ(RadarResolutionOf("ars408")->position_step_m, 0.2);
  EXPECT_FALSE(RadarResolutionOf("srr").has_value());

  ReflectorAssociationOptions bad = o;
  bad.azimuth_gate_rad = 0;
  EXPECT_NE(bad.Validate().message().find("azimuth_gate_rad"), std::string::npos);
  bad = o;
  bad.min_detections = 1;
  EXPECT_NE(bad.Validate().message().find("min_detections"), std::string::npos);
  bad = o;
  bad.resolution.position_step_m = -1;
  EXPECT_NE(bad.Validate().message().find("resolution.position_step_m"), std::string::npos);
}

// A radar 5 cm off its place moves a reflector 2.2 m away by up to 1.8° of azimuth, twice as
// much as one at 4 m, which the fixed gate was sized for: near reflectors widen their gate by the
// lateral margin's extra angle (3.41° at 4 m and beyond, 4.24° at 2.2 m for the ESR), far ones
// keep theirs.
TEST(AssociateReflectorsTest, NearReflectorsHaveAWiderAzimuthGate) {
  const SensorModel s = radar_test::TestCornerRadar();  // near 5.2 m, far 5.7 m, close 2.2 m
  const std::vector<ExpectedReflector> e = Expected(s, radar_test::CornerLayout());
  const ReflectorAssociationOptions o = OptionsFor(s);
  EXPECT_NEAR(o.azimuth_gate_rad, 3.413 * kDeg, 0.001 * kDeg);
  EXPECT_NEAR(o.azimuth_gate_lateral_m, std::hypot(0.05, 0.05), 1e-12);
  std::vector<RadarCycle> cycles(20);
  for (RadarCycle& c : cycles) {
    for (const ExpectedReflector& r : e) {
      c.detections.push_back(Detection(r.range_m, r.azimuth_rad + 3.8 * kDeg, 0.0, std::nullopt));
    }
  }
  const ReflectorAssociation out = AssociateReflectors(cycles, e, o);
  ASSERT_EQ(out.reflectors.size(), 3u);
  EXPECT_EQ(out.reflectors[0].status, ReflectorStatus::kNoDetections);  // near, 5.2 m
  EXPECT_EQ(out.reflectors[1].status, ReflectorStatus::kNoDetections);  // far, 5.7 m
  EXPECT_EQ(out.reflectors[2].status, ReflectorStatus::kFound);         // close, 2.2 m
  EXPECT_EQ(out.reflectors[2].n_used, 20);

  ReflectorAssociationOptions bad = o;
  bad.azimuth_gate_lateral_m = -0.1;
  EXPECT_NE(bad.Validate().message().find("azimuth_gate_lateral_m"), std::string::npos);
}

// Per cycle: the reflector, a weaker echo 0.35 m farther inside the range gate, a weak
// clutter return and a strong mover both nearer in range inside the gate, and a ghost at 1.5x
// the range. Only the reflector may be used, exactly as reported.
TEST(AssociateReflectorsTest, PicksTheReflectorOverGhostsClutterAndMovers) {
  const StationLayout layout = radar_test::TestLayout();
  SensorModel s = radar_test::TestRadar("ars408");
  s.targets = {"left"};
  const std::vector<ExpectedReflector> e = Expected(s, layout);
  const double r = e[0].range_m, a = e[0].azimuth_rad;
  std::vector<RadarCycle> cycles(20);
  for (size_t i = 0; i < cycles.size(); ++i) {
    const double da = (i % 2 == 0 ? 1 : -1) * 0.05 * kDeg;      // ±0.05°: mean exactly 0
    cycles[i].detections = {Detection(r + 0.35, a, 0.0, 12.0),  // farther echo
                            Detection(r - 0.2, a + 0.5 * kDeg, 0.0, 0.0),  // weak clutter
                            Detection(r - 0.3, a, 1.5, 20.0),              // moving
                            Detection(1.5 * r, a, 0.0, 5.0),               // multipath ghost
                            Detection(r + 0.02, a + da, 0.01, 19.0)};      // the reflector
  }
  const ReflectorAssociation out = AssociateReflectors(cycles, e, OptionsFor(s));
  ASSERT_EQ(out.reflectors.size(), 1u);
  const ReflectorObservation& o = out.reflectors[0];
  EXPECT_EQ(o.status, ReflectorStatus::kFound);
  EXPECT_EQ(o.n_used, 20);
  EXPECT_EQ(o.outliers, 0);
  EXPECT_EQ(o.ambiguous_cycles, 0);
  EXPECT_NEAR(o.range_m, r + 0.02, 1e-12);
  EXPECT_NEAR(o.azimuth_rad, a, 1e-12);
  // Scatter 0.05° is below the sensor's 0.1°, which floors it; plus the ARS408's 0.2 m cells.
  EXPECT_GE(o.azimuth_se_rad, 0.1 * kDeg / std::sqrt(20.0));
}

TEST(AssociateReflectorsTest, RejectsOutliersByMedianAndMad) {
  const StationLayout layout = radar_test::TestLayout();
  SensorModel s = radar_test::TestRadar("esr");
  s.targets = {"centre"};
  const std::vector<ExpectedReflector> e = Expected(s, layout);
  std::vector<RadarCycle> cycles(33);
  for (size_t i = 0; i < cycles.size(); ++i) {
    const double da = i < 3 ? 1.5 * kDeg : (i % 2 == 0 ? 0.1 : -0.1) * kDeg;
    cycles[i].detections = {Detection(e[0].range_m, e[0].azimuth_rad + da, 0.0, std::nullopt)};
  }
  const ReflectorObservation o = AssociateReflectors(cycles, e, OptionsFor(s)).reflectors[0];
  EXPECT_EQ(o.status, ReflectorStatus::kFound);
  EXPECT_EQ(o.outliers, 3);
  EXPECT_EQ(o.n_used, 30);
  EXPECT_NEAR(o.azimuth_rad, e[0].azimuth_rad, 1e-12);
}

// SimulateRadar with heavy clutter and multipath, encoded to CAN and decoded: every target is
// found, near its true range and azimuth, with (almost) every cycle's detection used.
TEST(AssociateReflectorsTest, SimulatedTrafficWithClutterAndMultipath) {
  const StationLayout layout = radar_test::TestLayout();
  const Rigid3d T_station_car(
      Eigen::Matrix3d(Eigen::AngleAxisd(0.1 * kDeg, Eigen::Vector3d::UnitZ())),
      Eigen::Vector3d(0.01, -0.015, 0));
  RadarSimOptions sim;
  sim.cycles = 50;
  sim.clutter_per_cycle = 30;
  sim.multipath = true;
  for (const char* model : {"esr", "ars408"}) {
    SCOPED_TRACE(model);
    const SensorModel s = radar_test::TestRadar(model);
    const Rigid3d T_car_radar = radar_test::TrueMounting(s, {0.6 * kDeg, 0.3 * kDeg, -0.4 * kDeg});
    const std::vector<RadarCycle> cycles =
        radar_test::SimulatedCycles(s, layout, T_station_car, T_car_radar, sim, 7);
    ASSERT_EQ(cycles.size(), 50u);
    const std::vector<RadarTruth> truth =
        RadarReflectorTruth(layout, T_station_car * T_car_radar, *RadarFieldOfViewOf(model));
    const ReflectorAssociation out =
        AssociateReflectors(cycles, Expected(s, layout, T_station_car), OptionsFor(s));
    ASSERT_EQ(out.reflectors.size(), 3u);
    for (const ReflectorObservation& o : out.reflectors) {
      SCOPED_TRACE(o.reflector_id);
      const RadarTruth& t = *std::find_if(truth.begin(), truth.end(), [&](const RadarTruth& x) {
        return x.reflector_id == o.reflector_id;
      });
      EXPECT_EQ(o.status, ReflectorStatus::kFound);
      // Detection probability 0.98: ≥ 45 of 50 cycles (binomial tail < 1e-3), a few outliers.
      EXPECT_GE(o.n_used, 45);
      EXPECT_LE(o.outliers, 3);
      EXPECT_NEAR(o.azimuth_rad, t.azimuth_rad, kSeBound * o.azimuth_se_rad);
      EXPECT_NEAR(o.range_m, t.range_m, kSeBound * o.range_se_m);
    }
  }
}

TEST(AssociateReflectorsTest, ReasonsForMissingReflectors) {
  const StationLayout layout = radar_test::TestLayout();
  SensorModel s = radar_test::TestRadar("esr");
  s.targets = {"behind", "centre", "left"};
  const std::vector<ExpectedReflector> e = Expected(s, layout);
  const ReflectorAssociationOptions options = OptionsFor(s);
  // The centre reflector only in 5 cycles (fewer than min_detections); the left one always
  // with a second candidate 0.1 m farther, which nearest-in-range cannot tell apart.
  std::vector<RadarCycle> cycles(40);
  for (size_t i = 0; i < cycles.size(); ++i) {
    if (i < 5)
      cycles[i].detections.push_back(Detection(e[1].range_m, e[1].azimuth_rad, 0, std::nullopt));
    cycles[i].detections.push_back(Detection(e[2].range_m, e[2].azimuth_rad, 0, std::nullopt));
    cycles[i].detections.push_back(
        Detection(e[2].range_m + 0.1, e[2].azimuth_rad, 0, std::nullopt));
  }
  ReflectorAssociation out = AssociateReflectors(cycles, e, options);
  ASSERT_EQ(out.reflectors.size(), 3u);
  EXPECT_EQ(out.reflectors[0].status, ReflectorStatus::kNotInView);
  EXPECT_EQ(out.reflectors[1].status, ReflectorStatus::kTooFewDetections);
  EXPECT_EQ(out.reflectors[1].n_used, 5);
  EXPECT_EQ(out.reflectors[2].status, ReflectorStatus::kAmbiguous);
  EXPECT_EQ(out.reflectors[2].ambiguous_cycles, 40);
  EXPECT_STREQ(ReflectorStatusName(out.reflectors[2].status), "ambiguous");

  // No detection anywhere near the centre reflector.
  for (RadarCycle& c : cycles) c.detections = {Detection(30.0, 0.0, 0, std::nullopt)};
  out = AssociateReflectors(cycles, e, options);
  EXPECT_EQ(out.reflectors[1].status, ReflectorStatus::kNoDetections);
  EXPECT_STREQ(ReflectorStatusName(ReflectorStatus::kNoDetections), "no_detections");

  // Two reflectors 10 cm apart: their gates overlap, neither can be told from the other.
  StationLayout close = layout;
  close.reflectors.push_back({"centre_twin", Eigen::Vector3d(12.0, 0.1, 0.45), 20.0});
  s.targets = {"centre", "centre_twin", "right"};
  out = AssociateReflectors(cycles, Expected(s, close), options);
  EXPECT_EQ(out.reflectors[0].status, ReflectorStatus::kAmbiguous);
  EXPECT_EQ(out.reflectors[1].status, ReflectorStatus::kAmbiguous);
  EXPECT_EQ(out.reflectors[2].status, ReflectorStatus::kNoDetections);
}

// Detections of `reflectors` static reflectors at random places (6–14 m, ±40°), `n` each, with
// Gaussian range and azimuth noise, rounded as the radar's resolution rounds them.
std::vector<ReflectorDetections> NoisyDetections(const RadarResolution& res, double range_sigma_m,
                                                 double azimuth_sigma_rad, int reflectors, int n,
                                                 std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> range(6.0, 14.0), azimuth(-40 * kDeg, 40 * kDeg);
  std::normal_distribution<double> normal;
  const auto round_to = [](double v, double step, double origin = 0) {
    return step > 0 ? origin + step * std::round((v - origin) / step) : v;
  };
  std::vector<ReflectorDetections> out(reflectors);
  for (ReflectorDetections& d : out) {
    const double r0 = range(rng), a0 = azimuth(rng);
    for (int k = 0; k < n; ++k) {
      double r = r0 + range_sigma_m * normal(rng), a = a0 + azimuth_sigma_rad * normal(rng);
      if (res.position_step_m > 0) {  // the ARS408's Cartesian grid
        const double x = round_to(r * std::cos(a), res.position_step_m, res.position_x_origin_m);
        const double y = round_to(r * std::sin(a), res.position_step_m);
        r = std::hypot(x, y);
        a = std::atan2(y, x);
      }
      d.range_m.push_back(round_to(r, res.range_step_m));
      d.azimuth_rad.push_back(round_to(a, res.azimuth_step_rad));
    }
  }
  return out;
}

// The noise estimate undoes the resolution's rounding: range noise of 2–10 cm under the ESR's
// 0.1 m steps and the ARS408's 0.2 m grid, azimuth noise of 0.1° under the ESR's 0.1° steps,
// from 6 reflectors x 50 cycles (294 degrees of freedom). What one capture can tell is limited
// by where its few reflectors happen to sit in their cells when the noise is below the step;
// the tolerances are about 3x the scatter measured over seeds 1–40 of this generator:
// - ESR range (moments): 2 cm scatters by ±25% (0.2 steps), 5–10 cm by ±5% → 75% / 15%;
//   ESR azimuth ±6% → 15%.
// - ARS408 range (likelihood over the grid): 5 cm ±12% → 35%, 8–10 cm ±5% → 15%. At 2 cm
//   (0.1 steps: most reflectors never change cell) it scatters by ±58%, from 0.05x to 2.3x, the
//   information of a handful of cell edges; it is checked only to stay below the nominal 5 cm,
//   so that such noise is never read as more than nominal (which would take the grid for
//   dithered and understate its error). The earlier moment estimate ranged over 0–3.5x here.
// - ARS408 azimuth: 0.1° at 6–14 m is 0.05–0.12 of a step across the line of sight, which no
//   capture of this size separates from the range noise (a free estimate scattered by ±70%);
//   it is taken as given (the sensor's nominal) and only the range noise is estimated.
// A sensor without steps gives the plain pooled standard deviation.
TEST(EstimateDetectionNoiseTest, RecoversInjectedNoiseThroughTheResolution) {
  const RadarResolution esr = *RadarResolutionOf("esr");
  const RadarResolution ars408 = *RadarResolutionOf("ars408");
  for (const double sigma_r : {0.02, 0.05, 0.08, 0.10}) {
    SCOPED_TRACE(sigma_r);
    const DetectionNoise e =
        EstimateDetectionNoise(NoisyDetections(esr, sigma_r, 0.1 * kDeg, 6, 50, 3), esr);
    EXPECT_EQ(e.dof, 294);
    EXPECT_NEAR(e.range_sigma_m, sigma_r, (sigma_r < 0.03 ? 0.75 : 0.15) * sigma_r);
    EXPECT_NEAR(e.azimuth_sigma_rad, 0.1 * kDeg, 0.015 * kDeg);
    const DetectionNoise a =
        EstimateDetectionNoise(NoisyDetections(ars408, sigma_r, 0.1 * kDeg, 6, 50, 4), ars408);
    EXPECT_EQ(a.dof, 294);
    EXPECT_EQ(a.azimuth_sigma_rad, 0.1 * kDeg);
    if (sigma_r < 0.03) {
      EXPECT_GT(a.range_sigma_m, 0.0);
      EXPECT_LT(a.range_sigma_m, 0.05);
    } else {
      EXPECT_NEAR(a.range_sigma_m, sigma_r, (sigma_r < 0.06 ? 0.35 : 0.15) * sigma_r);
    }
  }
  const DetectionNoise plain =
      EstimateDetectionNoise(NoisyDetections(RadarResolution{}, 0.05, 0.1 * kDeg, 6, 50, 5), {});
  EXPECT_NEAR(plain.range_sigma_m, 0.05, 0.15 * 0.05);
  EXPECT_NEAR(plain.azimuth_sigma_rad, 0.1 * kDeg, 0.15 * 0.1 * kDeg);
  // Nothing to pool: no noise claimed, so every step counts as undithered.
  EXPECT_EQ(EstimateDetectionNoise({}, esr).dof, 0);
  EXPECT_EQ(EstimateDetectionNoise({}, esr).range_sigma_m, 0.0);
}

}  // namespace
}  // namespace linecal

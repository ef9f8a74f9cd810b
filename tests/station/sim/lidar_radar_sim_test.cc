// The simulator's LiDAR and radar, checked against geometry and through the real decoders:
// points lie on the board planes within the noise and never inside a hole, rays pass through
// every hole, simulated packets decode to the simulated points, and simulated CAN frames decode
// back to the reflectors' range and azimuth.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <numbers>
#include <set>
#include <string>

#include "station/io/candump.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/sensors/lidar/lidar_decoder.h"
#include "station/sensors/lidar/lidar_pcap.h"
#include "station/sensors/lidar/pcd.h"
#include "station/sensors/radar/radar_decoder.h"
#include "station/sim/lidar_sim.h"
#include "station/sim/radar_sim.h"
#include "station/sim/simulator.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
constexpr double kDegToRad = std::numbers::pi / 180.0;

class SimTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    station_ = new StationLayout(*ReadStationLayout(kDeploy + "/stations/reference.json"));
    car_ = new CarModel(*ReadCarModel(kDeploy + "/cars/reference.json"));
  }
  static void TearDownTestSuite() {
    delete station_;
    delete car_;
  }
  // The nominal T_station_sensor of a car at the station origin.
  static Rigid3d NominalPose(const std::string& sensor) {
    return car_->FindSensor(sensor)->T_car_sensor_nominal;
  }
  static LidarBeamTable Beams(const std::string& sensor) {
    const SensorModel* s = car_->FindSensor(sensor);
    const LidarModel model = *LidarModelFromName(s->model);
    return *(s->angles_file.empty() ? DefaultBeamTable(model)
                                    : ReadAngleCorrectionCsv(model, s->angles_file));
  }

  static StationLayout* station_;
  static CarModel* car_;
};
StationLayout* SimTest::station_ = nullptr;
CarModel* SimTest::car_ = nullptr;

// For every point that lies near a target board's plane: its position on the board is printed
// (never a hole), and the distances to the plane spread like the range noise.
void CheckBoardPoints(const LidarSimResult& sim, const Rigid3d& T_station_lidar,
                      const StationBoard& board, double sigma, int* on_board, double* rms) {
  const Rigid3d T_board_lidar = board.T_station_board.Inverse() * T_station_lidar;
  const Eigen::Vector2d half = 0.5 * board.board.page_size_m();
  // Points within 5 sigma (or 1 cm without noise) of the plane and inside the page count.
  const double band = std::max(5 * sigma, 0.01);
  double sum2 = 0;
  *on_board = 0;
  for (const LidarPoint& p : sim.scans[0].points) {
    const Eigen::Vector3d q = T_board_lidar * Eigen::Vector3d(p.x, p.y, p.z);
    if (std::abs(q.z()) > band || std::abs(q.x()) > half.x() || std::abs(q.y()) > half.y())
      continue;
    // Noise moves a point along its ray, so it lands slightly beside where the ray hit: compare
    // the paint where the ray crossed the plane.
    const Eigen::Vector3d o = T_board_lidar.translation();
    const Eigen::Vector3d d = (q - o).normalized();
    const Eigen::Vector3d hit = o + (-o.z() / d.z()) * d;
    const Paint paint = board.board.PaintAt(hit.head<2>());
    EXPECT_NE(paint, Paint::kHole)
        << "point in a hole of " << board.id << " at " << hit.transpose();
    ++*on_board;
    sum2 += q.z() * q.z();
  }
  *rms = *on_board ? std::sqrt(sum2 / *on_board) : 0;
}

TEST_F(SimTest, LidarPointsLieOnBoardsAndNeverInHoles) {
  for (const char* sensor : {"roof_lidar", "bumper_lidar"}) {
    for (double sigma : {0.0, 0.02}) {
      LidarSimOptions o;
      o.range_sigma_m = sigma;
      const Rigid3d pose = NominalPose(sensor);
      absl::StatusOr<LidarSimResult> sim = SimulateLidar(Beams(sensor), pose, *station_, o, 0, 7);
      ASSERT_TRUE(sim.ok()) << sim.status();
      for (const std::string& id : car_->FindSensor(sensor)->targets) {
        int n = 0;
        double rms = 0;
        CheckBoardPoints(*sim, pose, *station_->FindBoard(id), sigma, &n, &rms);
        // Each LiDAR puts dozens of returns on each of its boards at 2.8-5 m.
        EXPECT_GT(n, 30) << sensor << " " << id;
        // Without noise only the distance unit's rounding (2-4 mm) remains; with noise the
        // spread along the normal is about sigma times the cosine of the incidence angle
        // (boards face the car within ~35 degrees), hence 0.6..1.1 sigma.
        if (sigma == 0) {
          EXPECT_LT(rms, 0.004) << sensor << " " << id;
        } else {
          EXPECT_GT(rms, 0.6 * sigma) << sensor << " " << id;
          EXPECT_LT(rms, 1.1 * sigma) << sensor << " " << id;
        }
      }
    }
  }
}

TEST_F(SimTest, LidarRaysPassThroughEveryHole) {
  // The Pandar64's dense central beams cross every hole of both its boards: count, per hole,
  // the rays that cross the board plane inside it and return from farther away.
  const Rigid3d pose = NominalPose("roof_lidar");
  LidarSimOptions o;
  o.range_sigma_m = 0;
  absl::StatusOr<LidarSimResult> sim = SimulateLidar(Beams("roof_lidar"), pose, *station_, o, 0, 1);
  ASSERT_TRUE(sim.ok());
  for (const std::string& id : car_->FindSensor("roof_lidar")->targets) {
    const StationBoard& b = *station_->FindBoard(id);
    const Rigid3d T_board_lidar = b.T_station_board.Inverse() * pose;
    std::map<int, int> through;
    for (const LidarPoint& p : sim->scans[0].points) {
      const Eigen::Vector3d q = T_board_lidar * Eigen::Vector3d(p.x, p.y, p.z);
      if (q.z() > -0.05) continue;  // not behind the board
      const Eigen::Vector3d o = T_board_lidar.translation();
      const Eigen::Vector3d hit = o + (-o.z() / (q - o).z()) * (q - o);
      for (const BoardFeature& f : b.board.features()) {
        if (f.kind == FeatureKind::kHoleCentre && (hit.head<2>() - f.p_board).norm() < 0.12)
          ++through[f.id];
      }
    }
    EXPECT_EQ(through.size(), 5u) << id;
  }
}

TEST_F(SimTest, LidarIsDeterministic) {
  const Rigid3d pose = NominalPose("bumper_lidar");
  LidarSimOptions o;
  o.dropout_probability = 0.1;
  absl::StatusOr<LidarSimResult> a = SimulateLidar(Beams("bumper_lidar"), pose, *station_, o, 0, 5);
  absl::StatusOr<LidarSimResult> b = SimulateLidar(Beams("bumper_lidar"), pose, *station_, o, 0, 5);
  absl::StatusOr<LidarSimResult> c = SimulateLidar(Beams("bumper_lidar"), pose, *station_, o, 0, 6);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  EXPECT_EQ(a->scans[0].points, b->scans[0].points);
  EXPECT_NE(a->scans[0].points, c->scans[0].points);
}

// A free-running motor: each rotation's columns fire at their phase-locked azimuths plus the
// rotation's own phase (whole centidegrees within the 0.2 degree step), the same for a seed;
// the default keeps every rotation on the grid from azimuth 0.
TEST_F(SimTest, LidarFreeRunningRotationsFireAtTheirOwnPhase) {
  const Rigid3d pose = NominalPose("bumper_lidar");
  LidarSimOptions o;
  o.rotations = 4;
  o.range_sigma_m = 0;
  absl::StatusOr<LidarSimResult> locked =
      SimulateLidar(Beams("bumper_lidar"), pose, *station_, o, 0, 5);
  o.free_running = true;
  absl::StatusOr<LidarSimResult> a = SimulateLidar(Beams("bumper_lidar"), pose, *station_, o, 0, 5);
  absl::StatusOr<LidarSimResult> b = SimulateLidar(Beams("bumper_lidar"), pose, *station_, o, 0, 5);
  ASSERT_TRUE(locked.ok() && a.ok() && b.ok());
  EXPECT_EQ(a->scans[3].points, b->scans[3].points);
  const int step = SimulatedColumnStepCentideg(LidarModel::kVlp16);
  const std::size_t per_rotation = 36000 / step;
  const std::size_t lead = (locked->columns.size() - 4 * per_rotation) / 2;  // lead-in columns
  std::set<int> phases;
  for (int r = 0; r < 4; ++r) {
    // The column half way through rotation r.
    const std::size_t k = lead + static_cast<std::size_t>(r) * per_rotation + per_rotation / 2;
    EXPECT_EQ(locked->columns[k].azimuth_centideg % step, 0) << r;
    const int phase = a->columns[k].azimuth_centideg - locked->columns[k].azimuth_centideg;
    EXPECT_GE(phase, 0) << r;
    EXPECT_LT(phase, step) << r;
    phases.insert(phase);
  }
  EXPECT_GT(phases.size(), 1u);
}

// Per-laser firing delays, free-running: the simulated packets decode, through the real
// decoder, to points whose azimuths are those of the rays cast. A ray's azimuth is the motor's
// at the column (the packet's azimuth field, each rotation at its own phase) plus the beam's
// calibrated offset plus, on the VLP-16, the turn during the laser's firing delay (laser l
// fires l * 2.304 us into a 55.296 us firing sequence). Hesai's calibrated offsets include
// the delay, as the decoder models them.
TEST_F(SimTest, FreeRunningPacketsDecodeToTheAzimuthsOfTheRaysCast) {
  for (const char* sensor : {"roof_lidar", "bumper_lidar"}) {
    const LidarBeamTable beams = Beams(sensor);
    const LidarModelInfo& info = GetLidarModelInfo(beams.model);
    LidarSimOptions o;
    o.rotations = 3;
    o.free_running = true;
    constexpr std::int64_t kStartNs = 1'700'000'000'000'000'000;  // Hesai dates need a year
    absl::StatusOr<LidarSimResult> sim =
        SimulateLidar(beams, NominalPose(sensor), *station_, o, kStartNs, 9);
    ASSERT_TRUE(sim.ok()) << sim.status();
    const auto packets = EncodeLidarPackets(sim->encode, sim->columns);
    ASSERT_TRUE(packets.ok()) << packets.status();
    absl::StatusOr<LidarDecoder> decoder = LidarDecoder::Create(beams);
    ASSERT_TRUE(decoder.ok());
    std::vector<LidarScan> scans;
    for (const std::vector<std::uint8_t>& p : *packets)
      decoder->AddPacket(p, sim->encode.first_column_time_ns, &scans);
    decoder->Finish(&scans);
    EXPECT_EQ(decoder->stats().skipped_total(), 0);
    ASSERT_EQ(scans.size(), 3u) << sensor;
    std::map<int, int> channel_of_ring;
    for (std::size_t ch = 0; ch < beams.beams.size(); ++ch)
      channel_of_ring[beams.beams[ch].ring] = static_cast<int>(ch);
    const double step_deg = SimulatedColumnStepCentideg(beams.model) / 100.0;
    std::set<int> phases;
    int points = 0;
    for (int r = 0; r < 3; ++r) {
      const std::vector<LidarPoint>& cast = sim->scans[r].points;
      const std::vector<LidarPoint>& got = scans[r].points;
      ASSERT_EQ(got.size(), cast.size()) << sensor << " rotation " << r;
      for (std::size_t i = 0; i < got.size(); ++i) {
        // The ray: its column from the firing time the simulator stamped (exact ns).
        const int ch = channel_of_ring.at(cast[i].ring);
        const LidarBeam& beam = beams.beams[ch];
        const std::int64_t delay_ns = ChannelTimeOffsetNs(beams.model, ch);
        const std::int64_t since_first =
            cast[i].time_ns - delay_ns - sim->encode.first_column_time_ns;
        ASSERT_EQ(since_first % info.column_period_ns, 0) << sensor << " point " << i;
        const LidarColumn& column = sim->columns[since_first / info.column_period_ns];
        phases.insert(column.azimuth_centideg % SimulatedColumnStepCentideg(beams.model));
        const double turn_deg =
            beams.model == LidarModel::kVlp16
                ? step_deg * static_cast<double>(delay_ns) / info.column_period_ns
                : 0.0;
        const double ray_deg =
            column.azimuth_centideg / 100.0 + beam.azimuth_offset_rad / kDegToRad + turn_deg;
        const double got_deg = std::atan2(got[i].x, got[i].y) / kDegToRad;
        const double diff = std::remainder(got_deg - ray_deg, 360.0);
        ASSERT_NEAR(diff, 0.0, 1e-4) << sensor << " rotation " << r << " point " << i;
        ASSERT_EQ(got[i].ring, cast[i].ring);
        ++points;
      }
    }
    EXPECT_GT(points, 10000) << sensor;
    EXPECT_GT(phases.size(), 1u) << sensor;  // the rotations did fire at their own phases
  }
}

TEST_F(SimTest, LidarOptionsErrorsNameTheField) {
  LidarSimOptions o;
  o.range_sigma_m = -1;
  EXPECT_EQ(o.Validate().message(), "range_sigma_m = -1: must be in [0, 1]");
  o = {};
  o.rotations = 0;
  EXPECT_EQ(o.Validate().message(), "rotations = 0: must be in [1, 100]");
}

// The capture's pcap decodes, through the real decoder, to the capture's PCD points.
TEST_F(SimTest, PacketsDecodeToTheSimulatedPoints) {
  for (const char* sensor : {"roof_lidar", "bumper_lidar"}) {
    SimulatorOptions o;
    o.sensors = {sensor};
    o.lidar.rotations = 2;
    const fs::path dir = fs::path(testing::TempDir()) / (std::string("sim_pcap_") + sensor);
    absl::StatusOr<SimulationSummary> sim = SimulateCapture(*station_, *car_, o, 11, dir.string());
    ASSERT_TRUE(sim.ok()) << sim.status();
    const CaptureSensor& entry = sim->manifest.sensors[0];
    ASSERT_TRUE(entry.packets.has_value());
    ASSERT_EQ(entry.frames.size(), 2u);
    absl::StatusOr<LidarDecoder> decoder = LidarDecoder::Create(Beams(sensor));
    ASSERT_TRUE(decoder.ok());
    std::vector<LidarScan> scans;
    LidarPcapStats stats;
    ASSERT_TRUE(DecodeLidarPcap(
                    dir / entry.packets->path, {}, &*decoder,
                    [&](LidarScan&& s) {
                      scans.push_back(std::move(s));
                      return absl::OkStatus();
                    },
                    &stats)
                    .ok());
    EXPECT_EQ(decoder->stats().skipped_total(), 0);
    ASSERT_EQ(scans.size(), 2u) << sensor;
    for (int r = 0; r < 2; ++r) {
      absl::StatusOr<PcdCloud> pcd = ReadPcd(dir / entry.frames[r].path);
      ASSERT_TRUE(pcd.ok());
      const std::vector<LidarPoint>& expected = pcd->points;
      const std::vector<LidarPoint>& got = scans[r].points;
      ASSERT_EQ(got.size(), expected.size()) << sensor << " rotation " << r;
      for (size_t i = 0; i < got.size(); ++i) {
        // float coordinates of the same metres: rounding of the two computations only.
        ASSERT_NEAR(got[i].x, expected[i].x, 2e-5) << i;
        ASSERT_NEAR(got[i].y, expected[i].y, 2e-5) << i;
        ASSERT_NEAR(got[i].z, expected[i].z, 2e-5) << i;
        ASSERT_EQ(got[i].ring, expected[i].ring) << i;
        ASSERT_EQ(got[i].intensity, expected[i].intensity) << i;
        // The packets' time fields have 1 us resolution.
        // (Compared as integers: a double cannot hold ns since the epoch exactly.)
        ASSERT_LE(std::llabs(got[i].time_ns - expected[i].time_ns), 1000) << i;
      }
    }
  }
}

TEST_F(SimTest, RadarFramesDecodeToTheReflectors) {
  for (const char* sensor : {"front_radar", "corner_radar_left"}) {
    const SensorModel* s = car_->FindSensor(sensor);
    const Rigid3d pose = s->T_car_sensor_nominal;
    RadarSimOptions o;
    o.cycles = 50;
    absl::StatusOr<std::vector<CanFrame>> frames =
        SimulateRadar(s->model, s->radar_sensor_id, *station_, pose, CanTime{}, "can0", o, 3);
    ASSERT_TRUE(frames.ok()) << frames.status();
    const RadarDecodeResult decoded =
        DecodeRadarFrames(*frames, *ParseRadarModel(s->model), RadarConventions{});
    EXPECT_EQ(decoded.cycles.size(), 50u);
    for (const RadarCycle& c : decoded.cycles) EXPECT_TRUE(c.complete());
    // Every target reflector: the detections nearest its true position average to the truth.
    for (const RadarTruth& t :
         RadarReflectorTruth(*station_, pose, *RadarFieldOfViewOf(s->model))) {
      if (std::find(s->targets.begin(), s->targets.end(), t.reflector_id) == s->targets.end())
        continue;
      ASSERT_TRUE(t.in_view) << t.reflector_id;
      double sum_az = 0, sum_r = 0;
      int n = 0;
      for (const RadarCycle& c : decoded.cycles) {
        for (const RadarDetection& d : c.detections) {
          // Within 5 sigma of range and azimuth plus the encoding steps (0.2 m, 0.1 deg).
          if (std::abs(d.range_m - t.range_m) < 0.5 &&
              std::abs(d.azimuth_rad - t.azimuth_rad) < 1.0 * kDegToRad) {
            sum_az += d.azimuth_rad;
            sum_r += d.range_m;
            ++n;
          }
        }
      }
      // 98% detection probability over 50 cycles.
      EXPECT_GE(n, 45) << sensor << " " << t.reflector_id;
      // Means of ~50 detections, within 4 standard errors plus the ESR's half angle step
      // (0.05 deg). A detection's spread is the azimuth noise (0.1 deg) and, for the ARS408,
      // its lateral step: DistLat is -102.3 + 0.2 k m, which cannot hold 0, so a reflector on
      // the boresight decodes at +-0.1 m, the sign set by the noise (+-0.1 m / range).
      const double step_rad = 0.1 / t.range_m;
      const double spread_rad = std::hypot(0.1 * kDegToRad, step_rad);
      EXPECT_NEAR(sum_az / n, t.azimuth_rad, 0.05 * kDegToRad + 4 * spread_rad / std::sqrt(n))
          << t.reflector_id;
      EXPECT_NEAR(sum_r / n, t.range_m, 0.06 + 4 * 0.05 / std::sqrt(n)) << t.reflector_id;
    }
  }
}

TEST_F(SimTest, WholeCaptureIsValidAndDeterministic) {
  SimulatorOptions o;
  o.sensors = {"front_camera", "bumper_lidar", "front_radar"};
  const fs::path a = fs::path(testing::TempDir()) / "sim_whole_a";
  const fs::path b = fs::path(testing::TempDir()) / "sim_whole_b";
  absl::StatusOr<SimulationSummary> sa = SimulateCapture(*station_, *car_, o, 21, a.string());
  absl::StatusOr<SimulationSummary> sb = SimulateCapture(*station_, *car_, o, 21, b.string());
  ASSERT_TRUE(sa.ok() && sb.ok()) << sa.status();
  absl::StatusOr<Capture> c = ReadCapture(a.string());
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->manifest.sensors.size(), 3u);
  EXPECT_EQ(sa->ground_truth.dump(), sb->ground_truth.dump());
  for (const char* f :
       {"front_camera/frame-000000.png", "bumper_lidar/packets.pcap", "front_radar/can.log"}) {
    std::ifstream fa(a / f, std::ios::binary), fb(b / f, std::ios::binary);
    const std::string da((std::istreambuf_iterator<char>(fa)), {}),
        db((std::istreambuf_iterator<char>(fb)), {});
    EXPECT_FALSE(da.empty());
    EXPECT_EQ(da, db) << f;
  }
  // The mounting error stays within its bounds, and the true pose is nominal + error.
  for (const auto& s : sa->ground_truth["sensors"]) {
    for (int i = 0; i < 3; ++i) {
      EXPECT_LE(std::abs(s["mounting_error"]["ypr_deg"][i].get<double>()), o.perturb_angle_deg);
      EXPECT_LE(std::abs(s["mounting_error"]["xyz_m"][i].get<double>()), o.perturb_offset_m);
    }
  }
}

// A given aligner measurement is the one the capture records (and the one the truth uses),
// and an implausible one is refused naming the field.
TEST_F(SimTest, GivenAlignerIsUsed) {
  SimulatorOptions o;
  o.sensors = {"front_radar"};
  o.aligner = AlignerMeasurement{0.031, -0.012, 0.1 * kDegToRad};
  const fs::path dir = fs::path(testing::TempDir()) / "sim_given_aligner";
  absl::StatusOr<SimulationSummary> s = SimulateCapture(*station_, *car_, o, 5, dir.string());
  ASSERT_TRUE(s.ok()) << s.status();
  absl::StatusOr<Capture> c = ReadCapture(dir.string());
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_NEAR(c->manifest.aligner.longitudinal_offset_m, 0.031, 1e-12);
  EXPECT_NEAR(c->manifest.aligner.lateral_offset_m, -0.012, 1e-12);
  EXPECT_NEAR(c->manifest.aligner.thrust_angle_rad, 0.1 * kDegToRad, 1e-12);
  o.aligner->lateral_offset_m = 3.0;
  const absl::Status bad = SimulateCapture(*station_, *car_, o, 5, dir.string()).status();
  EXPECT_EQ(bad.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(bad.message().find("aligner.lateral_offset_m"), std::string::npos) << bad;
}

// A given true mounting is the one the truth records (its error from nominal), the other
// sensors' draws stay as they were, and a sensor the car lacks is refused.
TEST_F(SimTest, GivenTrueMountingIsUsed) {
  SimulatorOptions o;
  o.sensors = {"front_radar", "corner_radar_left"};
  const fs::path dir = fs::path(testing::TempDir()) / "sim_true_mounting";
  const absl::StatusOr<SimulationSummary> drawn =
      SimulateCapture(*station_, *car_, o, 7, dir.string());
  ASSERT_TRUE(drawn.ok()) << drawn.status();
  const Rigid3d nominal = NominalPose("front_radar");
  const Eigen::Vector3d offset(0.004, -0.007, 0.002);
  o.true_mountings["front_radar"] = Rigid3d(
      nominal.RotationMatrix() * Eigen::AngleAxisd(0.3 * kDegToRad, Eigen::Vector3d::UnitZ()),
      nominal.translation() + offset);
  const absl::StatusOr<SimulationSummary> given =
      SimulateCapture(*station_, *car_, o, 7, dir.string());
  ASSERT_TRUE(given.ok()) << given.status();
  const nlohmann::json& truth = given->ground_truth["sensors"][0]["mounting_error"];
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(truth["xyz_m"][i].get<double>(), offset[i], 1e-12);
  // The radar's z axis is the car's: a turn about it is a yaw error alone.
  EXPECT_NEAR(std::abs(truth["ypr_deg"][0].get<double>()), 0.3, 1e-9);
  EXPECT_NEAR(truth["ypr_deg"][1].get<double>(), 0.0, 1e-9);
  EXPECT_NEAR(truth["ypr_deg"][2].get<double>(), 0.0, 1e-9);
  EXPECT_EQ(given->ground_truth["sensors"][1].dump(), drawn->ground_truth["sensors"][1].dump());
  o.true_mountings["periscope"] = nominal;
  const absl::Status bad = SimulateCapture(*station_, *car_, o, 7, dir.string()).status();
  EXPECT_EQ(bad.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(bad.message().find("true_mountings"), std::string::npos) << bad;
}

TEST_F(SimTest, UnknownSensorIsRefused) {
  SimulatorOptions o;
  o.sensors = {"periscope"};
  absl::StatusOr<SimulationSummary> s =
      SimulateCapture(*station_, *car_, o, 1, (fs::path(testing::TempDir()) / "sim_bad").string());
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().message(), "car model 'reference' has no sensor 'periscope'");
}

}  // namespace
}  // namespace linecal

// The station core with the live source: a car of the reference front camera, roof LiDAR and
// front radar, each served by a real source — the LiDAR by the UDP source receiving the
// simulator's Pandar64 packets from a sender thread on 127.0.0.1, the radar by the candump
// source replaying the simulator's log, the camera by a small SensorSource of this test that
// copies the simulator's PNG renders (the Aravis and V4L2 sources are tested on their own) —
// into a real SQLite store. Live cycles give what `linecal calibrate` gives for their recording;
// a silent sensor gives that sensor error and the others their verdicts; cancel is prompt;
// a calibration past its deadline ends the cycle in error; configurations name the key.
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>
#include <thread>
#include <vector>

#include "daemon/core/station_core.h"
#include "station/capture/capture.h"
#include "station/pipeline/capture_calibration.h"
#include "station/sim/simulator.h"
#include "tests/daemon/loopback_udp.h"
#include "tests/daemon/scratch_dir.h"
#include "tests/daemon/test_car.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using testing_daemon::LoopingSender;
using Clock = std::chrono::steady_clock;
const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
constexpr char kVin[] = "1M8GDM9AXKP042788";

// A camera source that copies recorded PNG frames (cycling through them) into the capture.
class PngCopySource : public SensorSource {
 public:
  explicit PngCopySource(std::vector<std::string> frames) : frames_(std::move(frames)) {}
  absl::StatusOr<CaptureSensor> Acquire(const SensorModel& sensor,
                                        const AcquireRequest& request) override {
    CaptureSensor out;
    out.name = sensor.name;
    out.kind = sensor.kind;
    fs::create_directories(fs::path(request.capture_dir) / request.sensor_dir);
    for (int k = 0; k < request.frames; ++k) {
      if (request.cancelled()) return absl::CancelledError("cancelled");
      const std::string rel =
          (fs::path(request.sensor_dir) / ("frame_" + std::to_string(k) + ".png")).string();
      std::error_code ec;
      fs::copy_file(frames_[k % frames_.size()], fs::path(request.capture_dir) / rel, ec);
      if (ec) return absl::InternalError(ec.message());
      out.frames.push_back({rel, 1'700'000'000'000'000'000 + k * 100'000'000LL});
    }
    return out;
  }
  std::string Describe() const override { return "png copies"; }

 private:
  const std::vector<std::string> frames_;
};

class StationCoreLiveTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_daemon::FreshTestDir("live");
    // The reference car cut down to one sensor of each kind.
    testing_daemon::WriteCutDownCar((dir_ / "car.json").string(),
                                    {"front_camera", "roof_lidar", "front_radar"}, "three_sensor");

    // The simulator's recording of the car: what the devices send.
    SimulatorOptions o;
    o.lidar.rotations = 2;
    o.aligner = Request().aligner;  // the car stands where the cycle's request says
    const CarModel model = *ReadCarModel((dir_ / "car.json").string());
    ASSERT_TRUE(SimulateCapture(*ReadStationLayout(kDeploy + "/stations/reference.json"), model, o,
                                3, (dir_ / "sim").string())
                    .ok());

    port_ = testing_daemon::FreeUdpPort();
    config_.station_path = kDeploy + "/stations/reference.json";
    config_.car_model_paths = {(dir_ / "car.json").string()};
    config_.db_path = (dir_ / "station.db").string();
    config_.data_root = (dir_ / "data").string();
    config_.source = CycleSource::kLive;
    SourceConfig camera;
    camera.type = SourceType::kAravis;
    camera.aravis.device_id = "Aravis-Fake-TEST01";
    SourceConfig lidar;
    lidar.type = SourceType::kUdp;
    lidar.udp.bind_address = "127.0.0.1";
    lidar.udp.port = port_;
    SourceConfig radar;
    radar.type = SourceType::kCandump;
    radar.can.log_path = (dir_ / "sim/front_radar/can.log").string();
    config_.live_sources = {
        {"front_camera", camera}, {"roof_lidar", lidar}, {"front_radar", radar}};
    // The camera from the simulator's renders; the others as the daemon builds them.
    const std::string render = (dir_ / "sim/front_camera/frame-000000.png").string();
    config_.make_source =
        [render](const std::string& sensor,
                 const SourceConfig& c) -> absl::StatusOr<std::unique_ptr<SensorSource>> {
      if (sensor == "front_camera")
        return std::make_unique<PngCopySource>(std::vector<std::string>{render});
      return MakeSensorSource(c);
    };
    config_.acquire_deadline = std::chrono::milliseconds(5000);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::unique_ptr<StationCore> Core() {
    absl::StatusOr<std::unique_ptr<StationCore>> core = StationCore::Create(config_);
    EXPECT_TRUE(core.ok()) << core.status();
    return core.ok() ? std::move(*core) : nullptr;
  }

  static CycleRequest Request() {
    CycleRequest r;
    r.vin = kVin;
    r.car_model_id = "three_sensor";
    r.aligner = {0.012, -0.008, 0.05 * std::numbers::pi / 180};
    r.record_capture = true;
    r.frames_per_sensor = 2;  // two rotations: one leaves the LiDAR's pose too uncertain
    return r;
  }

  // The cycle's events as "type:sensor"; `arrivals`, when given, gets each one's arrival time.
  std::vector<std::string> Events(StationCore& core, int64_t id,
                                  std::map<std::string, Clock::time_point>* arrivals = nullptr) {
    std::vector<std::string> types;
    EXPECT_TRUE(core.WatchCycle(id,
                                [&](const StoredEvent& e) {
                                  types.push_back(
                                      EventTypeName(e.type) +
                                      std::string(e.sensor.empty() ? "" : ":" + e.sensor));
                                  if (arrivals != nullptr)
                                    arrivals->emplace(types.back(), Clock::now());
                                  return true;
                                })
                    .ok());
    return types;
  }

  static bool Has(const std::vector<std::string>& v, const std::string& x) {
    return std::find(v.begin(), v.end(), x) != v.end();
  }

  fs::path dir_;
  std::uint16_t port_ = 0;
  StationCoreConfig config_;
};

constexpr double kDeg = 180.0 / std::numbers::pi;

// Every stored field of `offline`'s sensors, bit for bit.
void ExpectStoredEqualsOffline(const StoredCycle& stored, const CycleCalibration& offline) {
  for (const SensorCalibration& s : offline.sensors) {
    SCOPED_TRACE(s.name);
    const StoredSensorResult* r = nullptr;
    for (const StoredSensorResult& x : stored.sensors) {
      if (x.sensor == s.name) r = &x;
    }
    ASSERT_NE(r, nullptr);
    EXPECT_EQ(r->kind, s.kind);
    EXPECT_EQ(r->verdict, s.verdict == Verdict::kPass   ? Verdict::kPass
                          : s.verdict == Verdict::kFail ? Verdict::kFail
                                                        : Verdict::kError);
    EXPECT_EQ(r->reason, s.reason);
    EXPECT_EQ(r->message, s.message);
    EXPECT_EQ(r->features_used, s.features_used);
    EXPECT_EQ(r->residual_rms, s.residual_rms);
    ASSERT_EQ(r->T_car_sensor.size(), s.solved ? 16u : 0u);
    if (!s.solved) continue;
    const Eigen::Matrix4d T = s.mounting.T_car_sensor.Matrix();
    for (int i = 0; i < 16; ++i) EXPECT_EQ(r->T_car_sensor[i], T(i / 4, i % 4)) << i;
    EXPECT_EQ(r->measured.yaw_deg, s.mounting.angles.yaw * kDeg);
    EXPECT_EQ(r->measured.pitch_deg, s.mounting.angles.pitch * kDeg);
    EXPECT_EQ(r->measured.roll_deg, s.mounting.angles.roll * kDeg);
    EXPECT_EQ(r->measured.x_m, s.mounting.position_m.x());
    EXPECT_EQ(r->deviation.yaw_deg, s.mounting.angles_deviation.yaw * kDeg);
    EXPECT_EQ(r->deviation.z_m, s.mounting.position_deviation_m.z());
    EXPECT_EQ(r->sigma.yaw_deg, s.mounting.sigma[0] * kDeg);
    EXPECT_EQ(r->sigma.z_m, s.mounting.sigma[5]);
    EXPECT_EQ(r->vanishing_point_u_px.has_value(), s.vanishing_point_px.has_value());
    if (s.vanishing_point_px) {
      EXPECT_EQ(*r->vanishing_point_u_px, s.vanishing_point_px->x());
    }
    EXPECT_EQ(r->ground_homography.size(), s.ground_homography ? 9u : 0u);
  }
}

TEST_F(StationCoreLiveTest, LiveCycleEqualsTheOfflineCalibrationOfItsRecording) {
  std::unique_ptr<StationCore> core = Core();
  ASSERT_NE(core, nullptr);
  const StationStatusInfo status = core->Status();
  EXPECT_EQ(status.source, "live");
  EXPECT_EQ(status.sensor_sources.at("roof_lidar"), "udp 127.0.0.1:" + std::to_string(port_));
  EXPECT_EQ(status.sensor_sources.at("front_radar"),
            "candump " + (dir_ / "sim/front_radar/can.log").string());
  EXPECT_EQ(status.sensor_sources.at("front_camera"), "png copies");

  // Sending starts once the cycle has bound its socket, so the first rotation it completes is
  // the recording's first, not one spliced across the loop.
  absl::StatusOr<std::vector<testing_daemon::Payload>> packets =
      testing_daemon::PcapPayloads((dir_ / "sim/roof_lidar/packets.pcap").string());
  ASSERT_TRUE(packets.ok()) << packets.status();
  LoopingSender sender(port_, *std::move(packets), testing_daemon::SendStart::kWhenBound);
  absl::StatusOr<int64_t> id = core->StartCycle(Request());
  ASSERT_TRUE(id.ok()) << id.status();
  const std::vector<std::string> events = Events(*core, *id);
  for (const char* sensor : {"front_camera", "roof_lidar", "front_radar"}) {
    EXPECT_TRUE(Has(events, std::string("sensor_acquired:") + sensor)) << sensor;
    EXPECT_TRUE(Has(events, std::string("sensor_verdict:") + sensor)) << sensor;
  }
  EXPECT_TRUE(Has(events, "sensor_progress:roof_lidar"));
  EXPECT_TRUE(Has(events, "sensor_progress:front_radar"));

  absl::StatusOr<StoredCycle> cycle = core->GetCycle(*id);
  ASSERT_TRUE(cycle.ok());
  EXPECT_EQ(cycle->state, CycleState::kDone);
  ASSERT_EQ(cycle->sensors.size(), 3u);
  absl::StatusOr<Capture> capture =
      ReadCapture((fs::path(config_.data_root) / cycle->capture_path).string());
  ASSERT_TRUE(capture.ok()) << capture.status();
  EXPECT_EQ(capture->manifest.origin, "station");
  EXPECT_EQ(capture->manifest.vin, kVin);
  EXPECT_DOUBLE_EQ(capture->manifest.aligner.lateral_offset_m, -0.008);
  ASSERT_EQ(capture->manifest.sensors.size(), 3u);
  EXPECT_EQ(capture->manifest.FindSensor("roof_lidar")->frames.size(), 2u);
  EXPECT_EQ(capture->manifest.FindSensor("front_camera")->frames.size(), 2u);
  EXPECT_TRUE(capture->manifest.FindSensor("roof_lidar")->packets.has_value());
  absl::StatusOr<CycleCalibration> offline = CalibrateCapture(*capture);
  ASSERT_TRUE(offline.ok());
  ExpectStoredEqualsOffline(*cycle, *offline);
  EXPECT_EQ(cycle->verdict, offline->verdict == Verdict::kPass   ? Verdict::kPass
                            : offline->verdict == Verdict::kFail ? Verdict::kFail
                                                                 : Verdict::kError);
  // The simulated car is within tolerance: every sensor passes through the live path.
  for (const StoredSensorResult& r : cycle->sensors)
    EXPECT_EQ(r.verdict, Verdict::kPass) << r.sensor << " " << r.reason;
}

TEST_F(StationCoreLiveTest, SilentLidarIsThatSensorsErrorAndTheOthersGetTheirVerdicts) {
  config_.acquire_deadline = std::chrono::milliseconds(1500);
  std::unique_ptr<StationCore> core = Core();
  ASSERT_NE(core, nullptr);
  const auto start = Clock::now();
  absl::StatusOr<int64_t> id = core->StartCycle(Request());  // nothing sends to the LiDAR's port
  ASSERT_TRUE(id.ok());
  std::map<std::string, Clock::time_point> arrivals;
  const std::vector<std::string> events = Events(*core, *id, &arrivals);
  // The silent sensor is given up at its deadline (1.5 s), not at the end of the others' work:
  // timed to that event, so a slow (sanitized, loaded) calibration of the others does not count.
  ASSERT_TRUE(arrivals.contains("sensor_error:roof_lidar"));
  EXPECT_LT(std::chrono::duration<double>(arrivals["sensor_error:roof_lidar"] - start).count(),
            4.0);
  EXPECT_TRUE(Has(events, "sensor_error:roof_lidar"));
  EXPECT_TRUE(Has(events, "sensor_acquired:front_camera"));
  EXPECT_TRUE(Has(events, "sensor_acquired:front_radar"));

  absl::StatusOr<StoredCycle> cycle = core->GetCycle(*id);
  ASSERT_TRUE(cycle.ok());
  EXPECT_EQ(cycle->state, CycleState::kDone);
  EXPECT_EQ(cycle->verdict, Verdict::kError);
  ASSERT_EQ(cycle->sensors.size(), 3u);
  const std::string why =
      "roof_lidar: no packets from 127.0.0.1:" + std::to_string(port_) + " in 1.5 s";
  for (const StoredSensorResult& r : cycle->sensors) {
    if (r.sensor != "roof_lidar") continue;
    EXPECT_EQ(r.kind, SensorKind::kLidar);
    EXPECT_EQ(r.verdict, Verdict::kError);
    EXPECT_EQ(r.reason, "acquisition_failed: " + why);
    EXPECT_EQ(r.message, why);
  }
  EXPECT_NE(cycle->reason.find("roof_lidar:acquisition_failed: " + why), std::string::npos)
      << cycle->reason;
  // The recording holds the two sensors acquired, and they have the offline results.
  absl::StatusOr<Capture> capture =
      ReadCapture((fs::path(config_.data_root) / cycle->capture_path).string());
  ASSERT_TRUE(capture.ok()) << capture.status();
  EXPECT_EQ(capture->manifest.sensors.size(), 2u);
  EXPECT_EQ(capture->manifest.FindSensor("roof_lidar"), nullptr);
  absl::StatusOr<CycleCalibration> offline = CalibrateCapture(*capture);
  ASSERT_TRUE(offline.ok());
  ASSERT_EQ(offline->sensors.size(), 2u);
  ExpectStoredEqualsOffline(*cycle, *offline);
  for (const SensorCalibration& s : offline->sensors)
    EXPECT_EQ(s.verdict, Verdict::kPass) << s.name;
}

TEST_F(StationCoreLiveTest, CancelDuringAcquisitionEndsTheCycleWithinASecond) {
  config_.acquire_deadline = std::chrono::milliseconds(20000);
  std::unique_ptr<StationCore> core = Core();
  ASSERT_NE(core, nullptr);
  CycleRequest request = Request();
  request.record_capture = false;
  absl::StatusOr<int64_t> id = core->StartCycle(request);  // the LiDAR is silent: acquisition waits
  ASSERT_TRUE(id.ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const auto cancelled = Clock::now();
  ASSERT_TRUE(core->CancelCycle(*id).ok());
  core->WaitIdle();
  EXPECT_LT(std::chrono::duration<double>(Clock::now() - cancelled).count(), 1.0);
  absl::StatusOr<StoredCycle> cycle = core->GetCycle(*id);
  ASSERT_TRUE(cycle.ok());
  EXPECT_EQ(cycle->state, CycleState::kCancelled);
  EXPECT_EQ(cycle->reason, "cancelled");
  EXPECT_TRUE(cycle->sensors.empty());
  // Not recorded: the capture is gone.
  EXPECT_FALSE(fs::exists(fs::path(config_.data_root) / cycle->capture_path));
}

TEST_F(StationCoreLiveTest, CalibrationPastItsDeadlineEndsTheCycleInError) {
  config_.calibrate_deadline = std::chrono::milliseconds(1);
  std::unique_ptr<StationCore> core = Core();
  ASSERT_NE(core, nullptr);
  absl::StatusOr<std::vector<testing_daemon::Payload>> packets =
      testing_daemon::PcapPayloads((dir_ / "sim/roof_lidar/packets.pcap").string());
  ASSERT_TRUE(packets.ok()) << packets.status();
  LoopingSender sender(port_, *std::move(packets), testing_daemon::SendStart::kWhenBound);
  absl::StatusOr<int64_t> id = core->StartCycle(Request());
  ASSERT_TRUE(id.ok());
  core->WaitIdle();
  absl::StatusOr<StoredCycle> cycle = core->GetCycle(*id);
  ASSERT_TRUE(cycle.ok());
  EXPECT_EQ(cycle->state, CycleState::kDone);
  EXPECT_EQ(cycle->verdict, Verdict::kError);
  EXPECT_EQ(cycle->reason, "calibrate_deadline_exceeded");
  EXPECT_TRUE(cycle->sensors.empty());
  // The calibration was stopped and joined before the cycle ended (StationCoreFaultTest
  // measures the threads); the core goes without waiting for it.
  core.reset();
}

TEST_F(StationCoreLiveTest, SourceConfigurationErrorsNameTheSensor) {
  StationCoreConfig c = config_;
  c.live_sources.erase("roof_lidar");
  absl::Status s = StationCore::Create(c).status();
  EXPECT_TRUE(absl::IsInvalidArgument(s));
  EXPECT_EQ(s.message(),
            "source.sensors: no source for sensor 'roof_lidar' of car model 'three_sensor'");

  c = config_;
  c.live_sources["roof_lidar"].type = SourceType::kAravis;
  s = StationCore::Create(c).status();
  EXPECT_EQ(s.message(),
            "source.sensors.roof_lidar.type: 'aravis' serves cameras, but 'roof_lidar' of car "
            "model 'three_sensor' is a "
            "lidar");

  c = config_;
  c.live_sources["rear_lidar"] = c.live_sources["roof_lidar"];
  s = StationCore::Create(c).status();
  EXPECT_EQ(s.message(), "source.sensors.rear_lidar: no car model has a sensor 'rear_lidar'");

  c = config_;
  c.live_sources["front_radar"].can.log_path.clear();
  s = StationCore::Create(c).status();
  EXPECT_TRUE(absl::IsInvalidArgument(s));
  EXPECT_EQ(s.message(), "source.sensors.front_radar.log: empty");

  c = config_;
  c.acquire_deadline = std::chrono::milliseconds(0);
  EXPECT_TRUE(absl::IsInvalidArgument(StationCore::Create(c).status()));
}

}  // namespace
}  // namespace linecal

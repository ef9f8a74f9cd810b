#include "station/sim/simulator.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numbers>
#include <random>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "station/io/candump.h"
#include "station/io/image_io.h"
#include "station/io/json_reader.h"
#include "station/io/pcap.h"
#include "station/model/pose_json.h"
#include "station/model/vin.h"
#include "station/sensors/lidar/pcd.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
constexpr double kDegToRad = std::numbers::pi / 180.0;
// Frames of one camera are taken this far apart (a 30 fps camera).
constexpr std::int64_t kFramePeriodNs = 33'333'333;

absl::Status CheckBound(const char* field, double v, double hi) {
  if (!(v >= 0 && v <= hi)) {
    return absl::InvalidArgumentError(absl::StrCat(field, " = ", v, ": must be in [0, ", hi, "]"));
  }
  return absl::OkStatus();
}

// One random stream per sensor: (seed, index) mixed by SplitMix64's finaliser.
std::uint64_t StreamSeed(std::uint64_t seed, std::uint64_t index) {
  std::uint64_t z = seed + 0x9E3779B97F4A7C15ull * (index + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

absl::Status Prefix(const std::string& prefix, const absl::Status& s) {
  return absl::Status(s.code(), absl::StrCat(prefix, ": ", s.message()));
}

struct SensorOutput {
  CaptureSensor entry;
  nlohmann::json truth;
};

absl::StatusOr<SensorOutput> SimulateCamera(const SensorModel& sensor,
                                            const Rigid3d& T_station_sensor,
                                            const StationLayout& station, const SimulatorOptions& o,
                                            std::uint64_t stream, const fs::path& dir) {
  absl::StatusOr<CameraModel> camera = CameraModel::Create(*sensor.intrinsics);
  if (!camera.ok()) return Prefix(sensor.name, camera.status());
  fs::create_directories(dir / sensor.name);
  SensorOutput out;
  out.entry.name = sensor.name;
  out.entry.kind = SensorKind::kCamera;
  nlohmann::json frames = nlohmann::json::array();
  for (int f = 0; f < o.camera_frames; ++f) {
    absl::StatusOr<CameraFrame> frame =
        RenderCameraFrame(*camera, T_station_sensor, station, o.camera, StreamSeed(stream, f));
    if (!frame.ok()) return Prefix(sensor.name, frame.status());
    const std::string rel = absl::StrFormat("%s/frame-%06d.png", sensor.name, f);
    const absl::Status written = frame->bit_depth == 16
                                     ? WritePng16((dir / rel).string(), frame->image16.view())
                                     : WritePng8((dir / rel).string(), frame->image8.view());
    if (!written.ok()) return written;
    out.entry.frames.push_back({rel, o.time_ns + f * kFramePeriodNs});
    nlohmann::json features = nlohmann::json::array();
    for (const RenderedFeature& rf : frame->features) {
      features.push_back({{"board", rf.board_id},
                          {"id", rf.feature_id},
                          {"u", rf.uv_px.x()},
                          {"v", rf.uv_px.y()}});
    }
    frames.push_back(
        {{"path", rel}, {"occluders", frame->occluders.size()}, {"features", std::move(features)}});
  }
  out.truth["frames"] = std::move(frames);
  return out;
}

absl::StatusOr<SensorOutput> SimulateLidarSensor(const SensorModel& sensor,
                                                 const Rigid3d& T_station_sensor,
                                                 const StationLayout& station,
                                                 const SimulatorOptions& o, std::uint64_t stream,
                                                 const fs::path& dir) {
  absl::StatusOr<LidarBeamTable> beams = LidarBeamTableOf(sensor);
  if (!beams.ok()) return Prefix(sensor.name, beams.status());
  const LidarModel model = beams->model;
  absl::StatusOr<LidarSimResult> sim =
      SimulateLidar(*beams, T_station_sensor, station, o.lidar, o.time_ns, stream);
  if (!sim.ok()) return Prefix(sensor.name, sim.status());
  fs::create_directories(dir / sensor.name);
  SensorOutput out;
  out.entry.name = sensor.name;
  out.entry.kind = SensorKind::kLidar;
  if (o.lidar_pcd) {
    for (size_t r = 0; r < sim->scans.size(); ++r) {
      const std::string rel = absl::StrFormat("%s/scan-%06d.pcd", sensor.name, r);
      if (absl::Status s = WritePcd(dir / rel, sim->scans[r].points); !s.ok()) return s;
      out.entry.frames.push_back({rel, sim->scans[r].stamp_ns});
    }
  }
  if (o.lidar_pcap) {
    const std::string rel = sensor.name + "/packets.pcap";
    absl::StatusOr<PcapWriter> writer = PcapWriter::Create(dir / rel);
    if (!writer.ok()) return writer.status();
    const LidarModelInfo& info = GetLidarModelInfo(model);
    UdpEndpoints endpoints;
    endpoints.dst_port = info.default_udp_port;
    endpoints.src_port = info.default_udp_port;
    absl::StatusOr<std::vector<std::vector<std::uint8_t>>> packets =
        EncodeLidarPackets(sim->encode, sim->columns);
    if (!packets.ok()) return Prefix(sensor.name, packets.status());
    const int per_packet = ColumnsPerPacket(model, 1);
    for (size_t p = 0; p < packets->size(); ++p) {
      // A packet leaves the sensor when its last column has fired.
      const std::int64_t t =
          sim->encode.first_column_time_ns +
          static_cast<std::int64_t>((p + 1) * per_packet - 1) * info.column_period_ns;
      if (absl::Status s = writer->WriteUdp(t, endpoints, (*packets)[p]); !s.ok()) return s;
    }
    if (absl::Status s = writer->Close(); !s.ok()) return s;
    out.entry.packets = CaptureFile{rel, sim->encode.first_column_time_ns};
  }
  // Ground truth: where each target board and its features are in the LiDAR frame.
  const Rigid3d T_sensor_station = T_station_sensor.Inverse();
  nlohmann::json boards = nlohmann::json::array();
  for (const std::string& id : sensor.targets) {
    const StationBoard* b = station.FindBoard(id);
    const Rigid3d T_lidar_board = T_sensor_station * b->T_station_board;
    nlohmann::json features = nlohmann::json::array();
    for (const BoardFeature& f : b->board.features()) {
      if (f.kind != FeatureKind::kHoleCentre) continue;
      const Eigen::Vector3d p = T_lidar_board * Eigen::Vector3d(f.p_board.x(), f.p_board.y(), 0);
      features.push_back({{"id", f.id}, {"p", {p.x(), p.y(), p.z()}}});
    }
    boards.push_back({{"board", id},
                      {"T_lidar_board", MatrixToJson(T_lidar_board.Matrix())},
                      {"holes", features}});
  }
  out.truth["boards"] = std::move(boards);
  return out;
}

absl::StatusOr<SensorOutput> SimulateRadarSensor(const SensorModel& sensor,
                                                 const Rigid3d& T_station_sensor,
                                                 const StationLayout& station,
                                                 const SimulatorOptions& o, std::uint64_t stream,
                                                 const fs::path& dir) {
  const CanTime start{std::chrono::nanoseconds(o.time_ns)};
  absl::StatusOr<std::vector<CanFrame>> frames =
      SimulateRadar(sensor.model, sensor.radar_sensor_id, station, T_station_sensor, start, "can0",
                    o.radar, stream);
  if (!frames.ok()) return Prefix(sensor.name, frames.status());
  fs::create_directories(dir / sensor.name);
  const std::string rel = sensor.name + "/can.log";
  if (absl::Status s = WriteCandumpLog(dir / rel, *frames); !s.ok()) return s;
  SensorOutput out;
  out.entry.name = sensor.name;
  out.entry.kind = SensorKind::kRadar;
  out.entry.can_log = CaptureFile{rel, o.time_ns};
  nlohmann::json reflectors = nlohmann::json::array();
  for (const RadarTruth& t :
       RadarReflectorTruth(station, T_station_sensor, *RadarFieldOfViewOf(sensor.model))) {
    reflectors.push_back({{"id", t.reflector_id},
                          {"range_m", t.range_m},
                          {"azimuth_deg", t.azimuth_rad / kDegToRad},
                          {"in_view", t.in_view}});
  }
  out.truth["reflectors"] = std::move(reflectors);
  return out;
}

}  // namespace

absl::Status SimulatorOptions::Validate() const {
  if (absl::Status s = ValidateVin(vin, false); !s.ok())
    return absl::InvalidArgumentError(absl::StrCat("vin: ", s.message()));
  if (time_ns < 0) return absl::InvalidArgumentError("time_ns: must be >= 0");
  // Mounting errors beyond 10 degrees or 0.5 m are not mounting errors but another car.
  if (auto s = CheckBound("perturb_angle_deg", perturb_angle_deg, 10); !s.ok()) return s;
  if (auto s = CheckBound("perturb_offset_m", perturb_offset_m, 0.5); !s.ok()) return s;
  // The aligner's own plausibility bounds (aligner.h).
  if (auto s = CheckBound("aligner_offset_m", aligner_offset_m, 1.0); !s.ok()) return s;
  if (auto s = CheckBound("aligner_thrust_deg", aligner_thrust_deg, 10); !s.ok()) return s;
  if (aligner) {
    if (auto s = CheckBound("aligner.longitudinal_offset_m",
                            std::abs(aligner->longitudinal_offset_m), 1.0);
        !s.ok())
      return s;
    if (auto s = CheckBound("aligner.lateral_offset_m", std::abs(aligner->lateral_offset_m), 1.0);
        !s.ok())
      return s;
    if (auto s = CheckBound("aligner.thrust_angle_deg",
                            std::abs(aligner->thrust_angle_rad) / kDegToRad, 10);
        !s.ok()) {
      return s;
    }
  }
  if (camera_frames < 1 || camera_frames > 100) {
    return absl::InvalidArgumentError(
        absl::StrCat("camera_frames = ", camera_frames, ": must be in [1, 100]"));
  }
  for (size_t i = 0; i < moved_boards.size(); ++i) {
    const MovedBoard& b = moved_boards[i];
    const std::string field = absl::StrCat("moved_boards[", i, "]");
    for (size_t j = 0; j < i; ++j) {
      if (moved_boards[j].board_id == b.board_id) {
        return absl::InvalidArgumentError(
            absl::StrCat(field, ".board_id: '", b.board_id, "' moved twice"));
      }
    }
    for (const double a : {b.yaw_deg, b.pitch_deg, b.roll_deg}) {
      if (auto s = CheckBound((field + ".ypr_deg").c_str(), std::abs(a), 10); !s.ok()) return s;
    }
    if (!b.offset_m.allFinite() || b.offset_m.cwiseAbs().maxCoeff() > 0.5) {
      return absl::InvalidArgumentError(absl::StrCat(field, ".xyz_m: each must be in [-0.5, 0.5]"));
    }
  }
  if (!lidar_pcd && !lidar_pcap)
    return absl::InvalidArgumentError("lidar_pcd, lidar_pcap: at least one must be on");
  if (auto s = camera.Validate(); !s.ok())
    return absl::InvalidArgumentError(absl::StrCat("camera.", s.message()));
  if (auto s = lidar.Validate(); !s.ok())
    return absl::InvalidArgumentError(absl::StrCat("lidar.", s.message()));
  if (auto s = radar.Validate(); !s.ok())
    return absl::InvalidArgumentError(absl::StrCat("radar.", s.message()));
  return absl::OkStatus();
}

namespace {

// The station as it stands: `surveyed` with options.moved_boards applied.
absl::StatusOr<StationLayout> StandingStation(const StationLayout& surveyed,
                                              const SimulatorOptions& options) {
  StationLayout standing = surveyed;
  for (const MovedBoard& move : options.moved_boards) {
    auto board = std::find_if(standing.boards.begin(), standing.boards.end(),
                              [&](const StationBoard& b) { return b.id == move.board_id; });
    if (board == standing.boards.end()) {
      return absl::InvalidArgumentError(
          absl::StrCat("moved_boards: the station has no board '", move.board_id, "'"));
    }
    const Eigen::Matrix3d R_move = RotationFromYawPitchRoll(
        {move.yaw_deg * kDegToRad, move.pitch_deg * kDegToRad, move.roll_deg * kDegToRad});
    board->T_station_board = Rigid3d(R_move * board->T_station_board.RotationMatrix(),
                                     board->T_station_board.translation() + move.offset_m);
  }
  return standing;
}

// The sensors to simulate: options.sensors of `car`, or all of them when empty. Errors:
// InvalidArgument naming a sensor of options.sensors or options.true_mountings the car lacks.
absl::StatusOr<std::vector<const SensorModel*>> SelectedSensors(const CarModel& car,
                                                                const SimulatorOptions& options) {
  std::vector<const SensorModel*> sensors;
  if (options.sensors.empty()) {
    for (const SensorModel& s : car.sensors) sensors.push_back(&s);
  } else {
    for (const std::string& name : options.sensors) {
      const SensorModel* s = car.FindSensor(name);
      if (s == nullptr)
        return absl::InvalidArgumentError(
            absl::StrCat("car model '", car.id, "' has no sensor '", name, "'"));
      sensors.push_back(s);
    }
  }
  for (const auto& [name, pose] : options.true_mountings) {
    if (car.FindSensor(name) == nullptr)
      return absl::InvalidArgumentError(
          absl::StrCat("true_mountings: car model '", car.id, "' has no sensor '", name, "'"));
  }
  return sensors;
}

// A sensor's true mounting and its error from the nominal one (for the ground truth).
struct SensorTruth {
  Rigid3d T_car_sensor;
  YawPitchRoll error;
  Eigen::Vector3d offset;
};

// The true mounting of `sensor`: the nominal mounting angles and position plus a random error
// within options' perturb bounds drawn from `srng`, or options.true_mountings' pose when it
// has one (the error is drawn all the same, so that `srng` goes on as it would).
SensorTruth DrawSensorTruth(const SensorModel& sensor, const SimulatorOptions& options,
                            std::mt19937_64& srng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::Matrix3d r_base = SensorBaseRotation(sensor.kind);
  const YawPitchRoll nominal = MountingAngles(sensor.T_car_sensor_nominal.RotationMatrix(), r_base);
  const double a = options.perturb_angle_deg * kDegToRad;
  SensorTruth t;
  t.error = {a * u(srng), a * u(srng), a * u(srng)};
  // Braced lists evaluate in order (a constructor's parenthesised arguments do not), so the
  // same seed gives the same pose whatever the compiler.
  t.offset = Eigen::Vector3d{options.perturb_offset_m * u(srng), options.perturb_offset_m * u(srng),
                             options.perturb_offset_m * u(srng)};
  const YawPitchRoll truth_angles{nominal.yaw + t.error.yaw, nominal.pitch + t.error.pitch,
                                  nominal.roll + t.error.roll};
  t.T_car_sensor = Rigid3d(MountingRotation(truth_angles, r_base),
                           sensor.T_car_sensor_nominal.translation() + t.offset);
  if (const auto given = options.true_mountings.find(sensor.name);
      given != options.true_mountings.end()) {
    t.T_car_sensor = given->second;
    const YawPitchRoll angles = MountingAngles(t.T_car_sensor.RotationMatrix(), r_base);
    t.error = {angles.yaw - nominal.yaw, angles.pitch - nominal.pitch, angles.roll - nominal.roll};
    t.offset = t.T_car_sensor.translation() - sensor.T_car_sensor_nominal.translation();
  }
  return t;
}

}  // namespace

absl::StatusOr<SimulationSummary> SimulateCapture(const StationLayout& surveyed,
                                                  const CarModel& car,
                                                  const SimulatorOptions& options,
                                                  std::uint64_t seed, const std::string& out_dir,
                                                  const SimulatorProgress& progress) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (absl::Status s = CheckTargetsExist(car, surveyed); !s.ok()) return s;
  // Sensors see the standing station; the capture carries the surveyed one.
  absl::StatusOr<StationLayout> standing = StandingStation(surveyed, options);
  if (!standing.ok()) return standing.status();
  const StationLayout& station = *standing;
  absl::StatusOr<std::vector<const SensorModel*>> selected = SelectedSensors(car, options);
  if (!selected.ok()) return selected.status();
  const std::vector<const SensorModel*>& sensors = *selected;
  const fs::path dir(out_dir);
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return absl::InternalError(absl::StrCat(out_dir, ": cannot create: ", ec.message()));

  // Stream 0 draws the aligner; sensor i (car model order) draws from stream i + 1.
  std::mt19937_64 rng(StreamSeed(seed, 0));
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  SimulationSummary out;
  CaptureManifest& m = out.manifest;
  m.vin = options.vin;
  m.car_model = car.id;
  m.time_ns = options.time_ns;
  m.origin = "simulator";
  if (options.aligner) {
    m.aligner = *options.aligner;
  } else {
    m.aligner.longitudinal_offset_m = options.aligner_offset_m * u(rng);
    m.aligner.lateral_offset_m = options.aligner_offset_m * u(rng);
    m.aligner.thrust_angle_rad = options.aligner_thrust_deg * kDegToRad * u(rng);
  }
  const Rigid3d T_station_car = m.aligner.T_station_car();

  nlohmann::json truth_sensors = nlohmann::json::array();
  int done = 0;
  for (const SensorModel* sensor : sensors) {
    if (options.cancel != nullptr && options.cancel->load()) {
      return absl::CancelledError(absl::StrCat("simulation cancelled before ", sensor->name));
    }
    const size_t index = static_cast<size_t>(sensor - car.sensors.data());
    std::mt19937_64 srng(StreamSeed(seed, index + 1));
    const SensorTruth truth = DrawSensorTruth(*sensor, options, srng);
    const Eigen::Matrix3d r_base = SensorBaseRotation(sensor->kind);
    const YawPitchRoll& error = truth.error;
    const Eigen::Vector3d& offset = truth.offset;
    const Rigid3d& T_car_sensor = truth.T_car_sensor;
    const Rigid3d T_station_sensor = T_station_car * T_car_sensor;
    const std::uint64_t stream = srng();

    absl::StatusOr<SensorOutput> result;
    switch (sensor->kind) {
      case SensorKind::kCamera:
        result = SimulateCamera(*sensor, T_station_sensor, station, options, stream, dir);
        break;
      case SensorKind::kLidar:
        result = SimulateLidarSensor(*sensor, T_station_sensor, station, options, stream, dir);
        break;
      case SensorKind::kRadar:
        result = SimulateRadarSensor(*sensor, T_station_sensor, station, options, stream, dir);
        break;
    }
    if (!result.ok()) return result.status();
    m.sensors.push_back(result->entry);
    nlohmann::json t = result->truth;
    t["name"] = sensor->name;
    t["kind"] = SensorKindName(sensor->kind);
    t["T_car_sensor"] = PoseToJson(T_car_sensor, r_base);
    t["mounting_error"] = {
        {"ypr_deg", {error.yaw / kDegToRad, error.pitch / kDegToRad, error.roll / kDegToRad}},
        {"xyz_m", {offset.x(), offset.y(), offset.z()}}};
    truth_sensors.push_back(std::move(t));
    if (progress) progress(++done, static_cast<int>(sensors.size()), sensor->name);
  }
  out.ground_truth = {{"format", kGroundTruthFormat},
                      {"version", kGroundTruthVersion},
                      {"seed", seed},
                      {"T_station_car", PoseToJson(T_station_car, Eigen::Matrix3d::Identity())},
                      {"sensors", std::move(truth_sensors)}};
  if (!options.moved_boards.empty()) {
    nlohmann::json moved = nlohmann::json::array();
    for (const MovedBoard& b : options.moved_boards) {
      moved.push_back({{"board_id", b.board_id},
                       {"ypr_deg", {b.yaw_deg, b.pitch_deg, b.roll_deg}},
                       {"xyz_m", {b.offset_m.x(), b.offset_m.y(), b.offset_m.z()}}});
    }
    out.ground_truth["moved_boards"] = std::move(moved);
  }
  if (absl::Status s = WriteJsonFile((dir / kCaptureGroundTruthFile).string(), out.ground_truth);
      !s.ok())
    return s;
  if (absl::Status s = WriteCapture(out_dir, m, surveyed, car); !s.ok()) return s;
  return out;
}

}  // namespace linecal

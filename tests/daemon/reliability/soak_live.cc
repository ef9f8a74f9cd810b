#include "tests/daemon/reliability/soak_live.h"

#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <system_error>

#include "absl/strings/str_cat.h"

namespace linecal::reliability {
namespace {

namespace fs = std::filesystem;

// Writes the soak's car cut to its LiDARs and radars, with car model id LiveRig::kCarId.
absl::Status WriteLiveCar(const std::string& car_path, const fs::path& out) {
  std::ifstream in(car_path);
  if (!in) return absl::NotFoundError(absl::StrCat(car_path, ": cannot read"));
  nlohmann::json car = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (car.is_discarded()) return absl::DataLossError(absl::StrCat(car_path, ": not JSON"));
  nlohmann::json kept = nlohmann::json::array();
  for (const nlohmann::json& s : car["sensors"]) {
    if (s.value("kind", "") == "lidar" || s.value("kind", "") == "radar") kept.push_back(s);
  }
  car["sensors"] = kept;
  car["id"] = LiveRig::kCarId;
  std::ofstream o(out);
  o << car.dump(2);
  if (!o) return absl::InternalError(absl::StrCat(out.string(), ": cannot write"));
  return absl::OkStatus();
}

SourceConfig UdpSource(std::uint16_t port) {
  SourceConfig c;
  c.type = SourceType::kUdp;
  c.udp.bind_address = "127.0.0.1";
  c.udp.port = port;
  return c;
}

SourceConfig CandumpSource(const std::string& log) {
  SourceConfig c;
  c.type = SourceType::kCandump;
  c.can.log_path = log;
  return c;
}

}  // namespace

absl::StatusOr<LiveRig> LiveRig::Create(const fs::path& dir, const fs::path& pristine,
                                        const Capture& layout, const std::string& car_path,
                                        const StationCoreConfig& soak_config) {
  LiveRig rig;
  rig.dir_ = dir;
  rig.config_ = soak_config;
  rig.config_.source = CycleSource::kLive;
  rig.config_.replay_capture.clear();
  rig.config_.car_model_paths = {(dir / "live_car.json").string()};
  rig.config_.acquire_deadline = kAcquireDeadline;
  rig.config_.log = [](const LogRecord&) {};  // the faults' errors are expected
  rig.empty_log_ = dir / "silent_can.log";
  std::ofstream(rig.empty_log_).flush();
  for (const CaptureSensor& s : layout.manifest.sensors) {
    if (s.kind == SensorKind::kLidar && s.packets) {
      absl::StatusOr<std::vector<testing_daemon::Payload>> packets =
          testing_daemon::PcapPayloads((pristine / s.packets->path).string());
      if (!packets.ok()) return packets.status();
      rig.packets_[s.name] = *std::move(packets);
      rig.config_.live_sources[s.name] = UdpSource(testing_daemon::FreeUdpPort());
      rig.lidars_.push_back(s.name);
    } else if (s.kind == SensorKind::kRadar && s.can_log) {
      rig.config_.live_sources[s.name] = CandumpSource((pristine / s.can_log->path).string());
      rig.radars_.push_back(s.name);
    }
  }
  if (rig.empty()) return rig;
  if (absl::Status st = WriteLiveCar(car_path, dir / "live_car.json"); !st.ok()) return st;
  return rig;
}

absl::StatusOr<LiveCycle> LiveRig::Run(const CycleRequest& request, const LiveFault& fault) const {
  const fs::path root = dir_ / "live";
  std::error_code ec;
  fs::remove_all(root, ec);
  fs::create_directories(root, ec);
  if (ec) return absl::InternalError(absl::StrCat(root.string(), ": ", ec.message()));
  StationCoreConfig config = config_;
  config.data_root = root.string();
  config.db_path = (root / "station.db").string();
  if (!fault.silent_radar.empty())
    config.live_sources.at(fault.silent_radar).can.log_path = empty_log_.string();
  absl::StatusOr<std::unique_ptr<StationCore>> core = StationCore::Create(config);
  if (!core.ok()) return absl::InternalError(absl::StrCat("live core: ", core.status().ToString()));
  // Each LiDAR sends from when the cycle has bound its port: its first rotation is then the
  // recording's, so an undisturbed LiDAR computes the same every cycle.
  std::vector<std::unique_ptr<testing_daemon::LoopingSender>> senders;
  for (const std::string& lidar : lidars_) {
    senders.push_back(std::make_unique<testing_daemon::LoopingSender>(
        config.live_sources.at(lidar).udp.port, packets_.at(lidar),
        testing_daemon::SendStart::kWhenBound,
        lidar == fault.lidar ? fault.send : testing_daemon::SendFaults{}));
  }
  const auto t0 = std::chrono::steady_clock::now();
  const absl::StatusOr<std::int64_t> id = (*core)->StartCycle(request);
  if (!id.ok()) return absl::InternalError(absl::StrCat("StartCycle: ", id.status().ToString()));
  (*core)->WaitIdle();
  LiveCycle out;
  out.wall = std::chrono::steady_clock::now() - t0;
  senders.clear();
  absl::StatusOr<StoredCycle> stored = (*core)->GetCycle(*id);
  if (!stored.ok())
    return absl::InternalError(absl::StrCat("GetCycle: ", stored.status().ToString()));
  out.stored = *std::move(stored);
  for (StoredSensorResult& r : out.stored.sensors) r.elapsed_ns = 0;
  return out;
}

}  // namespace linecal::reliability

#include "daemon/core/station_core.h"

#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "station/capture/capture.h"
#include "station/model/vin.h"
#include "station/pipeline/capture_calibration.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

constexpr double kRadToDeg = 180.0 / std::numbers::pi;
// The aligner centres a car to centimetres; beyond these it is a wrong unit or a bad reading
// (the bounds of station/model/aligner.h).
constexpr double kMaxAlignerOffsetM = 1.0;
constexpr double kMaxThrustDeg = 10.0;
constexpr int kMaxFramesPerSensor = 100;

std::int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

StoredSensorResult ToStored(const SensorCalibration& s) {
  constexpr double kDeg = kRadToDeg;
  StoredSensorResult r;
  r.sensor = s.name;
  r.kind = s.kind;
  r.verdict = s.verdict;
  r.reason = s.reason;
  r.message = s.message;
  if (s.solved) {
    const MountingEstimate& m = s.mounting;
    const Eigen::Matrix4d T = m.T_car_sensor.Matrix();
    for (int i = 0; i < 4; ++i) {
      for (int j = 0; j < 4; ++j) r.T_car_sensor.push_back(T(i, j));
    }
    r.measured = {m.angles.yaw * kDeg, m.angles.pitch * kDeg, m.angles.roll * kDeg,
                  m.position_m.x(),    m.position_m.y(),      m.position_m.z()};
    r.deviation = {m.angles_deviation.yaw * kDeg,  m.angles_deviation.pitch * kDeg,
                   m.angles_deviation.roll * kDeg, m.position_deviation_m.x(),
                   m.position_deviation_m.y(),     m.position_deviation_m.z()};
    r.sigma = {m.sigma[0] * kDeg, m.sigma[1] * kDeg, m.sigma[2] * kDeg,
               m.sigma[3],        m.sigma[4],        m.sigma[5]};
  }
  r.residual_rms = s.residual_rms;
  r.features_used = s.features_used;
  for (const BoardDetectionSummary& b : s.boards) {
    r.boards.push_back({b.board_id, b.frames, b.frames_found, b.frames_partial, b.residual_rms});
  }
  // By board id, as the store reads them back.
  std::sort(
      r.boards.begin(), r.boards.end(),
      [](const StoredBoardResult& a, const StoredBoardResult& b) { return a.board < b.board; });
  if (s.vanishing_point_px) {
    r.vanishing_point_u_px = s.vanishing_point_px->x();
    r.vanishing_point_v_px = s.vanishing_point_px->y();
  }
  if (s.ground_homography) {
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) r.ground_homography.push_back((*s.ground_homography)(i, j));
    }
  }
  if (!s.ranging.empty()) {
    nlohmann::json ranging = nlohmann::json::array();
    for (const RangingCheck& c : s.ranging) {
      ranging.push_back({{"true_distance_m", c.true_distance_m},
                         {"measured_distance_m", std::isfinite(c.measured_distance_m)
                                                     ? nlohmann::json(c.measured_distance_m)
                                                     : nlohmann::json(nullptr)}});
    }
    r.ranging_json = ranging.dump();
  }
  r.elapsed_ns = s.elapsed_ns;
  return r;
}

// After a kill the captures of the cycles that were acquiring are partial, and nothing
// else removes them (RunCycle removes a capture at the cycle's end): each is removed unless
// its request asked to record it (then it stays, its cycle stored aborted). Only a cycle's
// own captures/<VIN>-<start ns> is touched, never a replayed capture.
void RemoveAbortedCaptures(const std::string& data_root, const std::vector<StoredCycle>& aborted) {
  for (const StoredCycle& c : aborted) {
    if (c.capture_path != absl::StrCat("captures/", c.vin, "-", c.started_ns)) continue;
    const nlohmann::json request =
        nlohmann::json::parse(c.request_json, nullptr, /*allow_exceptions=*/false);
    const nlohmann::json record =
        request.is_object() ? request.value("record_capture", nlohmann::json()) : nullptr;
    if (record.is_boolean() && record.get<bool>()) continue;
    std::error_code ec;
    fs::remove_all(fs::path(data_root) / c.capture_path, ec);
  }
}

// The capture source of `config.source`: its checks (a replayed capture that reads, a live
// source for every sensor) made once here, at Create.
absl::StatusOr<std::unique_ptr<CaptureSource>> MakeCaptureSource(
    const StationCoreConfig& config, const std::vector<CarModel>& cars) {
  switch (config.source) {
    case CycleSource::kReplay:
      return MakeReplaySource(config.data_root, config.replay_capture, config.input_budget);
    case CycleSource::kLive:
      return MakeLiveSource(config.live_sources, config.make_source, cars, config.acquire_deadline);
    case CycleSource::kSimulator:
      break;
  }
  return MakeSimulatorSource(config.simulated_moves);
}

Verdict OverallVerdict(const std::vector<SensorCalibration>& sensors) {
  bool any_error = sensors.empty(), all_pass = !sensors.empty();
  for (const SensorCalibration& s : sensors) {
    any_error |= s.verdict == Verdict::kError;
    all_pass &= s.verdict == Verdict::kPass;
  }
  return all_pass ? Verdict::kPass : any_error ? Verdict::kError : Verdict::kFail;
}

}  // namespace

absl::StatusOr<std::unique_ptr<StationCore>> StationCore::Create(const StationCoreConfig& config) {
  absl::StatusOr<StationLayout> station = ReadStationLayout(config.station_path);
  if (!station.ok()) return station.status();
  std::vector<CarModel> cars;
  for (const std::string& path : config.car_model_paths) {
    absl::StatusOr<CarModel> car = ReadCarModel(path);
    if (!car.ok()) return car.status();
    for (const CarModel& c : cars) {
      if (c.id == car->id)
        return absl::InvalidArgumentError(
            absl::StrCat(path, ": car model id '", car->id, "' twice"));
    }
    if (absl::Status s = CheckTargetsExist(*car, *station); !s.ok()) return s;
    cars.push_back(std::move(*car));
  }
  for (const SimulatedBoardMove& m : config.simulated_moves) {
    if (station->FindBoard(m.move.board_id) == nullptr) {
      return absl::InvalidArgumentError(absl::StrCat(config.station_path, ": no board '",
                                                     m.move.board_id, "' (source.moved_boards)"));
    }
  }
  if (cars.empty())
    return absl::InvalidArgumentError("car_models: at least one car model is needed");
  std::error_code ec;
  fs::create_directories(config.data_root, ec);
  if (ec)
    return absl::InvalidArgumentError(
        absl::StrCat("data_root: cannot create '", config.data_root, "': ", ec.message()));
  absl::StatusOr<std::unique_ptr<CaptureSource>> capture_source = MakeCaptureSource(config, cars);
  if (!capture_source.ok()) return capture_source.status();
  if (config.acquire_deadline <= std::chrono::milliseconds(0) ||
      config.calibrate_deadline <= std::chrono::milliseconds(0)) {
    return absl::InvalidArgumentError("deadlines_ms: acquire and calibrate must be > 0");
  }
  if (config.default_frames_per_sensor < 1 ||
      config.default_frames_per_sensor > kMaxFramesPerSensor) {
    return absl::InvalidArgumentError("default_frames_per_sensor: must be in [1, 100]");
  }
  StoreOptions store_options;
  store_options.busy_timeout = config.busy_timeout;
  store_options.outbox = config.plant.has_value();
  absl::StatusOr<std::unique_ptr<Store>> store = Store::Open(config.db_path, store_options);
  if (!store.ok()) return store.status();
  RemoveAbortedCaptures(config.data_root, (*store)->aborted_cycles_at_open());
  struct stat root {};
  if (::stat(config.data_root.c_str(), &root) != 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("data_root: '", config.data_root, "': ", std::strerror(errno)));
  }
  std::unique_ptr<StationCore> core(new StationCore(config, std::move(*station), std::move(cars),
                                                    std::move(*store), *std::move(capture_source)));
  core->data_root_dev_ = root.st_dev;
  core->data_root_ino_ = root.st_ino;
  if (config.plant) {
    absl::StatusOr<std::string> conninfo = PlantConnectionString(*config.plant);
    if (!conninfo.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("plant.dsn: ", conninfo.status().message()));
    }
    ForwarderOptions forwarding;
    forwarding.conninfo = *std::move(conninfo);
    forwarding.station_id = config.plant->station_id;
    forwarding.batch = config.plant->batch;
    forwarding.max_retry_interval = config.plant->max_retry_interval;
    StationCore* logger = core.get();
    forwarding.log = [logger](const LogRecord& record) {
      logger->Log(record.level, record.message);
    };
    absl::StatusOr<std::unique_ptr<Forwarder>> forwarder =
        Forwarder::Start(core->store_.get(), std::move(forwarding));
    if (!forwarder.ok()) return forwarder.status();
    core->forwarder_ = *std::move(forwarder);
  }
  return core;
}

StationCore::StationCore(StationCoreConfig config, StationLayout station,
                         std::vector<CarModel> cars, std::unique_ptr<Store> store,
                         std::unique_ptr<CaptureSource> capture_source)
    : config_(std::move(config)),
      station_(std::move(station)),
      cars_(std::move(cars)),
      store_(std::move(store)),
      capture_source_(std::move(capture_source)) {}

StationCore::~StationCore() {
  stopping_ = true;
  cancel_ = true;
  if (worker_.joinable()) worker_.join();
  JoinAbandoned(/*all=*/true);
  if (StoreUnstoredEnd().ok()) return;
  Log(LogLevel::kError,
      absl::StrCat("cycle ", unstored_end_->id, " ended ", CycleStateName(unstored_end_->state),
                   " (", unstored_end_->reason,
                   ") but its end could not be stored; the next start stores it as "
                   "aborted (daemon_restarted)"),
      unstored_end_->id, unstored_end_->vin);
}

void StationCore::Log(LogLevel level, const std::string& message, int64_t cycle,
                      const std::string& vin) const {
  const LogRecord record{level, message, cycle, vin};
  if (config_.log) {
    config_.log(record);
  } else {
    WriteLog(record);
  }
}

absl::Status StationCore::CheckStorage() const {
  struct stat root {};
  if (::stat(config_.data_root.c_str(), &root) != 0) {
    return absl::FailedPreconditionError(absl::StrCat("data_root '", config_.data_root,
                                                      "' was removed while linecald ran (",
                                                      std::strerror(errno), ")"));
  }
  if (root.st_dev != data_root_dev_ || root.st_ino != data_root_ino_) {
    return absl::FailedPreconditionError(absl::StrCat(
        "data_root '", config_.data_root, "' was removed and made again while linecald ran"));
  }
  return store_->CheckFile();
}

std::string StationCore::FailureReason(const std::string& what, const absl::Status& status) {
  const bool full = absl::IsResourceExhausted(status) ||
                    status.message().find(std::strerror(ENOSPC)) != absl::string_view::npos;
  const std::string failure =
      what.empty() ? std::string(status.message()) : absl::StrCat(what, ": ", status.message());
  if (!full) return failure;
  std::lock_guard<std::mutex> lock(mutex_);
  disk_full_ = true;
  return absl::StrCat("disk_full: ", failure);
}

// A calibration on its own thread; the thread owns what it reads (the capture) through this.
struct StationCore::PendingCalibration {
  std::stop_source stop;  // requested at the deadline or a cancel: the work ends soon after
  Capture capture;
  std::mutex mutex;
  std::condition_variable done_changed;
  bool done = false;
  absl::StatusOr<CycleCalibration> result = absl::UnknownError("not calibrated");
};

void StationCore::JoinAbandoned(bool all) {
  std::vector<std::thread> finished;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto it = abandoned_.begin(); it != abandoned_.end();) {
      bool done = all;
      if (!done) {
        std::lock_guard<std::mutex> pending_lock(it->first->mutex);
        done = it->first->done;
      }
      if (done) {
        finished.push_back(std::move(it->second));
        it = abandoned_.erase(it);
      } else {
        ++it;
      }
    }
  }
  for (std::thread& t : finished) t.join();
}

absl::StatusOr<CycleCalibration> StationCore::CalibrateWithDeadline(int64_t id, Capture capture) {
  const auto deadline = std::chrono::steady_clock::now() + config_.calibrate_deadline;
  auto pending = std::make_shared<PendingCalibration>();
  pending->capture = std::move(capture);
  std::thread thread([pending] {
    CaptureCalibrationOptions options;
    options.stop = pending->stop.get_token();
    absl::StatusOr<CycleCalibration> result = CalibrateCapture(pending->capture, options);
    std::lock_guard<std::mutex> lock(pending->mutex);
    pending->result = std::move(result);
    pending->done = true;
    pending->done_changed.notify_all();
  });
  absl::Status stopped;
  {
    std::unique_lock<std::mutex> lock(pending->mutex);
    while (!pending->done) {
      if (cancel_) {
        stopped = absl::CancelledError("cancelled");
        break;
      }
      if (std::chrono::steady_clock::now() >= deadline) {
        stopped = absl::DeadlineExceededError(absl::StrCat(
            "calibration still running after ", config_.calibrate_deadline.count(), " ms"));
        break;
      }
      // 50 ms: how late a cancel is noticed while the calibration runs.
      pending->done_changed.wait_for(lock, std::chrono::milliseconds(50));
    }
  }
  if (stopped.ok()) {
    thread.join();
    return std::move(pending->result);
  }
  // Past the deadline or cancelled: the work stops at its next frame, scan or board, so that
  // its threads and the core it kept busy are free again (they used to run on to the end).
  pending->stop.request_stop();
  bool done = false;
  {
    std::unique_lock<std::mutex> lock(pending->mutex);
    done =
        pending->done_changed.wait_for(lock, kCalibrationStopGrace, [&] { return pending->done; });
  }
  if (done) {
    thread.join();
    return stopped;
  }
  Log(LogLevel::kWarning,
      absl::StrCat("a stopped calibration still runs after ", kCalibrationStopGrace.count(),
                   " ms; it is left to end on its own"),
      id, pending->capture.manifest.vin);
  std::lock_guard<std::mutex> lock(mutex_);
  abandoned_.emplace_back(std::move(pending), std::move(thread));
  return stopped;
}

const CarModel* StationCore::FindCar(const std::string& id) const {
  for (const CarModel& c : cars_) {
    if (c.id == id) return &c;
  }
  return nullptr;
}

absl::StatusOr<int64_t> ParseCycleId(const std::string& id) {
  int64_t v = 0;
  if (!absl::SimpleAtoi(id, &v) || v <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("cycle_id: ", QuoteInput(id), " is not a cycle id"));
  }
  return v;
}

absl::Status ValidateCycleRequest(const CycleRequest& request, const std::vector<CarModel>& cars,
                                  bool vin_check_digit) {
  if (absl::Status s = ValidateVin(request.vin, vin_check_digit); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("vin: ", s.message()));
  }
  const auto has_id = [&](const CarModel& c) { return c.id == request.car_model_id; };
  if (std::none_of(cars.begin(), cars.end(), has_id)) {
    std::vector<std::string> known;
    for (const CarModel& c : cars) known.push_back(c.id);
    return absl::InvalidArgumentError(absl::StrCat("car_model_id: unknown car model ",
                                                   QuoteInput(request.car_model_id),
                                                   "; known: ", absl::StrJoin(known, ", ")));
  }
  const AlignerMeasurement& a = request.aligner;
  const std::pair<const char*, double> offsets[] = {
      {"aligner.longitudinal_offset_m", a.longitudinal_offset_m},
      {"aligner.lateral_offset_m", a.lateral_offset_m}};
  for (const auto& [field, v] : offsets) {
    if (!(std::abs(v) <= kMaxAlignerOffsetM)) {
      return absl::InvalidArgumentError(
          absl::StrCat(field, " = ", v, ": must be within +-", kMaxAlignerOffsetM, " m"));
    }
  }
  if (!(std::abs(a.thrust_angle_rad * kRadToDeg) <= kMaxThrustDeg)) {
    return absl::InvalidArgumentError(
        absl::StrCat("aligner.thrust_angle_deg = ", a.thrust_angle_rad * kRadToDeg,
                     ": must be within +-", kMaxThrustDeg, " deg"));
  }
  if (request.frames_per_sensor < 0 || request.frames_per_sensor > kMaxFramesPerSensor) {
    return absl::InvalidArgumentError(absl::StrCat(
        "options.frames_per_sensor = ", request.frames_per_sensor, ": must be in [0, 100]"));
  }
  return absl::OkStatus();
}

absl::StatusOr<int64_t> StationCore::StartCycle(const CycleRequest& request) {
  if (absl::Status s = ValidateCycleRequest(request, cars_, config_.vin_check_digit); !s.ok())
    return s;
  JoinAbandoned(/*all=*/false);
  // Nothing stored now would outlive the process, and the last cycle's end comes first.
  if (absl::Status s = CheckStorage(); !s.ok()) return s;
  if (absl::Status s = StoreUnstoredEnd(); !s.ok()) return s;

  std::lock_guard<std::mutex> lock(mutex_);
  if (running_)
    return absl::FailedPreconditionError(absl::StrCat("cycle ", *running_, " is running"));
  if (worker_.joinable()) worker_.join();  // the previous cycle's thread has finished its work
  StoredCycle cycle;
  cycle.vin = request.vin;
  cycle.car_model_id = request.car_model_id;
  cycle.started_ns = NowNs();
  cycle.request_json = nlohmann::json{{"vin", request.vin},
                                      {"car_model_id", request.car_model_id},
                                      {"aligner", AlignerToJson(request.aligner)},
                                      {"record_capture", request.record_capture},
                                      {"frames_per_sensor", request.frames_per_sensor}}
                           .dump();
  cycle.capture_path = config_.source == CycleSource::kReplay
                           ? config_.replay_capture
                           : absl::StrCat("captures/", request.vin, "-", cycle.started_ns);
  absl::StatusOr<int64_t> id = store_->BeginCycle(cycle);
  if (absl::IsResourceExhausted(id.status())) disk_full_ = true;
  if (!id.ok()) return id.status();
  disk_full_ = false;
  running_ = *id;
  cancel_ = false;
  ending_ = false;
  worker_ = std::thread(&StationCore::RunCycle, this, *id, request);
  return *id;
}

absl::Status StationCore::Event(int64_t id, const std::string& vin, EventType type,
                                const std::string& sensor, const std::string& detail,
                                std::optional<Verdict> verdict) {
  absl::StatusOr<int64_t> seq =
      store_->AppendEvent({id, 0, NowNs(), type, sensor, detail, verdict});
  changed_.notify_all();
  Log(LogLevel::kDebug,
      absl::StrCat("event ", EventTypeName(type), sensor.empty() ? "" : " ", sensor,
                   detail.empty() ? "" : ": ", detail,
                   verdict ? absl::StrCat(" (", VerdictName(*verdict), ")") : ""),
      id, vin);
  return seq.status();
}

StationCore::CycleEnd StationCore::EndOf(int64_t id, CycleState state, std::string reason) {
  CycleEnd end;
  end.id = id;
  end.state = state;
  end.reason = std::move(reason);
  return end;
}

void StationCore::RunCycle(int64_t id, CycleRequest request) {
  const CarModel& car = *FindCar(request.car_model_id);
  Log(LogLevel::kInfo, absl::StrCat("cycle ", id, " started (car model ", car.id, ")"), id,
      request.vin);
  Event(id, request.vin, EventType::kStarted, "", car.id).IgnoreError();
  const absl::StatusOr<StoredCycle> stored = store_->GetCycle(id);
  CycleEnd end = stored.ok() ? WorkCycle(id, request, car, *stored)
                             : EndOf(id, CycleState::kDone, "store_unavailable");
  DecideEnd(&end);
  // The capture of a cycle that acquired it is kept only when asked (a replayed one is never
  // removed).
  if (stored.ok() && !request.record_capture && config_.source != CycleSource::kReplay &&
      !stored->capture_path.empty()) {
    std::error_code ec;
    fs::remove_all(fs::path(config_.data_root) / stored->capture_path, ec);
  }
  if (end.state == CycleState::kCancelled) end.verdict = Verdict::kError;
  end.vin = request.vin;
  end.ended_ns = NowNs();
  PublishEnd(end);
}

StationCore::CycleEnd StationCore::WorkCycle(int64_t id, const CycleRequest& request,
                                             const CarModel& car, const StoredCycle& stored) {
  const CycleEnd cancelled = EndOf(id, CycleState::kCancelled, "cancelled");
  const auto error = [id](std::string reason) {
    return EndOf(id, CycleState::kDone, std::move(reason));
  };
  const std::string dir = (fs::path(config_.data_root) / stored.capture_path).string();
  absl::StatusOr<AcquiredCapture> acquired = AcquireCapture(id, request, car, stored, dir);
  if (absl::IsCancelled(acquired.status())) return cancelled;
  if (!acquired.ok()) return error(FailureReason("", acquired.status()));
  if (cancel_) return cancelled;
  absl::StatusOr<Capture> capture = ReadCapture(dir, config_.input_budget);
  if (!capture.ok()) return error(absl::StrCat("capture_unreadable: ", capture.status().message()));
  absl::StatusOr<CycleCalibration> result = CalibrateWithDeadline(id, *std::move(capture));
  if (absl::IsCancelled(result.status())) return cancelled;
  if (absl::IsDeadlineExceeded(result.status())) return error("calibrate_deadline_exceeded");
  if (!result.ok()) return error(absl::StrCat("calibration_failed: ", result.status().message()));
  if (cancel_)
    return cancelled;  // asked while the sensors were computed: their results are not stored
  return StoreResults(id, request.vin, car, acquired->failures, std::move(result->sensors));
}

absl::StatusOr<AcquiredCapture> StationCore::AcquireCapture(int64_t id, const CycleRequest& request,
                                                            const CarModel& car,
                                                            const StoredCycle& stored,
                                                            const std::string& dir) {
  CaptureCycle cycle;
  cycle.id = id;
  cycle.station = &station_;
  cycle.car = &car;
  cycle.vin = request.vin;
  cycle.aligner = request.aligner;
  cycle.started_ns = stored.started_ns;
  cycle.dir = dir;
  cycle.frames =
      request.frames_per_sensor > 0 ? request.frames_per_sensor : config_.default_frames_per_sensor;
  cycle.cancel = &cancel_;
  cycle.event = [this, id, vin = request.vin](EventType type, const std::string& sensor,
                                              const std::string& detail,
                                              std::optional<Verdict> verdict) {
    Event(id, vin, type, sensor, detail, verdict).IgnoreError();
  };
  return capture_source_->Acquire(cycle);
}

StationCore::CycleEnd StationCore::StoreResults(int64_t id, const std::string& vin,
                                                const CarModel& car,
                                                const std::map<std::string, std::string>& failures,
                                                std::vector<SensorCalibration> calibrated) {
  // The sensors that failed to acquire take their place in the car model's order.
  std::vector<SensorCalibration> sensors;
  for (const SensorModel& m : car.sensors) {
    if (auto f = failures.find(m.name); f != failures.end()) {
      SensorCalibration failed;
      failed.name = m.name;
      failed.kind = m.kind;
      failed.verdict = Verdict::kError;
      failed.reason = absl::StrCat("acquisition_failed: ", f->second);
      failed.message = f->second;
      sensors.push_back(std::move(failed));
      continue;
    }
    for (SensorCalibration& c : calibrated) {
      if (c.name == m.name) sensors.push_back(std::move(c));
    }
  }
  CycleEnd end = EndOf(id, CycleState::kDone, "");
  std::vector<std::string> not_passed;
  for (const SensorCalibration& s : sensors) {
    if (absl::Status st = store_->PutSensorResult(id, ToStored(s)); !st.ok()) {
      end.reason = absl::IsResourceExhausted(st)
                       ? FailureReason("", st)
                       : absl::StrCat("store_unavailable: ", st.message());
      return end;
    }
    Event(id, vin, EventType::kSensorVerdict, s.name, s.reason, s.verdict).IgnoreError();
    if (s.verdict != Verdict::kPass) not_passed.push_back(absl::StrCat(s.name, ":", s.reason));
  }
  end.verdict = OverallVerdict(sensors);
  end.reason = absl::StrJoin(not_passed, ",");
  return end;
}

void StationCore::DecideEnd(CycleEnd* end) {
  {
    // The end is decided here: a cancel accepted until now makes the cycle cancelled whatever
    // it stored; CancelCycle refuses from now on, as for an ended cycle.
    std::lock_guard<std::mutex> lock(mutex_);
    ending_ = true;
    if (cancel_ && end->state == CycleState::kDone) {
      end->state = CycleState::kCancelled;
      end->reason = "cancelled";
    }
  }
  // A data root or database removed meanwhile: whatever the cycle found, its results went to
  // a file that no longer exists (or were written into a new data root): not a pass.
  if (absl::Status storage = CheckStorage(); !storage.ok() && end->state == CycleState::kDone) {
    end->verdict = Verdict::kError;
    end->reason = absl::StrCat("data_root_removed: ", storage.message());
  }
}

void StationCore::PublishEnd(const CycleEnd& end) {
  // The last event, then the end in the store, then the station idle: a watcher returns only
  // once the station no longer runs this cycle (WatchCycle), and WaitIdle once it is stored
  // as ended (or kept as unstored_end_), so whoever sees the end sees all of it.
  CycleEnd stored_end = end;
  const absl::Status stored = StoreEnd(&stored_end);
  if (!stored.ok()) {
    Log(LogLevel::kError,
        absl::StrCat("cycle ", end.id, " ended ", CycleStateName(end.state), " (", end.reason,
                     ") but its end cannot be stored: ", stored.message(),
                     "; it is stored once the disk has room, before the next cycle"),
        end.id, end.vin);
  } else if (absl::Status storage = CheckStorage(); !storage.ok()) {
    Log(LogLevel::kError,
        absl::StrCat("cycle ", end.id, " ended ", CycleStateName(end.state), " (", end.reason,
                     "), stored in a database that is lost at the next start: ", storage.message()),
        end.id, end.vin);
  } else {
    Log(LogLevel::kInfo,
        absl::StrCat("cycle ", end.id, " ended ", CycleStateName(end.state), ", verdict ",
                     VerdictName(end.verdict), end.reason.empty() ? "" : " (", end.reason,
                     end.reason.empty() ? "" : ")"),
        end.id, end.vin);
  }
  if (stored.ok() && forwarder_) forwarder_->Notify();
  std::lock_guard<std::mutex> lock(mutex_);
  if (!stored.ok()) unstored_end_ = stored_end;
  running_.reset();
  changed_.notify_all();
}

absl::Status StationCore::StoreEnd(CycleEnd* end) {
  // A database locked past the busy timeout (another process holding it) must not leave the
  // cycle `running` while the station takes the next car: the end is retried until the lock
  // is gone (each try waits the busy timeout), and the station stays busy meanwhile. Only
  // the destructor gives up; the cycle is then aborted at the next start. Any other failure
  // (a full disk) is returned: retrying it would keep the station busy for as long.
  const auto until_stored = [&](const std::function<absl::Status()>& write) {
    absl::Status s = write();
    while (absl::IsUnavailable(s) && !stopping_) {
      // 50 ms between tries: with a busy timeout of 0, not a busy loop on the lock.
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      s = write();
    }
    return s;
  };
  if (!end->event_stored) {
    absl::Status s = until_stored([&] {
      return Event(end->id, end->vin, EventType::kCycleEnded, "", end->reason, end->verdict);
    });
    if (!s.ok()) return s;
    end->event_stored = true;
  }
  const absl::Status s = until_stored([&] {
    return store_->EndCycle(end->id, end->state, end->verdict, end->reason, end->ended_ns);
  });
  // Already ended: an earlier try committed before it reported its failure.
  return absl::IsFailedPrecondition(s) ? absl::OkStatus() : s;
}

absl::Status StationCore::StoreUnstoredEnd() {
  // One writer of the end at a time (Health's poll and StartCycle): its event stored once.
  std::lock_guard<std::mutex> storing(unstored_end_mutex_);
  std::optional<CycleEnd> end;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    end = unstored_end_;
  }
  if (!end) return absl::OkStatus();
  const absl::Status s = StoreEnd(&*end);
  std::lock_guard<std::mutex> lock(mutex_);
  if (!s.ok()) {
    unstored_end_ = end;  // with event_stored as far as it got
    if (absl::IsResourceExhausted(s)) disk_full_ = true;
    return absl::Status(s.code(),
                        absl::StrCat("cycle ", end->id, "'s end is not stored yet: ", s.message()));
  }
  unstored_end_.reset();
  if (forwarder_) forwarder_->Notify();
  Log(LogLevel::kWarning,
      absl::StrCat("cycle ", end->id, "'s end (", end->reason, ") is stored now"), end->id,
      end->vin);
  changed_.notify_all();
  return absl::OkStatus();
}

absl::Status StationCore::Health() {
  absl::Status health = CheckStorage();
  if (health.ok()) health = StoreUnstoredEnd();
  if (health.ok()) health = CheckPlantBacklog();
  std::lock_guard<std::mutex> lock(mutex_);
  if (health.ok() && disk_full_) {
    std::error_code ec;
    const fs::space_info space = fs::space(fs::path(store_->path()).parent_path(), ec);
    if (!ec && space.available >= kFreeBytesToServe) {
      disk_full_ = false;
    } else {
      health = absl::ResourceExhaustedError(absl::StrCat("disk full: ", ec ? 0 : space.available,
                                                         " bytes free below the database, ",
                                                         kFreeBytesToServe, " needed"));
    }
  }
  const std::string now(health.message());
  if (now != last_health_) {
    Log(health.ok() ? LogLevel::kWarning : LogLevel::kError,
        health.ok() ? absl::StrCat("health: serving again (was: ", last_health_, ")")
                    : absl::StrCat("health: NOT_SERVING: ", now));
    last_health_ = now;
  }
  return health;
}

absl::Status StationCore::CheckPlantBacklog() {
  if (!forwarder_) return absl::OkStatus();
  const ForwarderStats stats = forwarder_->Stats();
  if (stats.oldest_unshipped_age <= config_.plant->max_backlog_age) return absl::OkStatus();
  return absl::UnavailableError(absl::StrCat(
      "plant database: ", stats.backlog, " cycles not forwarded, the oldest ended ",
      std::chrono::duration_cast<std::chrono::seconds>(stats.oldest_unshipped_age).count(),
      " s ago (plant.max_backlog_age_s ", config_.plant->max_backlog_age.count(), ")",
      stats.last_error.ok() ? "" : absl::StrCat("; last error: ", stats.last_error.message())));
}

int64_t StationCore::StopForwarding(std::chrono::steady_clock::time_point deadline) {
  return forwarder_ ? forwarder_->Stop(deadline) : 0;
}

absl::Status StationCore::CancelCycle(int64_t cycle_id) {
  absl::StatusOr<StoredCycle> cycle = store_->GetCycle(cycle_id);
  if (!cycle.ok()) return cycle.status();
  std::lock_guard<std::mutex> lock(mutex_);
  if (running_ != cycle_id) {
    return absl::FailedPreconditionError(
        absl::StrCat("cycle ", cycle_id, " is not running (", CycleStateName(cycle->state), ")"));
  }
  if (ending_) return absl::FailedPreconditionError(absl::StrCat("cycle ", cycle_id, " is ending"));
  cancel_ = true;
  return absl::OkStatus();
}

absl::StatusOr<StoredCycle> StationCore::GetCycle(int64_t cycle_id) {
  absl::StatusOr<StoredCycle> cycle = store_->GetCycle(cycle_id);
  std::lock_guard<std::mutex> lock(mutex_);
  // An end kept in memory (disk full) is the cycle's end, stored or not yet.
  if (cycle.ok() && cycle->state == CycleState::kRunning && unstored_end_ &&
      unstored_end_->id == cycle_id) {
    cycle->state = unstored_end_->state;
    cycle->verdict = unstored_end_->verdict;
    cycle->reason = unstored_end_->reason;
    cycle->ended_ns = unstored_end_->ended_ns;
  }
  return cycle;
}

absl::StatusOr<CyclePage> StationCore::ListCycles(const CycleFilter& filter) {
  absl::StatusOr<CyclePage> page = store_->ListCycles(filter);
  std::lock_guard<std::mutex> lock(mutex_);
  if (!page.ok() || !unstored_end_) return page;
  for (StoredCycle& c : page->cycles) {
    if (c.id != unstored_end_->id || c.state != CycleState::kRunning) continue;
    c.state = unstored_end_->state;  // as GetCycle shows it
    c.verdict = unstored_end_->verdict;
    c.reason = unstored_end_->reason;
    c.ended_ns = unstored_end_->ended_ns;
  }
  return page;
}

absl::StatusOr<Capture> StationCore::CycleCapture(int64_t cycle_id) {
  absl::StatusOr<StoredCycle> cycle = GetCycle(cycle_id);
  if (!cycle.ok()) return cycle.status();
  if (cycle->state == CycleState::kRunning) {
    return absl::FailedPreconditionError(absl::StrCat("cycle ", cycle_id, " is running"));
  }
  std::error_code ec;
  if (cycle->capture_path.empty() ||
      !fs::is_directory(fs::path(config_.data_root) / cycle->capture_path, ec)) {
    return absl::FailedPreconditionError(
        absl::StrCat("capture_not_kept: cycle ", cycle_id,
                     "'s capture was not kept (the cycle was started without record_capture)"));
  }
  // The store's path is the core's own, but a folder below the data root may have been
  // replaced by a link since: checked as a replay capture is.
  absl::StatusOr<fs::path> dir =
      ResolveInside(config_.data_root, cycle->capture_path,
                    absl::StrCat("'", cycle->capture_path, "'"), "data_root");
  if (!dir.ok()) return dir.status();
  absl::StatusOr<Capture> capture = ReadCapture(dir->string(), config_.input_budget);
  if (!capture.ok()) {
    return absl::FailedPreconditionError(
        absl::StrCat("capture_unreadable: ", capture.status().message()));
  }
  return capture;
}

absl::Status StationCore::WatchCycle(int64_t cycle_id,
                                     const std::function<bool(const StoredEvent&)>& on_event) {
  if (absl::StatusOr<StoredCycle> c = store_->GetCycle(cycle_id); !c.ok()) return c.status();
  int64_t next = 0;
  bool read_after_end = false;
  while (true) {
    // Whether the cycle had ended is read before the events, so the last read delivers all.
    absl::StatusOr<StoredCycle> cycle = store_->GetCycle(cycle_id);
    if (!cycle.ok()) return cycle.status();
    absl::StatusOr<std::vector<StoredEvent>> events = store_->Events(cycle_id);
    if (!events.ok()) return events.status();
    for (const StoredEvent& e : *events) {
      if (e.sequence < next) continue;
      if (!on_event(e)) return absl::CancelledError("the watcher went away");
      next = e.sequence + 1;
    }
    std::unique_lock<std::mutex> lock(mutex_);
    // Ended in the store and no longer run by the station: every event was stored before.
    if (cycle->state != CycleState::kRunning && running_ != cycle_id) return absl::OkStatus();
    // Ended, but the end could not be stored (disk full): its last event from memory, or,
    // when that event is stored, one more read delivers it.
    if (unstored_end_ && unstored_end_->id == cycle_id && running_ != cycle_id) {
      const CycleEnd end = *unstored_end_;
      lock.unlock();
      if (end.event_stored) {
        if (read_after_end) return absl::OkStatus();
        read_after_end = true;
        continue;
      }
      if (!on_event({cycle_id, next, end.ended_ns, EventType::kCycleEnded, "", end.reason,
                     end.verdict})) {
        return absl::CancelledError("the watcher went away");
      }
      return absl::OkStatus();
    }
    // 200 ms: a missed notification (between the reads and the wait) costs at most this.
    changed_.wait_for(lock, std::chrono::milliseconds(200));
  }
}

std::string StationStatusInfo::SourceOf(const std::string& sensor) const {
  const auto live = sensor_sources.find(sensor);
  return live != sensor_sources.end() ? live->second : source;
}

StationStatusInfo StationCore::Status() {
  StationStatusInfo s;
  s.station_id = config_.station_id;
  for (const CarModel& c : cars_) s.car_models.push_back(c.id);
  s.source = config_.source == CycleSource::kSimulator ? "simulator"
             : config_.source == CycleSource::kReplay  ? "replay"
                                                       : "live";
  s.sensor_sources = capture_source_->SensorSources();
  for (const CarModel& c : cars_) {
    for (const SensorModel& sensor : c.sensors) {
      bool listed = false;
      for (const auto& [name, kind] : s.sensors) listed |= name == sensor.name;
      if (!listed) s.sensors.emplace_back(sensor.name, sensor.kind);
    }
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    s.running_cycle = running_;
  }
  s.database_path = store_->path();
  if (forwarder_) {
    s.plant = forwarder_->Stats();
    s.plant_max_backlog_age = config_.plant->max_backlog_age;
  }
  std::error_code ec;
  const fs::space_info space = fs::space(config_.data_root, ec);
  if (!ec) s.disk_free_bytes = space.available;
  absl::StatusOr<StationHealth> health = Trends(kHealthWindowCycles);
  if (health.ok()) {
    s.target_alarms = std::move(health->alarms);
  } else {
    s.health_error = std::string(health.status().message());
  }
  return s;
}

absl::StatusOr<StationHealth> StationCore::Trends(int cycles, const StationHealthOptions& options) {
  absl::StatusOr<std::vector<TrendRow>> rows = store_->RecentSolvedResults(cycles);
  if (!rows.ok()) return rows.status();
  absl::StatusOr<std::vector<BoardTrendRow>> boards = store_->RecentBoardResults(cycles);
  if (!boards.ok()) return boards.status();
  // Both lists are in cycle order; a cycle may be in either alone (none solved, or stored
  // before the store kept boards).
  std::map<int64_t, HealthCycle> by_id;
  for (const TrendRow& row : *rows) {
    HealthCycle& c = by_id[row.cycle_id];
    c.cycle_id = row.cycle_id;
    c.started_ns = row.started_ns;
    c.car_model = row.car_model_id;
    const MountingValues& d = row.deviation;
    c.results.push_back(
        {row.sensor, {d.yaw_deg, d.pitch_deg, d.roll_deg, d.x_m, d.y_m, d.z_m, row.residual_rms}});
  }
  for (const BoardTrendRow& row : *boards) {
    HealthCycle& c = by_id[row.cycle_id];
    c.cycle_id = row.cycle_id;
    c.started_ns = row.started_ns;
    c.car_model = row.car_model_id;
    const StoredBoardResult& b = row.board;
    c.boards.push_back({row.sensor, b.board, b.frames, b.frames_found, b.frames_partial,
                        row.solved ? b.residual_rms : std::nullopt});
  }
  std::vector<HealthCycle> health_cycles;
  health_cycles.reserve(by_id.size());
  for (auto& [id, c] : by_id) health_cycles.push_back(std::move(c));
  return ComputeStationHealth(cars_, health_cycles, options);
}

void StationCore::WaitIdle() {
  std::unique_lock<std::mutex> lock(mutex_);
  changed_.wait(lock, [&] { return !running_.has_value(); });
}

bool StationCore::WaitIdleFor(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mutex_);
  return changed_.wait_for(lock, timeout, [&] { return !running_.has_value(); });
}

}  // namespace linecal

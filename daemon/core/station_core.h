#pragma once
// The station's core, without gRPC: validates cycle requests, runs one cycle at a time on a
// worker thread (acquire -> detect -> solve -> verdict through station/pipeline), stores every
// attempt and its events in the SQLite store, and serves reads and event streams. The gRPC
// handlers (daemon/service) only translate to and from this.
//
// Sources: which data a cycle calibrates from is station configuration —
//   simulator  the car is simulated in the station (the request's aligner measurement, the
//              cycle id as seed) into the cycle's capture directory, then calibrated;
//   replay     a recorded capture under the data root is calibrated as it is;
//   live       every sensor is acquired from its own source (daemon/sources: Aravis, V4L2,
//              UDP LiDAR, SocketCAN or a candump log), all at once, one thread per sensor,
//              into the cycle's capture directory, which is then written as a capture
//              (origin "station") and calibrated. A sensor whose source fails is stored with
//              verdict error and reason "acquisition_failed: <message>"; the others are
//              calibrated as usual.
// Deadlines: acquisition (live) and calibration each have one; a calibration that runs past
// its deadline ends the cycle in error ("calibrate_deadline_exceeded") and is stopped
// (CaptureCalibrationOptions::stop: at its next frame, scan or board), as is one whose cycle
// is cancelled: its threads are gone within a second. One that does not stop within
// kCalibrationStopGrace is left to end on its own thread (it owns what it reads), joined at a
// later StartCycle or when the core is destroyed.
// Storage faults: a full disk (SQLITE_FULL, ENOSPC writing the capture) ends the cycle in
// error ("disk_full: ..."); a data root or database file removed while the core runs ends it
// in error ("data_root_removed: ..."), since what SQLite writes then goes to an unlinked file
// and is lost. An end that cannot be stored is kept in memory (GetCycle and WatchCycle show
// it, the log says so) and stored once space returns, before any new cycle starts; Health()
// says NOT_SERVING meanwhile.
//
// Errors (absl::Status): InvalidArgument naming the request field; FailedPrecondition for a
// second cycle while one runs, or cancelling an ended cycle; NotFound for unknown cycle ids;
// Unavailable when the store is locked; ResourceExhausted when the disk is full (StartCycle);
// FailedPrecondition when the data root or database file is gone (StartCycle). A cycle whose
// writes meet a store locked past the busy timeout ends in error ("store_unavailable: ..."),
// its end stored once the lock is gone.
// Thread safety: every method may be called from any thread.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <stop_token>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "daemon/core/capture_source.h"
#include "daemon/log/daemon_log.h"
#include "daemon/plant/forwarder.h"
#include "daemon/simstation/simulator_source.h"
#include "daemon/store/store.h"
#include "station/health/station_health.h"
#include "station/io/input_budget.h"
#include "station/model/aligner.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/pipeline/capture_calibration.h"

namespace linecal {

enum class CycleSource { kSimulator, kReplay, kLive };

struct StationCoreConfig {
  std::string station_id = "demo";
  std::string station_path;                  // linecal.station file
  std::vector<std::string> car_model_paths;  // linecal.car files; ids must be unique
  std::string db_path;                       // SQLite file (its directory must exist)
  std::string data_root;                     // captures are written and read below it
  CycleSource source = CycleSource::kSimulator;
  std::string replay_capture;  // replay: a capture directory relative to data_root
  std::vector<SimulatedBoardMove> simulated_moves;  // simulator: boards moved from a cycle on
  // live: the source of every sensor of every car model, by sensor name (a name shared by
  // several car models has one source). Create checks that each sensor has one of its kind.
  std::map<std::string, SourceConfig> live_sources;
  // live: how the sources are built; empty: MakeSensorSource. Tests serve sensors from
  // their own SensorSource implementations through it.
  SensorSourceFactory make_source;
  // live: how long all sensors together may take to acquire their data. 10 s: a radar's
  // default 3.6 s record plus camera frames and LiDAR rotations with margin.
  std::chrono::milliseconds acquire_deadline{10000};
  // How long detection and solving of all sensors may take: 20 s is twenty times the
  // acceptance bar of 1 s per cycle, so only a stuck calibration reaches it.
  std::chrono::milliseconds calibrate_deadline{20000};
  bool vin_check_digit = true;        // ISO 3779 check digit (markets that use it)
  int default_frames_per_sensor = 1;  // camera frames and LiDAR rotations when the request gives 0
  std::chrono::milliseconds busy_timeout{5000};
  // What one file of a capture may claim (the `input_budget` key), for every ReadCapture.
  InputBudget input_budget;
  // Forwarding of every ended cycle to the plant database (daemon/plant/forwarder.h): the
  // store queues each end in its outbox and a Forwarder ships it. Absent: no forwarding.
  std::optional<PlantConfig> plant;
  // Where the core's log records go: linecald's log. Empty: WriteLog (spdlog's default
  // logger). A cycle logs its start and end (info) and every event (debug), each with its
  // cycle id and VIN, as every warning or error about it.
  LogSink log;
};

// How long a stopped calibration (deadline, cancel) is waited for before it is left to end
// on its own: a frame's detection takes well under a second on the reference images.
inline constexpr std::chrono::milliseconds kCalibrationStopGrace{1000};
// Free bytes on the database's file system at which a full disk counts as over (Health):
// a cycle of the reference car writes about 10 MB of capture and tens of kB of results.
inline constexpr std::uint64_t kFreeBytesToServe = 16u << 20;

// Cycles the station status judges its health over: 200 cars hold a baseline of 180 before
// the alarm's 20 recent ones, and read in a few milliseconds.
inline constexpr int kHealthWindowCycles = 200;

struct CycleRequest {
  std::string vin;
  std::string car_model_id;
  AlignerMeasurement aligner;
  bool record_capture = false;  // keep the cycle's capture (simulator source) after the cycle
  int frames_per_sensor =
      0;  // camera frames and LiDAR rotations; 0: the configured default; at most 100
};

// The checks StartCycle makes before it touches the store: the VIN (ISO 3779, the check digit
// when `vin_check_digit`), a car model among `cars`, finite aligner values in range, frames
// per sensor in [0, 100]. InvalidArgument naming the field ("aligner.lateral_offset_m = 3: must
// be within +-1 m"). Pure; O(cars).
absl::Status ValidateCycleRequest(const CycleRequest& request, const std::vector<CarModel>& cars,
                                  bool vin_check_digit);

// A cycle id as the APIs (gRPC, the console's JSON) spell it: a positive decimal integer,
// else InvalidArgument naming cycle_id. Pure.
absl::StatusOr<int64_t> ParseCycleId(const std::string& id);

struct StationStatusInfo {
  std::string station_id;
  std::vector<std::string> car_models;
  std::string source;  // "simulator", "replay" (they serve every sensor) or "live"
  // live: sensor name -> what serves it (SensorSource::Describe, "udp 127.0.0.1:2368").
  std::map<std::string, std::string> sensor_sources;
  // Every sensor of the car models, by name (first car model first), with its kind.
  std::vector<std::pair<std::string, SensorKind>> sensors;
  std::optional<int64_t> running_cycle;
  std::string database_path;
  std::uint64_t disk_free_bytes = 0;
  std::optional<ForwarderStats> plant;            // with a `plant` section: the forwarding's state
  std::chrono::seconds plant_max_backlog_age{0};  // plant.max_backlog_age_s (Health)
  // Moved-target alarms over the newest kHealthWindowCycles cycles (station/health); empty
  // when none is raised or the store could not be read (health_error says why).
  std::vector<TargetAlarm> target_alarms;
  std::string health_error;

  // What serves `sensor`: its live source's description, else `source` (the simulator and a
  // recorded capture serve every sensor).
  std::string SourceOf(const std::string& sensor) const;
};

class StationCore {
 public:
  // Loads the station and car models, opens the store (cycles left running by a previous
  // process become aborted, and their partial captures/<VIN>-<start ns> are removed unless
  // the request asked to record them). Errors name the file and field; FailedPrecondition
  // when another process (or StationCore) holds the database (Store::Open).
  static absl::StatusOr<std::unique_ptr<StationCore>> Create(const StationCoreConfig& config);
  // Cancels a running cycle and waits for its thread.
  ~StationCore();
  StationCore(const StationCore&) = delete;
  StationCore& operator=(const StationCore&) = delete;

  // Validates and starts a cycle; returns its id once it is stored as running.
  absl::StatusOr<int64_t> StartCycle(const CycleRequest& request);
  // Asks the running cycle to stop at its next step; it ends as cancelled (OK means it
  // will). FailedPrecondition once the cycle has ended or is storing its end.
  absl::Status CancelCycle(int64_t cycle_id);
  absl::StatusOr<StoredCycle> GetCycle(int64_t cycle_id);
  absl::StatusOr<CyclePage> ListCycles(const CycleFilter& filter);
  // The capture of an ended cycle when it was kept (record_capture, or the replay source's),
  // read as a replay reads it: inside the data root after resolving links, ReadCapture under
  // the input budget. NotFound for an unknown cycle; FailedPrecondition while the cycle runs,
  // or when its capture was not kept or is gone ("capture_not_kept: ..."); InvalidArgument
  // when it resolves outside the data root or does not read. Cost: ReadCapture's (stat calls
  // and three small JSON files).
  absl::StatusOr<Capture> CycleCapture(int64_t cycle_id);
  // Calls on_event for every event of the cycle in order, those already stored first, then
  // as they come, until the cycle has ended and all its events were delivered (OK), or
  // on_event returns false (Cancelled: the watcher went away). NotFound for unknown ids.
  absl::Status WatchCycle(int64_t cycle_id,
                          const std::function<bool(const StoredEvent&)>& on_event);
  StationStatusInfo Status();
  // Trends, alarms and per-target counts over the newest `cycles` (1..100000) cycles that
  // ended done (ComputeStationHealth). InvalidArgument for the count or options; the store's
  // errors. Cost: one store query and O(cycles × sensors).
  absl::StatusOr<StationHealth> Trends(int cycles, const StationHealthOptions& options = {});
  // OK when the station can run and store cycles. Else why not: FailedPrecondition when the
  // data root or the database file was removed (until a restart), ResourceExhausted while
  // the disk is full (a cycle's end waiting to be stored, or the last write refused for want
  // of space, until a cycle starts or kFreeBytesToServe are free again), Unavailable while
  // the oldest cycle not yet at the plant database ended more than plant.max_backlog_age ago
  // (the backlog, that age and the forwarder's last error named; cycles still run). Tries to
  // store a waiting end first, so calling it is how the daemon recovers when space returns;
  // the first call after a change logs it. Cost: a few stat calls, at most one store write,
  // one count of the outbox.
  absl::Status Health();
  // Ships what the plant outbox holds until `deadline` while the plant answers, then stops
  // forwarding (Forwarder::Stop: never waits on a stalled plant past the deadline). Returns
  // the cycles left queued (sent at the next start); 0 without a `plant` section.
  int64_t StopForwarding(std::chrono::steady_clock::time_point deadline);
  // Blocks until no cycle runs (tests, shutdown).
  void WaitIdle();
  // The same, at most `timeout`; false when a cycle still runs.
  bool WaitIdleFor(std::chrono::milliseconds timeout);

  Store& store() { return *store_; }
  // The car models as loaded at Create (never changed after it, so safe from any thread).
  const std::vector<CarModel>& car_models() const { return cars_; }

 private:
  StationCore(StationCoreConfig config, StationLayout station, std::vector<CarModel> cars,
              std::unique_ptr<Store> store, std::unique_ptr<CaptureSource> capture_source);
  struct PendingCalibration;
  // A cycle's end as RunCycle decided it.
  struct CycleEnd {
    int64_t id = 0;
    std::string vin;  // the cycle's, for the log
    CycleState state = CycleState::kDone;
    Verdict verdict = Verdict::kError;
    std::string reason;
    int64_t ended_ns = 0;
    bool event_stored = false;  // its cycle_ended event is in the store
  };
  // An end in `state` with `reason` and verdict error (until the results decide it).
  static CycleEnd EndOf(int64_t id, CycleState state, std::string reason);

  // A cycle on the worker thread: its work, then its end decided, its capture removed unless
  // kept, and the end stored (StoreEnd) and published (running_ cleared, watchers woken).
  void RunCycle(int64_t id, CycleRequest request);
  // The cycle's work, acquire -> read -> calibrate -> store: the end it reached (state,
  // verdict, reason; not yet `ended_ns`). Every failing step ends it in error with a reason.
  CycleEnd WorkCycle(int64_t id, const CycleRequest& request, const CarModel& car,
                     const StoredCycle& stored);
  // Acquire: the capture source makes the cycle's capture readable in `dir`
  // (CaptureSource::Acquire, its events into the cycle's stream).
  absl::StatusOr<AcquiredCapture> AcquireCapture(int64_t id, const CycleRequest& request,
                                                 const CarModel& car, const StoredCycle& stored,
                                                 const std::string& dir);
  // Store: every sensor's result in the car model's order (a sensor that failed to acquire as
  // its `error`, reason "acquisition_failed: <message>") and its sensor_verdict event; the
  // end is done with the overall verdict and the not-passed sensors as reason, or error when
  // a result cannot be stored.
  CycleEnd StoreResults(int64_t id, const std::string& vin, const CarModel& car,
                        const std::map<std::string, std::string>& failures,
                        std::vector<SensorCalibration> calibrated);
  // Once the work is over: a cancel accepted until now makes the cycle cancelled (CancelCycle
  // refuses from now on); a data root or database removed meanwhile makes it an error.
  void DecideEnd(CycleEnd* end);
  // Stores the end (kept as unstored_end_ when it cannot be), logs what went wrong, wakes the
  // forwarder and the watchers and clears running_.
  void PublishEnd(const CycleEnd& end);
  // Calibrates `capture` of cycle `id` on its own thread, waiting until it is done, the
  // calibrate deadline passed (DeadlineExceeded) or the cycle was cancelled (Cancelled).
  absl::StatusOr<CycleCalibration> CalibrateWithDeadline(int64_t id, Capture capture);
  // Stores the end's event and the end, retrying while the store is locked (until the
  // destructor runs); the first other error is returned and `end` says what got stored.
  absl::Status StoreEnd(CycleEnd* end);
  // Stores unstored_end_, if any; OK when there is none left.
  absl::Status StoreUnstoredEnd();
  // OK while the plant backlog's oldest cycle is younger than plant.max_backlog_age (or
  // there is no forwarding); else Unavailable saying so (Health's words).
  absl::Status CheckPlantBacklog();
  // OK while the data root and the database file are the ones the core opened.
  absl::Status CheckStorage() const;
  // A failure as a cycle reason: "disk_full: <what>: <message>" when it is a full disk
  // (ResourceExhausted, or ENOSPC in the message), else "<what>: <message>" (no "<what>: "
  // when `what` is empty). Remembers a full disk for Health().
  std::string FailureReason(const std::string& what, const absl::Status& status);
  // One record to config_.log (else WriteLog); about cycle `cycle` (0: none) of `vin`.
  void Log(LogLevel level, const std::string& message, int64_t cycle = 0,
           const std::string& vin = "") const;
  // Joins calibrations abandoned at their deadline: those done, or all when `all`.
  void JoinAbandoned(bool all);
  // Stores an event of cycle `id` (of `vin`), wakes the watchers and logs it (debug).
  absl::Status Event(int64_t id, const std::string& vin, EventType type, const std::string& sensor,
                     const std::string& detail, std::optional<Verdict> verdict = std::nullopt);
  const CarModel* FindCar(const std::string& id) const;

  const StationCoreConfig config_;
  const StationLayout station_;
  const std::vector<CarModel> cars_;
  std::unique_ptr<Store> store_;
  // With a `plant` section; declared after store_, so destroyed (stopped) before it.
  std::unique_ptr<Forwarder> forwarder_;
  // What cycles calibrate from (config_.source); used by one cycle at a time.
  std::unique_ptr<CaptureSource> capture_source_;

  std::mutex mutex_;
  std::condition_variable changed_;  // an event was stored or a cycle ended
  std::optional<int64_t> running_;
  std::atomic<bool> cancel_{false};
  bool ending_ = false;  // the running cycle's end is decided: cancels are refused (under mutex_)
  std::atomic<bool> stopping_{false};  // the destructor runs: stop retrying a locked store
  std::thread worker_;
  // The end of the last cycle when the store refused it (disk full): stored before the next
  // cycle starts and by Health(); guarded by mutex_.
  std::optional<CycleEnd> unstored_end_;
  std::mutex unstored_end_mutex_;  // held by StoreUnstoredEnd, before mutex_
  bool disk_full_ = false;         // a store write was refused for want of space; under mutex_
  std::string last_health_;        // Health()'s last answer ("" = OK), to log changes; under mutex_
  // The data root's identity (st_dev, st_ino) when the core was created.
  std::uint64_t data_root_dev_ = 0, data_root_ino_ = 0;
  // Calibrations abandoned at their deadline, still running or done; guarded by mutex_.
  std::vector<std::pair<std::shared_ptr<PendingCalibration>, std::thread>> abandoned_;
};

}  // namespace linecal

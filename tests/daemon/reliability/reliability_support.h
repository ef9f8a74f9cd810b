#pragma once
// What the daemon's reliability programs (soak, crash) and tests share: the process's own
// resource counts from /proc, a linecald child process, and the replay capture they cycle on.

#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace linecal::reliability {

// Numbers of /proc/PID/status ("self" for this process).
struct ProcessStatus {
  std::int64_t rss_kb = 0;  // VmRSS: resident now
  std::int64_t hwm_kb = 0;  // VmHWM: the resident peak
  int threads = 0;
};
// NotFound when the process is gone; Internal when a field is missing. Cost: one small read.
absl::StatusOr<ProcessStatus> ReadProcessStatus(const std::string& pid = "self");

// Entries of a /proc directory ("/proc/self/task": threads, "/proc/self/fd": descriptors),
// once the count has stayed the same for 3 samples 20 ms apart (at most 1 s): a thread that
// has just finished its work leaves the list a moment later.
int SettledEntryCount(const std::string& proc_dir);

// A least-squares line through samples (x, y), x ascending: y ~ intercept + slope x, with
// the standard deviation of the residuals about it (`scatter`), their lag-1 autocorrelation
// (consecutive samples of a process with memory lie on the same side of the line) and the
// slope's standard error from both: scatter / sqrt(sum (x - mean x)^2), widened by
// sqrt((1 + r) / (1 - r)) for an autocorrelation r > 0 (an AR(1) series of n samples carries
// the information of n (1 - r) / (1 + r) independent ones). Fewer than 3 samples, or one x
// only: all 0.
struct LinearTrend {
  double slope = 0;
  double intercept = 0;
  double scatter = 0;
  double autocorrelation = 0;  // clamped to [0, 0.95]
  double slope_error = 0;
  int samples = 0;
};
LinearTrend FitLinearTrend(const std::vector<double>& x, const std::vector<double>& y);

// The soak's memory verdict on one series (resident set or heap in use, MB, sampled against
// the cycle number after warm-up): the line's rise over the run and projected over 1,000
// cycles. A leak when both hold: the projection exceeds `max_growth_per_1000` (MB), and the
// slope is more than `min_significance` standard errors above 0 (a series wandering in a
// band without a trend fits a slope within a few standard errors of 0; a leak rises above).
struct MemoryGrowth {
  LinearTrend trend;
  double run_growth = 0;       // slope x (last cycle - first cycle)
  double growth_per_1000 = 0;  // slope x 1000
  double significance = 0;     // slope / slope_error
  bool leak = false;
};
MemoryGrowth JudgeMemoryGrowth(const std::vector<double>& cycles, const std::vector<double>& mb,
                               double max_growth_per_1000, double min_significance);

// The soak's bounds (docs/reliability.md, "The soak"). Two points of the resident set are
// not a trend: over 1,000 cycles it wanders in a band of 51-88 MB (glibc's two arenas keep
// and give back the peaks of frames and clouds) while the heap in use moves by tenths of a MB.
// Resident set: docs/acceptance.md's "memory growth over 1,000 cycles < 5%", on the fitted
// line: at most 5% of the line's level at the end of the warm-up per 1,000 cycles.
inline constexpr double kSoakRssGrowthFractionPer1000 = 0.05;
// Heap in use (malloc): at most 4 MB per 1,000 cycles. Twice the 2 MB that SQLite's page
// cache (its default cache_size, -2000 KiB) grows to with the database, which is no leak; a
// leak of 4 kB per cycle, a stored result's strings, exceeds it.
inline constexpr double kSoakHeapGrowthMbPer1000 = 4.0;
// And a slope 4 standard errors above 0: with the autocorrelation taken into account a band
// without a trend stays below it (MemoryTrendTest: 20 independent and 20 wandering series of
// the soak's band), while 40 kB per cycle in the resident set or 5 kB per cycle in the heap is
// far above it.
inline constexpr double kSoakMinSignificance = 4.0;

// A VIN with its ISO 3779 check digit: every cycle of the programs is this car.
inline constexpr char kVin[] = "1M8GDM9AXKP042788";
// The reference station layout of the source tree (deploy/stations/reference.json).
std::string ReferenceStationPath();

// The flags both programs take, and their own by name.
struct ProgramFlags {
  int cycles = 0;                    // --cycles N (>= 1)
  std::uint64_t seed = 1;            // --seed S: the capture's simulation and every random draw
  std::vector<std::string> sensors;  // --sensors a,b,...: of the reference car; empty: all
  std::string dir;  // --dir DIR: the scratch directory (kept); empty: a fresh one, removed
  std::map<std::string, std::string> own;  // the program's own flags: "--rss-from" -> "100"
};
// Parses "--flag value" pairs over `defaults`; `own_flags` are the program's own names.
// InvalidArgument naming an unknown flag, a missing value or a bad --cycles or --seed.
absl::StatusOr<ProgramFlags> ParseProgramFlags(int argc, char** argv, ProgramFlags defaults,
                                               const std::vector<std::string>& own_flags);

// A program's scratch directory (emptied first): `car_path` is the reference car cut to the
// flags' sensors with car model id `car_id`, and `capture` (below the directory) its capture
// simulated with the flags' seed, one frame or rotation per sensor (the daemon's default).
// Errors: a sensor the reference car does not have (InvalidArgument naming it), files that
// cannot be written. Cost: the renders, a few seconds.
struct Workspace {
  std::filesystem::path dir;
  bool owned = false;  // made under /tmp: the program removes it
  std::string car_path;
};
absl::StatusOr<Workspace> PrepareWorkspace(const ProgramFlags& flags, const std::string& program,
                                           const std::string& car_id, const std::string& capture);

// A capture of the reference car's front camera (seed 9) in `dir` whose manifest lists
// `frames` frames, hard links of the one render: a calibration of `frames` detections, each
// a fraction of a second, for cycles that must still be calibrating when a test acts (a
// deadline, SIGTERM). Car model id "reference". Cost: one render and a second.
absl::Status WriteLongCameraCapture(const std::string& dir, int frames);

// Writes `path` until its file system has no byte left (ENOSPC, a block then single bytes):
// a full disk for the disk-full faults. Returns the bytes written. Cost: writing them.
std::uint64_t FillFileSystem(const std::string& path);

// A linecald started as a child process with its stderr appended to a log file. The
// destructor kills (SIGKILL) and reaps it if it still runs.
class LinecaldProcess {
 public:
  // Forks and execs `binary` with `args`; returns at once. Internal when fork fails. With a
  // `descriptor_limit`, the child's RLIMIT_NOFILE, soft and hard, is set to it before the
  // exec (linecald raises its soft limit to the hard one: both, so that the limit holds).
  static absl::StatusOr<std::unique_ptr<LinecaldProcess>> Spawn(
      const std::string& binary, const std::vector<std::string>& args, const std::string& log_path,
      std::uint64_t descriptor_limit = 0);
  ~LinecaldProcess();
  LinecaldProcess(const LinecaldProcess&) = delete;
  LinecaldProcess& operator=(const LinecaldProcess&) = delete;

  // Waits until the daemon's log (written since Spawn) names the port it listens on, which
  // it does once the store is open and calls are served; returns the port. Aborted when the
  // process exited first (it is not reaped: Wait gives its status), DeadlineExceeded after
  // `timeout`; both with the new part of the log.
  absl::StatusOr<int> WaitReady(std::chrono::milliseconds timeout);
  // Waits until the daemon's log (written since Spawn) contains `text`: OK, or
  // DeadlineExceeded after `timeout` with the new part of the log.
  absl::Status WaitForLog(const std::string& text, std::chrono::milliseconds timeout) const;
  // Sends `signal`; a process already gone is not an error.
  void Signal(int signal) const;
  // Reaps the process (once) and returns its wait status (as waitpid's).
  int Wait();

  pid_t pid() const { return pid_; }

 private:
  LinecaldProcess(pid_t pid, std::string log_path, std::uintmax_t log_offset)
      : pid_(pid), log_path_(std::move(log_path)), log_offset_(log_offset) {}
  std::string NewLog() const;

  pid_t pid_;
  bool reaped_ = false;
  int status_ = 0;  // once reaped
  std::string log_path_;
  std::uintmax_t log_offset_;  // the log's size at Spawn: what came before is older runs'
};

// TCP connections to 127.0.0.1 that never send a byte: what exhausts a server's descriptors
// (issue 21, item 2). The kernel completes each handshake into the listen backlog whether or
// not the server accepts it, so each Open succeeds while the backlog has room. Closed by
// Close() or the destructor.
class IdleConnections {
 public:
  IdleConnections() = default;
  ~IdleConnections() { Close(); }
  IdleConnections(const IdleConnections&) = delete;
  IdleConnections& operator=(const IdleConnections&) = delete;

  // `count` more connections to `port`; Internal naming the errno and how many were open
  // when a socket or a connect fails (those stay open).
  absl::Status Open(int port, int count);
  void Close();
  int size() const { return static_cast<int>(fds_.size()); }

 private:
  std::vector<int> fds_;
};

// "exit 0", "killed by signal 9", ...: a wait status for people.
std::string DescribeWaitStatus(int status);

}  // namespace linecal::reliability

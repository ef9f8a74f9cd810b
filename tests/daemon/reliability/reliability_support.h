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

// A VIN with its ISO 3779 check digit: every cycle of the programs is this car.
inline constexpr char kVin[] = "1M8GDM9AXKP042788";
// The reference station layout of the source tree (deploy/stations/reference.json).
std::string ReferenceStationPath();

// The flags both programs take, and their own by name.
struct ProgramFlags {
  int cycles = 0;                    // --cycles N (>= 1)
  std::uint64_t seed = 1;            // --seed S: the capture's simulation and every random draw
  std::vector<std::string> sensors;  // --sensors a,b,...: of the reference car; empty: all
  std::string dir;                   // --dir DIR: the scratch directory (kept); empty: a fresh one, removed
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
  // Forks and execs `binary` with `args`; returns at once. Internal when fork fails.
  static absl::StatusOr<std::unique_ptr<LinecaldProcess>> Spawn(const std::string& binary,
                                                               const std::vector<std::string>& args,
                                                               const std::string& log_path);
  ~LinecaldProcess();
  LinecaldProcess(const LinecaldProcess&) = delete;
  LinecaldProcess& operator=(const LinecaldProcess&) = delete;

  // Waits until the daemon's log (written since Spawn) names the port it listens on, which
  // it does once the store is open and calls are served; returns the port. Aborted when the
  // process exited first (it is not reaped: Wait gives its status), DeadlineExceeded after
  // `timeout`; both with the new part of the log.
  absl::StatusOr<int> WaitReady(std::chrono::milliseconds timeout);
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

// "exit 0", "killed by signal 9", ...: a wait status for people.
std::string DescribeWaitStatus(int status);

}  // namespace linecal::reliability

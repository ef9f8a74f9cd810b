// linecal-crash-test: linecald as a child process (replay source, its own SQLite file), cycles
// started and watched over gRPC on loopback, the daemon killed with SIGKILL at random moments
// and restarted. After every restart nothing the client saw committed may be lost or changed,
// and every interrupted cycle must be stored as aborted with reason daemon_restarted
// (docs/acceptance.md, "kill -9 at random moments in 100 cycles"; docs/reliability.md).
// `tools/crash-test` runs it.
//
//   linecal-crash-test [--cycles N] [--seed S] [--sensors a,b,...] [--linecald PATH] [--dir DIR]
//
// Round 0 measures the daemon's start-up and one cycle (no kill). Then N rounds: the client
// runs cycles back to back (StartCycle, WatchCycle to the end, GetCycle) and a killer thread
// sends SIGKILL at a moment drawn uniformly from 0 to 2.2 cycle times after the round's first
// StartCycle; every fifth round also kills the daemon once while it starts (opening the store,
// aborting the cycle left running), at a moment drawn up to its start-up time. The last
// restart also meets a second daemon on the same configuration, descriptors exhausted by idle
// connections (gRPC's accept fails with EMFILE; the same process must serve again once they
// close) and SIGHUP. Exit status 0 when every check held, 1 otherwise, 2 for bad flags or a
// failed setup.
#include <google/protobuf/util/message_differencer.h>
#include <grpcpp/grpcpp.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "daemon/store/store.h"
#include "linecal/v1/station.grpc.pb.h"
#include "tests/daemon/reliability/reliability_support.h"

namespace linecal::reliability {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr char kCarId[] = "crash";
// Generous for loopback calls and for a start-up on a loaded machine; a call that takes
// longer is a hang worth reporting.
constexpr std::chrono::seconds kCallDeadline{30};
constexpr std::chrono::seconds kStartTimeout{30};
// Every this many rounds the daemon is also killed while it starts.
constexpr int kStartupKillEvery = 5;

// What the client was doing when the daemon was killed.
enum Phase : int { kIdle, kStarting, kWatching, kReading, kPhases };
constexpr const char* kPhaseNames[kPhases] = {
    "between calls", "in StartCycle", "in WatchCycle (cycle running)", "in GetCycle (cycle ended)"};

std::chrono::system_clock::time_point Deadline() {
  return std::chrono::system_clock::now() + kCallDeadline;
}

struct Client {
  explicit Client(int port)
      : stub(v1::Station::NewStub(grpc::CreateChannel(absl::StrCat("127.0.0.1:", port),
                                                      grpc::InsecureChannelCredentials()))) {}

  grpc::Status Get(const std::string& id, v1::Cycle* out) {
    grpc::ClientContext context;
    context.set_deadline(Deadline());
    v1::GetCycleRequest request;
    request.set_cycle_id(id);
    return stub->GetCycle(&context, request, out);
  }

  // Every cycle stored, newest first.
  grpc::Status ListAll(std::vector<v1::Cycle>* out) {
    v1::ListCyclesRequest request;
    request.set_page_size(1000);  // the API's largest page
    do {
      grpc::ClientContext context;
      context.set_deadline(Deadline());
      v1::ListCyclesResponse page;
      if (grpc::Status s = stub->ListCycles(&context, request, &page); !s.ok()) return s;
      out->insert(out->end(), page.cycles().begin(), page.cycles().end());
      request.set_page_token(page.next_page_token());
    } while (!request.page_token().empty());
    return grpc::Status::OK;
  }

  std::unique_ptr<v1::Station::Stub> stub;
};

struct Run {
  ProgramFlags flags;
  std::string linecald;
  fs::path dir;
  std::string config_path, log_path, db_path;
  std::mt19937_64 rng;
  // Cycles the client saw ended (GetCycle after the watch): exactly this after every restart.
  std::map<std::string, v1::Cycle> committed;
  // Started (StartCycle answered) but not seen ended; `watched_to_end`: the watch stream
  // ended OK, so the end was committed even if GetCycle did not get through.
  std::map<std::string, bool> pending;
  std::vector<std::string> violations;
  int interrupted = 0, ended_unseen = 0, unacknowledged = 0, started = 0, startup_kills = 0,
      cycle_kills = 0;
  int phase_kills[kPhases] = {};
  double startup_s = 0, cycle_s = 0;
  std::int64_t rss_after_cycle_kb = 0;
};

void Violation(Run& r, const std::string& what) {
  r.violations.push_back(what);
  std::fprintf(stderr, "linecal-crash-test: %s\n", what.c_str());
}

absl::StatusOr<std::unique_ptr<LinecaldProcess>> Spawn(const Run& r) {
  return LinecaldProcess::Spawn(r.linecald, {"--config", r.config_path}, r.log_path);
}

std::string Describe(const v1::Cycle& c) {
  return absl::StrCat(v1::CycleState_Name(c.state()), " ", v1::Verdict_Name(c.verdict()), " '",
                      c.reason(), "'");
}

// After a restart: every committed cycle as it was, every pending one ended or aborted,
// nothing running, and cycles the client never heard of (killed inside StartCycle) ended.
void Verify(Run& r, Client& client, const std::string& when) {
  for (const auto& [id, before] : r.committed) {
    v1::Cycle now;
    if (grpc::Status s = client.Get(id, &now); !s.ok()) {
      Violation(r, absl::StrCat(when, ": committed cycle ", id, " lost: ", s.error_message()));
    } else if (!google::protobuf::util::MessageDifferencer::Equals(before, now)) {
      Violation(r, absl::StrCat(when, ": committed cycle ", id, " changed: was ", Describe(before),
                                ", now ", Describe(now)));
    }
  }
  for (const auto& [id, watched_to_end] : r.pending) {
    v1::Cycle now;
    if (grpc::Status s = client.Get(id, &now); !s.ok()) {
      Violation(r, absl::StrCat(when, ": started cycle ", id, " lost: ", s.error_message()));
      continue;
    }
    if (now.state() == v1::CYCLE_STATE_ABORTED) {
      if (now.reason() != "daemon_restarted" || now.verdict() != v1::VERDICT_ERROR) {
        Violation(r, absl::StrCat(when, ": interrupted cycle ", id, " is ", Describe(now)));
      }
      if (watched_to_end)
        Violation(r, absl::StrCat(when, ": cycle ", id, " was seen ended, now aborted"));
      ++r.interrupted;
    } else if (now.state() == v1::CYCLE_STATE_DONE || now.state() == v1::CYCLE_STATE_CANCELLED) {
      ++r.ended_unseen;  // its end was committed just before the kill
    } else {
      Violation(r, absl::StrCat(when, ": cycle ", id, " is ", Describe(now), " after a restart"));
    }
    r.committed[id] = now;
  }
  r.pending.clear();
  std::vector<v1::Cycle> all;
  if (grpc::Status s = client.ListAll(&all); !s.ok()) {
    Violation(r, absl::StrCat(when, ": ListCycles: ", s.error_message()));
    return;
  }
  for (const v1::Cycle& c : all) {
    if (r.committed.count(c.cycle_id())) continue;
    // Stored by a StartCycle whose answer the kill cut off.
    if (c.state() == v1::CYCLE_STATE_RUNNING || c.state() == v1::CYCLE_STATE_UNSPECIFIED) {
      Violation(r,
                absl::StrCat(when, ": unacknowledged cycle ", c.cycle_id(), " is ", Describe(c)));
    }
    ++r.unacknowledged;
    v1::Cycle full;
    if (client.Get(c.cycle_id(), &full).ok()) r.committed[c.cycle_id()] = full;
  }
  if (all.size() != r.committed.size()) {
    Violation(
        r, absl::StrCat(when, ": ", all.size(), " cycles listed, ", r.committed.size(), " known"));
  }
}

// One cycle through the API, as `linecal cycle start --wait` runs it: StartCycle, WatchCycle
// to the stream's end, GetCycle. `phase` follows the calls; on_started gets the id as soon
// as StartCycle answers. Fails with the first failed call, named.
struct CycleCall {
  std::string id;
  bool watched_to_end = false;  // the stream ended OK after cycle_ended: the end is committed
  v1::Cycle cycle;
};
absl::Status OneCycle(Client& client, std::atomic<int>* phase,
                      const std::function<void(const std::string&)>& on_started, CycleCall* out) {
  const auto failed = [](const char* call, const grpc::Status& s) {
    return absl::UnavailableError(absl::StrCat(call, ": ", s.error_message()));
  };
  *phase = kStarting;
  {
    v1::StartCycleRequest request;
    request.set_vin(kVin);
    request.set_car_model_id(kCarId);
    v1::StartCycleResponse response;
    grpc::ClientContext context;
    context.set_deadline(Deadline());
    if (grpc::Status s = client.stub->StartCycle(&context, request, &response); !s.ok())
      return failed("StartCycle", s);
    out->id = response.cycle_id();
  }
  on_started(out->id);
  *phase = kWatching;
  {
    grpc::ClientContext context;
    context.set_deadline(Deadline());
    v1::WatchCycleRequest watch;
    watch.set_cycle_id(out->id);
    std::unique_ptr<grpc::ClientReader<v1::CycleEvent>> reader =
        client.stub->WatchCycle(&context, watch);
    v1::CycleEvent event;
    bool ended = false;
    while (reader->Read(&event)) ended |= event.type() == v1::CycleEvent::TYPE_CYCLE_ENDED;
    if (grpc::Status s = reader->Finish(); !s.ok()) return failed("WatchCycle", s);
    if (!ended)
      return absl::InternalError(
          absl::StrCat("cycle ", out->id, ": the watch ended OK without cycle_ended"));
    out->watched_to_end = true;
  }
  *phase = kReading;
  if (grpc::Status s = client.Get(out->id, &out->cycle); !s.ok()) return failed("GetCycle", s);
  *phase = kIdle;
  if (out->cycle.state() == v1::CYCLE_STATE_RUNNING) {
    return absl::InternalError(
        absl::StrCat("cycle ", out->id, " still running after its watch ended"));
  }
  return absl::OkStatus();
}

// A second linecald on the same configuration while `first` runs (issue 21): it must stop
// before it listens, naming the lock file and the first daemon's pid; what it must not do
// (abort the first one's cycles) the Verify after it checks.
void SecondDaemonRefused(Run& r, pid_t first) {
  absl::StatusOr<std::unique_ptr<LinecaldProcess>> second =
      LinecaldProcess::Spawn(r.linecald, {"--config", r.config_path}, r.log_path + ".second");
  if (!second.ok()) return Violation(r, absl::StrCat("second daemon: ", second.status().message()));
  const absl::StatusOr<int> port = (*second)->WaitReady(kStartTimeout);
  if (port.ok()) return Violation(r, absl::StrCat("second daemon: listens on port ", *port));
  const int status = (*second)->Wait();
  const std::string holder = absl::StrCat("in use by another linecald (pid ", first,
                                          " holds the lock file ", r.db_path, ".lock)");
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 2 ||
      port.status().message().find(holder) == std::string::npos) {
    Violation(r, absl::StrCat("second daemon: ", DescribeWaitStatus(status), ", ",
                              port.status().message()));
  }
}

// Issue 21, item 2: the running daemon's descriptors exhausted by idle connections, then
// freed. Its soft RLIMIT_NOFILE is lowered (prlimit) to what it has open plus
// kDescriptorHeadroom, and kDescriptorHeadroom + 100 connections that send nothing are opened:
// gRPC's accept4 fails with EMFILE (its log says so), after which gRPC 1.51 would never accept
// again. Once they close, the same process must serve a call on a new connection within
// kCallDeadline; the limit is then restored. Returns the seconds from the close to the call's
// answer (-1 after a violation).
constexpr int kDescriptorHeadroom = 64;
double DescriptorsExhausted(Run& r, const LinecaldProcess& daemon, int port) {
  const pid_t pid = daemon.pid();
  rlimit before{};
  if (::prlimit(pid, RLIMIT_NOFILE, nullptr, &before) != 0) {
    Violation(r, absl::StrCat("descriptors: prlimit: ", std::strerror(errno)));
    return -1;
  }
  const rlim_t open = static_cast<rlim_t>(std::distance(
      fs::directory_iterator(absl::StrCat("/proc/", pid, "/fd")), fs::directory_iterator{}));
  const rlimit lowered{open + kDescriptorHeadroom, before.rlim_max};
  if (::prlimit(pid, RLIMIT_NOFILE, &lowered, nullptr) != 0) {
    Violation(r, absl::StrCat("descriptors: prlimit: ", std::strerror(errno)));
    return -1;
  }
  double served_s = -1;
  {
    IdleConnections idle;
    if (absl::Status s = idle.Open(port, kDescriptorHeadroom + 100); !s.ok()) {
      Violation(r, absl::StrCat("descriptors: ", s.message()));
    } else if (absl::Status s =
                   daemon.WaitForLog("Failed accept4: Too many open files", kCallDeadline);
               !s.ok()) {
      Violation(r, absl::StrCat("descriptors: accept never failed: ", s.message()));
    } else {
      idle.Close();
      const Clock::time_point t0 = Clock::now();
      // A new connection: a channel of its own subchannel pool (channels to the same target
      // share their connections by default, and the client's is still open).
      grpc::ChannelArguments arguments;
      arguments.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
      std::unique_ptr<v1::Station::Stub> fresh = v1::Station::NewStub(grpc::CreateCustomChannel(
          absl::StrCat("127.0.0.1:", port), grpc::InsecureChannelCredentials(), arguments));
      grpc::ClientContext context;
      context.set_deadline(Deadline());
      context.set_wait_for_ready(true);  // through the restart
      v1::StationStatus status;
      if (grpc::Status st = fresh->GetStationStatus(&context, {}, &status); !st.ok()) {
        Violation(r, absl::StrCat("descriptors: no call served on a new connection after they ",
                                  "freed up: ", st.error_message()));
      } else {
        served_s = std::chrono::duration<double>(Clock::now() - t0).count();
      }
    }
  }
  if (::prlimit(pid, RLIMIT_NOFILE, &before, nullptr) != 0) {
    Violation(r, absl::StrCat("descriptors: restoring the limit: ", std::strerror(errno)));
  }
  return served_s;
}

// Starts a cycle; returns its id, or "" after a violation.
std::string StartOnly(Run& r, Client& client) {
  v1::StartCycleRequest request;
  request.set_vin(kVin);
  request.set_car_model_id(kCarId);
  v1::StartCycleResponse response;
  grpc::ClientContext context;
  context.set_deadline(Deadline());
  if (grpc::Status s = client.stub->StartCycle(&context, request, &response); !s.ok()) {
    Violation(r, "final StartCycle: " + s.error_message());
  }
  return response.cycle_id();
}

// Runs cycles back to back until a call fails; a failure before `killed` is a violation.
void CycleLoop(Run& r, Client& client, const std::atomic<bool>& killed, std::atomic<int>* phase) {
  while (true) {
    CycleCall call;
    const absl::Status s = OneCycle(
        client, phase,
        [&](const std::string& id) {
          ++r.started;
          r.pending[id] = false;
        },
        &call);
    if (call.watched_to_end) r.pending[call.id] = true;
    if (!s.ok()) {
      if (!killed || s.code() != absl::StatusCode::kUnavailable) {
        Violation(r, absl::StrCat(s.message(), killed ? "" : " (the daemon alive)"));
      }
      return;
    }
    r.committed[call.id] = call.cycle;
    r.pending.erase(call.id);
  }
}

// The scratch paths of `r` under workspace.dir and linecald's configuration file: the
// reference station and the workspace's car, replaying the capture.
void WriteConfig(Run& r, const Workspace& workspace) {
  r.config_path = (r.dir / "linecald.json").string();
  r.log_path = (r.dir / "linecald.log").string();
  r.db_path = (r.dir / "data" / "linecal.db").string();
  std::ofstream(r.config_path) << nlohmann::json{
      {"listen", "127.0.0.1:0"},
      {"station_id", "crash"},
      {"station", ReferenceStationPath()},
      {"car_models", {workspace.car_path}},
      {"data_root", "data"},
      {"db", "linecal.db"},
      {"source",
       {{"type", "replay"},
        {"capture", "replay"}}}}.dump(2);
}

// Round 0: the start-up and cycle times the kill moments are drawn against (r.startup_s,
// r.cycle_s), one cycle that must end done, then SIGTERM. The error is a setup failure.
absl::Status RoundZero(Run& r) {
  const Clock::time_point t0 = Clock::now();
  absl::StatusOr<std::unique_ptr<LinecaldProcess>> daemon = Spawn(r);
  if (!daemon.ok()) return daemon.status();
  absl::StatusOr<int> port = (*daemon)->WaitReady(kStartTimeout);
  if (!port.ok()) return port.status();
  r.startup_s = std::chrono::duration<double>(Clock::now() - t0).count();
  Client client(*port);
  std::atomic<int> phase{kIdle};
  CycleCall call;
  const Clock::time_point c0 = Clock::now();
  if (absl::Status s = OneCycle(
          client, &phase, [](const std::string&) {}, &call);
      !s.ok())
    return s;
  r.cycle_s = std::chrono::duration<double>(Clock::now() - c0).count();
  if (call.cycle.state() != v1::CYCLE_STATE_DONE) {
    return absl::InternalError("round 0's cycle ended " + Describe(call.cycle));
  }
  ++r.started;
  r.committed[call.id] = call.cycle;
  r.rss_after_cycle_kb =
      ReadProcessStatus(std::to_string((*daemon)->pid())).value_or(ProcessStatus{}).rss_kb;
  (*daemon)->Signal(SIGTERM);
  const int status = (*daemon)->Wait();
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    Violation(r, "round 0: SIGTERM: " + DescribeWaitStatus(status));
  }
  return absl::OkStatus();
}

// Round `round` (1..): every kStartupKillEvery-th round a daemon killed while starting; then
// a daemon started and verified, and killed at a random moment of its cycles; a progress line
// every 10 rounds. False when it did not restart (a violation: the rounds end); the error is
// a setup failure.
absl::StatusOr<bool> KillRound(Run& r, int round, Clock::time_point start) {
  const std::string when = absl::StrCat("round ", round);
  if (round % kStartupKillEvery == 0) {
    absl::StatusOr<std::unique_ptr<LinecaldProcess>> daemon = Spawn(r);
    if (!daemon.ok()) return daemon.status();
    std::this_thread::sleep_for(std::chrono::duration<double>(
        std::uniform_real_distribution<double>(0, r.startup_s)(r.rng)));
    (*daemon)->Signal(SIGKILL);
    const int status = (*daemon)->Wait();
    // Killed, or it had already started and was killed idle: both fine; exiting otherwise is not.
    if (!(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL)) {
      Violation(r, absl::StrCat(when, ": killed while starting: ", DescribeWaitStatus(status)));
    }
    ++r.startup_kills;
  }
  absl::StatusOr<std::unique_ptr<LinecaldProcess>> daemon = Spawn(r);
  if (!daemon.ok()) return daemon.status();
  absl::StatusOr<int> port = (*daemon)->WaitReady(kStartTimeout);
  if (!port.ok()) {
    Violation(r, absl::StrCat(when, ": restart: ", port.status().message()));
    return false;
  }
  Client client(*port);
  Verify(r, client, when);

  // Armed now, just before the round's first StartCycle.
  std::atomic<bool> killed{false};
  std::atomic<int> phase{kIdle};
  const double kill_after_s = std::uniform_real_distribution<double>(0, 2.2 * r.cycle_s)(r.rng);
  std::thread killer([&] {
    std::this_thread::sleep_for(std::chrono::duration<double>(kill_after_s));
    ++r.phase_kills[phase.load()];
    killed = true;
    (*daemon)->Signal(SIGKILL);
  });
  CycleLoop(r, client, killed, &phase);
  killer.join();
  const int status = (*daemon)->Wait();
  if (!(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL)) {
    Violation(r, absl::StrCat(when, ": the daemon ended by itself: ", DescribeWaitStatus(status)));
  }
  ++r.cycle_kills;
  if (round % 10 == 0 || round == r.flags.cycles) {
    std::printf("  round %3d  %6.1f s  cycles started %d  violations %zu\n", round,
                std::chrono::duration<double>(Clock::now() - start).count(), r.started,
                r.violations.size());
    std::fflush(stdout);
  }
  return true;
}

// What the final restart and the clean stop leave, for the report.
struct FinalState {
  int final_status = -1;             // the wait status after SIGHUP
  std::string last_id;               // the cycle running at SIGHUP
  double descriptors_served_s = -1;  // after the descriptors freed up; -1: not served
  absl::Status integrity = absl::UnknownError("not opened");
  int aborted_at_open = -1;  // cycles running at the store's last open
};

// The last restart: everything verified once more, also after a second daemon on the same
// configuration was refused and after its descriptors ran out; then a cycle started and
// SIGHUP, which must drain as SIGTERM does (exit 0, the cycle cancelled or, had it ended
// first, done). The error is a setup failure.
absl::Status FinalRestart(Run& r, FinalState* f) {
  absl::StatusOr<std::unique_ptr<LinecaldProcess>> daemon = Spawn(r);
  if (!daemon.ok()) return daemon.status();
  absl::StatusOr<int> port = (*daemon)->WaitReady(kStartTimeout);
  if (port.ok()) {
    Client client(*port);
    Verify(r, client, "final restart");
    SecondDaemonRefused(r, (*daemon)->pid());
    Verify(r, client, "after a second daemon");
    f->descriptors_served_s = DescriptorsExhausted(r, **daemon, *port);
    // A new channel: the restarted gRPC server closed the old one's connection.
    Client again(*port);
    Verify(r, again, "after the descriptors ran out");
    f->last_id = StartOnly(r, again);
  } else {
    Violation(r, absl::StrCat("final restart: ", port.status().message()));
  }
  (*daemon)->Signal(SIGHUP);
  f->final_status = (*daemon)->Wait();
  if (!WIFEXITED(f->final_status) || WEXITSTATUS(f->final_status) != 0) {
    Violation(r, "final SIGHUP: " + DescribeWaitStatus(f->final_status));
  }
  return absl::OkStatus();
}

// The file itself after the clean stop: its integrity, no cycle left running, the cycle
// running at SIGHUP cancelled or done.
void CheckStoreAfterStop(Run& r, FinalState* f) {
  if (absl::StatusOr<std::unique_ptr<Store>> store = Store::Open(r.db_path); store.ok()) {
    f->integrity = (*store)->IntegrityCheck();
    f->aborted_at_open = (*store)->aborted_at_open();
    int64_t id = 0;
    if (absl::SimpleAtoi(f->last_id, &id)) {
      const absl::StatusOr<StoredCycle> last = (*store)->GetCycle(id);
      const bool ended =
          last.ok() && (last->state == CycleState::kCancelled || last->state == CycleState::kDone);
      if (!ended) {
        Violation(r,
                  absl::StrCat("the cycle running at SIGHUP: ",
                               last.ok() ? CycleStateName(last->state) : last.status().ToString()));
      }
    }
  } else {
    f->integrity = store.status();
  }
  if (!f->integrity.ok()) Violation(r, "integrity_check: " + f->integrity.ToString());
  if (f->aborted_at_open != 0)
    Violation(r, absl::StrCat(f->aborted_at_open, " cycles running after the clean stop"));
}

// The report on stdout: kills, cycles, what the store holds, and every violation.
void PrintReport(const Run& r, Clock::time_point start, const FinalState& f) {
  std::printf("\n%d rounds in %.1f s: %d kills during cycles, %d during start-up\n", r.flags.cycles,
              std::chrono::duration<double>(Clock::now() - start).count(), r.cycle_kills,
              r.startup_kills);
  std::printf("kills by what the client was doing:\n");
  for (int p = 0; p < kPhases; ++p) std::printf("  %-32s %d\n", kPhaseNames[p], r.phase_kills[p]);
  std::printf("cycles started (answered): %d; stored in all: %zu\n", r.started, r.committed.size());
  std::printf("  interrupted, stored aborted (daemon_restarted): %d\n", r.interrupted);
  std::printf("  ended just before the kill, unseen by the client: %d\n", r.ended_unseen);
  std::printf("  stored by a StartCycle whose answer the kill cut off: %d\n", r.unacknowledged);
  std::printf("daemon RSS after one cycle: %.1f MB\n", r.rss_after_cycle_kb / 1024.0);
  if (f.descriptors_served_s >= 0) {
    std::printf(
        "descriptors exhausted (accept4 EMFILE): a new connection served %.1f s after they "
        "freed up, same process\n",
        f.descriptors_served_s);
  } else {
    std::printf("descriptors exhausted: not served again (see the violations)\n");
  }
  std::printf("integrity_check: %s; final SIGHUP: %s; running at the last open: %d\n",
              f.integrity.ok() ? "ok" : std::string(f.integrity.message()).c_str(),
              DescribeWaitStatus(f.final_status).c_str(), f.aborted_at_open);
  std::printf("violations: %zu\n", r.violations.size());
  for (const std::string& v : r.violations) std::printf("  %s\n", v.c_str());
}

int Main(const ProgramFlags& flags, const std::string& linecald) {
  absl::StatusOr<Workspace> workspace = PrepareWorkspace(flags, "crash", kCarId, "data/replay");
  if (!workspace.ok()) {
    std::fprintf(stderr, "linecal-crash-test: setup: %s\n", workspace.status().ToString().c_str());
    return 2;
  }
  Run r;
  r.flags = flags;
  r.linecald = linecald;
  r.rng.seed(flags.seed);
  r.dir = workspace->dir;
  const auto setup_failed = [&](const absl::Status& s) {
    std::fprintf(stderr, "linecal-crash-test: setup: %s\n", s.ToString().c_str());
    if (workspace->owned) fs::remove_all(r.dir);
    return 2;
  };
  WriteConfig(r, *workspace);
  std::printf("linecal-crash-test: %d rounds, seed %llu, scratch %s\n", flags.cycles,
              static_cast<unsigned long long>(flags.seed), r.dir.c_str());
  const Clock::time_point start = Clock::now();
  if (absl::Status s = RoundZero(r); !s.ok()) return setup_failed(s);
  std::printf("  start-up %.0f ms, one cycle %.0f ms (round 0)\n", r.startup_s * 1e3,
              r.cycle_s * 1e3);
  for (int round = 1; round <= flags.cycles; ++round) {
    const absl::StatusOr<bool> go_on = KillRound(r, round, start);
    if (!go_on.ok()) return setup_failed(go_on.status());
    if (!*go_on) break;
  }
  FinalState f;
  if (absl::Status s = FinalRestart(r, &f); !s.ok()) return setup_failed(s);
  CheckStoreAfterStop(r, &f);
  PrintReport(r, start, f);
  if (workspace->owned && r.violations.empty()) fs::remove_all(r.dir);
  return r.violations.empty() ? 0 : 1;
}

}  // namespace
}  // namespace linecal::reliability

int main(int argc, char** argv) {
  using linecal::reliability::ProgramFlags;
  ProgramFlags defaults;
  defaults.cycles = 100;  // docs/acceptance.md: kill -9 at random moments in 100 cycles
  const absl::StatusOr<ProgramFlags> flags =
      linecal::reliability::ParseProgramFlags(argc, argv, defaults, {"--linecald"});
  if (!flags.ok()) {
    std::fprintf(stderr,
                 "linecal-crash-test: %s\nusage: linecal-crash-test [--cycles N] [--seed S] "
                 "[--sensors a,b,...] "
                 "[--linecald PATH] [--dir DIR]\n",
                 std::string(flags.status().message()).c_str());
    return 2;
  }
  const auto linecald = flags->own.find("--linecald");
  return linecal::reliability::Main(
      *flags, linecald != flags->own.end() ? linecald->second
                                           : std::string(LINECAL_BINARY_DIR) + "/bin/linecald");
}

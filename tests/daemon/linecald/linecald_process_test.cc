// linecald as a real process (the demo station: every sensor of the reference car simulated,
// a scratch data directory, a free loopback port) under what a station network and its
// operators do to it: a second daemon on the same database, SIGHUP, flags out of range, the
// descriptor limit and descriptors running out under a real RLIMIT_NOFILE (docs/daemon.md,
// docs/reliability.md).
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "daemon/store/store.h"
#include "linecal/v1/station.grpc.pb.h"
#include "tests/daemon/reliability/reliability_support.h"
#include "tests/daemon/scratch_dir.h"
#include "tests/daemon/test_pki.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using reliability::DescribeWaitStatus;
using reliability::LinecaldProcess;
using std::chrono::seconds;

const std::string kLinecald = std::string(LINECAL_BINARY_DIR) + "/bin/linecald";
// Start-up, calls and drains on a loaded 2-core machine, under the sanitizers too: generous,
// a hang still fails.
constexpr seconds kTimeout{60};
// Frames per sensor of the cycles that must still be running when the test acts on them:
// 4 renders per camera of the reference car take seconds (about 1.5 s per frame for the car),
// far longer than a second daemon takes to start and stop (0.2 s).
constexpr uint32_t kLongCycleFrames = 4;

std::string ReadFile(const fs::path& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

std::string WriteReplayConfig(const fs::path& dir, const std::string& data_dir,
                              const std::string& extra);

class LinecaldProcessTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = testing_daemon::FreshTestDir("linecald_process"); }
  void TearDown() override { fs::remove_all(dir_); }

  std::string DataDir() const { return (dir_ / "data").string(); }
  std::string LogPath(const std::string& name) const { return (dir_ / (name + ".log")).string(); }

  // linecald on the demo station with this test's data directory, through `sh -c` when
  // `shell_prefix` is given (e.g. "ulimit -n 64 &&"), so that the limit is the daemon's own.
  std::unique_ptr<LinecaldProcess> Spawn(const std::string& log_name,
                                         const std::vector<std::string>& flags,
                                         const std::string& shell_prefix = "") {
    std::vector<std::string> args = {"--data-dir", DataDir()};
    args.insert(args.end(), flags.begin(), flags.end());
    absl::StatusOr<std::unique_ptr<LinecaldProcess>> p;
    if (shell_prefix.empty()) {
      p = LinecaldProcess::Spawn(kLinecald, args, LogPath(log_name));
    } else {
      std::vector<std::string> sh = {"-c", shell_prefix + " exec \"$0\" \"$@\"", kLinecald};
      sh.insert(sh.end(), args.begin(), args.end());
      p = LinecaldProcess::Spawn("/bin/sh", sh, LogPath(log_name));
    }
    EXPECT_TRUE(p.ok()) << p.status();
    return p.ok() ? *std::move(p) : nullptr;
  }

  // linecald with these flags only (no --data-dir: a --config names its data root).
  std::unique_ptr<LinecaldProcess> SpawnConfig(const std::string& log_name,
                                               const std::vector<std::string>& flags) {
    absl::StatusOr<std::unique_ptr<LinecaldProcess>> p =
        LinecaldProcess::Spawn(kLinecald, flags, LogPath(log_name));
    EXPECT_TRUE(p.ok()) << p.status();
    return p.ok() ? *std::move(p) : nullptr;
  }

  // A replay configuration over a capture of 600 camera frames (a minute of detections or
  // more, so a cycle is still running whenever a test acts on it, and the calibration stops
  // at its next frame, sanitized builds too), with a calibrate deadline of 10 min.
  std::string WriteLongReplay() {
    EXPECT_TRUE(reliability::WriteLongCameraCapture(DataDir() + "/long", 600).ok());
    return WriteReplayConfig(dir_, DataDir(), "\"deadlines_ms\": {\"calibrate\": 600000}");
  }

  static std::unique_ptr<v1::Station::Stub> Stub(int port) {
    return v1::Station::NewStub(grpc::CreateChannel("127.0.0.1:" + std::to_string(port),
                                                    grpc::InsecureChannelCredentials()));
  }

  // Starts a cycle of kLongCycleFrames frames per sensor; returns its id ("" on failure).
  static std::string StartLongCycle(v1::Station::Stub& stub) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + kTimeout);
    v1::StartCycleRequest request;
    request.set_vin(reliability::kVin);
    request.set_car_model_id("reference");
    request.mutable_options()->set_frames_per_sensor(kLongCycleFrames);
    v1::StartCycleResponse response;
    const grpc::Status s = stub.StartCycle(&context, request, &response);
    EXPECT_TRUE(s.ok()) << s.error_message();
    return response.cycle_id();
  }

  static v1::Cycle GetCycle(v1::Station::Stub& stub, const std::string& id) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + kTimeout);
    v1::GetCycleRequest request;
    request.set_cycle_id(id);
    v1::Cycle cycle;
    const grpc::Status s = stub.GetCycle(&context, request, &cycle);
    EXPECT_TRUE(s.ok()) << s.error_message();
    return cycle;
  }

  // The stored cycle, read from the database once no daemon holds it.
  StoredCycle StoredAfterExit(const std::string& id) {
    absl::StatusOr<std::unique_ptr<Store>> store = Store::Open(DataDir() + "/linecal.db");
    EXPECT_TRUE(store.ok()) << store.status();
    if (!store.ok()) return {};
    EXPECT_EQ(*(*store)->RunningCycle(), std::nullopt);
    absl::StatusOr<StoredCycle> cycle = (*store)->GetCycle(std::stoll(id));
    EXPECT_TRUE(cycle.ok()) << cycle.status();
    return cycle.ok() ? *cycle : StoredCycle{};
  }

  void ExpectServedAgainAfterDescriptorsRanOut(
      const std::vector<std::string>& args,
      const std::shared_ptr<grpc::ChannelCredentials>& credentials);

  // Waits for a daemon that must stop before it serves: its exit status, or -1 when it
  // listened instead (then it is killed by the destructor): a failure, not a hang.
  static int ExitBeforeListening(LinecaldProcess& daemon) {
    const absl::StatusOr<int> port = daemon.WaitReady(kTimeout);
    EXPECT_EQ(port.status().code(), absl::StatusCode::kAborted)
        << "it listens on port " << port.value_or(0);
    return port.ok() ? -1 : daemon.Wait();
  }

  fs::path dir_;
};

// Issue 21, item 3: a second linecald on the same database used to open it, turn the first
// one's running cycle into `aborted` and only then fail to listen. Now it stops before the
// store opens, naming the lock file and the first daemon's pid, and the cycle goes on.
TEST_F(LinecaldProcessTest, SecondDaemonOnTheSameDatabaseExitsNamingTheHolder) {
  const std::string config = WriteLongReplay();
  std::unique_ptr<LinecaldProcess> first = SpawnConfig("first", {"--config", config});
  ASSERT_NE(first, nullptr);
  const absl::StatusOr<int> port = first->WaitReady(kTimeout);
  ASSERT_TRUE(port.ok()) << port.status();
  std::unique_ptr<v1::Station::Stub> stub = Stub(*port);
  const std::string id = StartLongCycle(*stub);
  ASSERT_FALSE(id.empty());

  // The same configuration: the same database and port.
  std::unique_ptr<LinecaldProcess> second =
      SpawnConfig("second", {"--config", config, "--listen", "127.0.0.1:" + std::to_string(*port)});
  ASSERT_NE(second, nullptr);
  const int status = ExitBeforeListening(*second);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2) << DescribeWaitStatus(status);
  const std::string lock = DataDir() + "/linecal.db.lock";
  EXPECT_NE(ReadFile(LogPath("second"))
                .find("in use by another linecald (pid " + std::to_string(first->pid()) +
                      " holds the lock file " + lock + ")"),
            std::string::npos)
      << ReadFile(LogPath("second"));
  // The first daemon's cycle was not touched: still running (its 600 frames take far longer
  // than the second daemon's start), not aborted.
  EXPECT_EQ(GetCycle(*stub, id).state(), v1::CYCLE_STATE_RUNNING);

  first->Signal(SIGTERM);
  const int first_status = first->Wait();
  EXPECT_TRUE(WIFEXITED(first_status) && WEXITSTATUS(first_status) == 0)
      << DescribeWaitStatus(first_status);
  const StoredCycle cycle = StoredAfterExit(id);
  EXPECT_EQ(cycle.state, CycleState::kCancelled);
  EXPECT_EQ(cycle.reason, "cancelled");
}

// Issue 21, item 8: SIGHUP used to kill linecald (exit 129) with its cycle left `running`.
// It now drains as SIGTERM does: the cycle ends cancelled, and the exit is 0.
TEST_F(LinecaldProcessTest, SighupDrainsLikeSigterm) {
  std::unique_ptr<LinecaldProcess> daemon = SpawnConfig("daemon", {"--config", WriteLongReplay()});
  ASSERT_NE(daemon, nullptr);
  const absl::StatusOr<int> port = daemon->WaitReady(kTimeout);
  ASSERT_TRUE(port.ok()) << port.status();
  std::unique_ptr<v1::Station::Stub> stub = Stub(*port);
  const std::string id = StartLongCycle(*stub);
  ASSERT_FALSE(id.empty());

  daemon->Signal(SIGHUP);
  const int status = daemon->Wait();
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << DescribeWaitStatus(status);
  EXPECT_NE(ReadFile(LogPath("daemon")).find("stopping on SIGHUP"), std::string::npos)
      << ReadFile(LogPath("daemon"));
  const StoredCycle cycle = StoredAfterExit(id);
  EXPECT_EQ(cycle.state, CycleState::kCancelled);
  EXPECT_EQ(cycle.reason, "cancelled");
  EXPECT_GT(cycle.ended_ns, cycle.started_ns);
}

// A port out of range used to listen on another one; a log level outside the list was taken.
TEST_F(LinecaldProcessTest, FlagsOutOfRangeAreRefused) {
  std::unique_ptr<LinecaldProcess> verbose = Spawn("verbose", {"--log-level", "verbose"});
  ASSERT_NE(verbose, nullptr);
  int status = ExitBeforeListening(*verbose);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2) << DescribeWaitStatus(status);
  EXPECT_EQ(ReadFile(LogPath("verbose")),
            "linecald: --log-level: must be debug, info, warning or error, got 'verbose'\n");

  std::unique_ptr<LinecaldProcess> port = Spawn("port", {"--listen", "127.0.0.1:99999"});
  ASSERT_NE(port, nullptr);
  status = ExitBeforeListening(*port);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1) << DescribeWaitStatus(status);
  EXPECT_NE(
      ReadFile(LogPath("port"))
          .find("linecald: listen: '127.0.0.1:99999': must be HOST:PORT with a port in 0..65535\n"),
      std::string::npos)
      << ReadFile(LogPath("port"));
}

// The soft descriptor limit is raised to the hard one at start, and the log says so.
TEST_F(LinecaldProcessTest, SoftDescriptorLimitIsRaisedToTheHardOne) {
  // 256: below any hard limit a test machine has, above what linecald needs to start.
  std::unique_ptr<LinecaldProcess> daemon =
      Spawn("daemon", {"--listen", "127.0.0.1:0"}, "ulimit -S -n 256 &&");
  ASSERT_NE(daemon, nullptr);
  ASSERT_TRUE(daemon->WaitReady(kTimeout).ok()) << ReadFile(LogPath("daemon"));
  // /proc/PID/limits: "Max open files  <soft>  <hard>  files".
  std::istringstream limits(ReadFile("/proc/" + std::to_string(daemon->pid()) + "/limits"));
  std::string line, soft, hard;
  while (std::getline(limits, line)) {
    if (line.rfind("Max open files", 0) == 0) std::istringstream(line.substr(14)) >> soft >> hard;
  }
  ASSERT_FALSE(hard.empty());
  if (hard == "256") GTEST_SKIP() << "the hard limit is 256 here: nothing to raise";
  EXPECT_EQ(soft, hard);
  EXPECT_NE(ReadFile(LogPath("daemon"))
                .find("descriptors: soft limit raised from 256 to the hard limit " + hard),
            std::string::npos)
      << ReadFile(LogPath("daemon"));
  daemon->Signal(SIGTERM);
  EXPECT_EQ(daemon->Wait(), 0);
}

// Issue 21, item 2: with its descriptors exhausted by idle TCP connections, gRPC 1.51's
// listener fails accept4 with EMFILE and never accepted again, even once they closed. The
// daemon (started with `args`) runs under a limit of 256 descriptors, soft and hard (so that
// raising the soft one changes nothing), and gets 300 connections that send nothing; once
// accept has failed they close, and a call on a new connection (with `credentials`) must be
// served within seconds by the same process.
void LinecaldProcessTest::ExpectServedAgainAfterDescriptorsRanOut(
    const std::vector<std::string>& args,
    const std::shared_ptr<grpc::ChannelCredentials>& credentials) {
#if defined(__SANITIZE_ADDRESS__)
  // UBSan's vptr check probes an object's memory through a pipe (sanitizer_common's
  // IsAccessibleMemoryRange); in a process out of descriptors the pipe fails and every
  // virtual call that misses its type cache is reported as "invalid vptr" and aborts (a
  // ten-line program with a valid object and an exhausted table shows the same). The Release
  // build runs this test; suppressions do not reach this path.
  GTEST_SKIP() << "needs a process out of descriptors, where UBSan's vptr check cannot run";
#endif
  absl::StatusOr<std::unique_ptr<LinecaldProcess>> daemon =
      LinecaldProcess::Spawn(kLinecald, args, LogPath("daemon"), /*descriptor_limit=*/256);
  ASSERT_TRUE(daemon.ok()) << daemon.status();
  const absl::StatusOr<int> port = (*daemon)->WaitReady(kTimeout);
  ASSERT_TRUE(port.ok()) << port.status();

  // 300: more than the limit, well under the listen backlog (somaxconn, 4096 by default).
  reliability::IdleConnections idle;
  ASSERT_TRUE(idle.Open(*port, 300).ok());
  // gRPC's own line for the accept that failed: the fault happened.
  const absl::Status failed =
      (*daemon)->WaitForLog("Failed accept4: Too many open files", kTimeout);
  ASSERT_TRUE(failed.ok()) << failed;
  idle.Close();

  const auto t0 = std::chrono::steady_clock::now();
  // A new connection: a channel of its own subchannel pool (channels to the same target share
  // their connections by default).
  grpc::ChannelArguments arguments;
  arguments.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  std::unique_ptr<v1::Station::Stub> stub = v1::Station::NewStub(
      grpc::CreateCustomChannel("127.0.0.1:" + std::to_string(*port), credentials, arguments));
  grpc::ClientContext context;
  // A few seconds: the watchdog's detection (2-3 s), a restart and the client's reconnection
  // backoff; generous for the sanitizers. Without the watchdog the call waits for a listener
  // that never accepts.
  context.set_deadline(std::chrono::system_clock::now() + seconds(15));
  context.set_wait_for_ready(true);  // retry the connection until the daemon accepts again
  v1::StationStatus status;
  const grpc::Status s = stub->GetStationStatus(&context, {}, &status);
  const double served_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(s.ok()) << s.error_code() << " " << s.error_message() << "\n"
                      << ReadFile(LogPath("daemon"));
  std::printf("served %.2f s after the idle connections closed\n", served_s);
  const std::string log = ReadFile(LogPath("daemon"));
  EXPECT_NE(log.find("listening again on 127.0.0.1:" + std::to_string(*port) + " (restart 1)"),
            std::string::npos)
      << log;
  // The same process (no restart by systemd): it still answers SIGTERM with a clean stop.
  (*daemon)->Signal(SIGTERM);
  const int exit_status = (*daemon)->Wait();
  EXPECT_TRUE(WIFEXITED(exit_status) && WEXITSTATUS(exit_status) == 0)
      << DescribeWaitStatus(exit_status);
}

TEST_F(LinecaldProcessTest, AcceptsAgainAfterDescriptorsRanOut) {
  ExpectServedAgainAfterDescriptorsRanOut({"--data-dir", DataDir(), "--listen", "127.0.0.1:0"},
                                          grpc::InsecureChannelCredentials());
}

// The same on a mutual TLS port: the watchdog looks below TLS, at the kernel's accept queue.
TEST_F(LinecaldProcessTest, AcceptsAgainAfterDescriptorsRanOutOnAMutualTlsPort) {
  testing_daemon::TestPki pki;
  ASSERT_TRUE(testing_daemon::MakeTestPki(dir_, &pki));
  ASSERT_TRUE(reliability::WriteLongCameraCapture(DataDir() + "/long", 1).ok());
  const std::string config =
      WriteReplayConfig(dir_, DataDir(),
                        absl::StrCat("\"tls\": {\"cert\": \"", pki.server_cert, "\", \"key\": \"",
                                     pki.server_key, "\", \"client_ca\": \"", pki.ca_cert, "\"}"));
  grpc::SslCredentialsOptions options;
  options.pem_root_certs = ReadFile(pki.ca_cert);
  options.pem_cert_chain = ReadFile(pki.client_cert);
  options.pem_private_key = ReadFile(pki.client_key);
  ExpectServedAgainAfterDescriptorsRanOut({"--config", config}, grpc::SslCredentials(options));
}

// A configuration file for linecald: the reference station and car, this test's data
// directory, the replay source on data/long (reliability::WriteLongCameraCapture), and the
// extra keys `extra` (a JSON object's members).
std::string WriteReplayConfig(const fs::path& dir, const std::string& data_dir,
                              const std::string& extra) {
  const std::string deploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
  const fs::path path = dir / "linecald.json";
  std::ofstream(path) << "{\"station\": \"" << deploy << "/stations/reference.json\", "
                      << "\"car_models\": [\"" << deploy << "/cars/reference.json\"], "
                      << "\"data_root\": \"" << data_dir << "\", "
                      << "\"listen\": \"127.0.0.1:0\", "
                      << "\"source\": {\"type\": \"replay\", \"capture\": \"long\"}"
                      << (extra.empty() ? "" : ", " + extra) << "}";
  return path.string();
}

// Issue 21, item 6: after SIGTERM during a calibration the log said "stopped" and the
// process lived on until the calibration's end (124 s in the probe), since the core's
// destructor waited for it. Now the cancel stops the calibration at its next frame, and the
// process exits within linecald's drain time (kDrainTime, 20 s).
TEST_F(LinecaldProcessTest, SigtermDuringALongCalibrationExitsWithinTheDrainTime) {
  // 600 frames: a minute of detections or more, far past the drain time.
  absl::StatusOr<std::unique_ptr<LinecaldProcess>> daemon =
      LinecaldProcess::Spawn(kLinecald, {"--config", WriteLongReplay()}, LogPath("daemon"));
  ASSERT_TRUE(daemon.ok()) << daemon.status();
  const absl::StatusOr<int> port = (*daemon)->WaitReady(kTimeout);
  ASSERT_TRUE(port.ok()) << port.status();
  std::unique_ptr<v1::Station::Stub> stub = Stub(*port);
  const std::string id = StartLongCycle(*stub);
  ASSERT_FALSE(id.empty());
  // 2 s: the capture read and the calibration under way.
  std::this_thread::sleep_for(seconds(2));
  ASSERT_EQ(GetCycle(*stub, id).state(), v1::CYCLE_STATE_RUNNING);

  const auto signalled = std::chrono::steady_clock::now();
  (*daemon)->Signal(SIGTERM);
  const int status = (*daemon)->Wait();
  const double took_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - signalled).count();
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << DescribeWaitStatus(status);
  // linecald's drain time; the stop itself takes about a frame's detection.
  EXPECT_LT(took_s, 20.0) << ReadFile(LogPath("daemon"));
  EXPECT_NE(ReadFile(LogPath("daemon")).find("stopped"), std::string::npos);
  const StoredCycle cycle = StoredAfterExit(id);
  EXPECT_EQ(cycle.state, CycleState::kCancelled);
  EXPECT_EQ(cycle.reason, "cancelled");
}

// The configuration's input_budget reaches the core (main.cc passes it on): a replay capture
// over max_manifest_frames stops the start naming the key; it used to be read with the
// default budget and accepted.
TEST_F(LinecaldProcessTest, ConfiguredInputBudgetAppliesToTheReplayCapture) {
  ASSERT_TRUE(reliability::WriteLongCameraCapture(DataDir() + "/long", 3).ok());
  const std::string config =
      WriteReplayConfig(dir_, DataDir(), "\"input_budget\": {\"max_manifest_frames\": 2}");
  absl::StatusOr<std::unique_ptr<LinecaldProcess>> daemon =
      LinecaldProcess::Spawn(kLinecald, {"--config", config}, LogPath("daemon"));
  ASSERT_TRUE(daemon.ok()) << daemon.status();
  const int status = ExitBeforeListening(**daemon);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2) << DescribeWaitStatus(status);
  EXPECT_NE(ReadFile(LogPath("daemon"))
                .find("3 frames exceed the budget of 2 (input_budget.max_manifest_frames)"),
            std::string::npos)
      << ReadFile(LogPath("daemon"));
}

}  // namespace
}  // namespace linecal

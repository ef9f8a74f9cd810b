// linecald: the station daemon (docs/interfaces.md). `linecald --config FILE` with --listen,
// --db and --log-level overriding the file; without --config it starts on the bundled demo
// station (simulated sensors) with its data under --data-dir (default ./linecald-data).
// SIGTERM, SIGINT or SIGHUP: stop taking calls, let a running cycle end as cancelled (its
// calibration stops at its next frame), exit 0 within kDrainTime (SIGHUP too: a closed
// terminal or a `kill -HUP` meant as "reload" must not leave the cycle running, and there is
// nothing to reload that a restart would not do).
// Descriptors: the soft RLIMIT_NOFILE is raised to the hard limit at start; gRPC 1.51's
// listener stops for good after an accept error (EMFILE), so a ListenerWatchdog restarts the
// gRPC server on the same address when it finds the listener dead (docs/daemon.md,
// "Descriptors").
// With a `web` section, the station console's HTTP server (daemon/web) runs beside the gRPC
// server, behind the same auth_token; it stops after a running cycle was cancelled.
// Under systemd (Type=notify): READY=1 once calls are served, WATCHDOG=1 while the core
// answers, STOPPING=1 on the signal (daemon/systemd/sd_notify.h).
#include <grpc/support/log.h>
#include <malloc.h>
#include <pthread.h>
#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "daemon/core/daemon_config.h"
#include "daemon/log/daemon_log.h"
#include "daemon/service/listener_watchdog.h"
#include "daemon/service/station_service.h"
#include "daemon/systemd/sd_notify.h"
#include "daemon/web/web_server.h"

namespace {

constexpr char kUsage[] =
    "usage: linecald [--config FILE] [--listen HOST:PORT] [--db PATH] [--log-level LEVEL] "
    "[--data-dir DIR]\n"
    "                [--web-listen HOST:PORT]\n"
    "  Serves the linecal.v1.Station gRPC API (proto/linecal/v1/station.proto), the gRPC health\n"
    "  service and server reflection. Without --config: the demo station of deploy/ with\n"
    "  simulated sensors, data and database in --data-dir (default ./linecald-data).\n"
    "  --web-listen: the station console there (docs/console.md), as the file's web.listen.\n";

using linecal::LogLevel;

// One record of linecald's own (not about a cycle) to its log (daemon/log/daemon_log.h).
void Log(LogLevel level, const std::string& message) { linecal::WriteLog({level, message}); }

// A record of a part that names its levels in words (the listener watchdog).
void LogWords(const std::string& level, const std::string& message) {
  Log(linecal::ParseLogLevel(level).value_or(LogLevel::kError), message);
}

// How long a stop may take from the signal: the running cycle's end stored, calibration
// threads joined. Under the unit's TimeoutStopSec=30, so that systemd never has to kill us;
// a cancelled calibration stops within about a second (StationCore's kCalibrationStopGrace).
constexpr std::chrono::seconds kDrainTime{20};

// Raises the soft RLIMIT_NOFILE to the hard limit and says what it did. Each gRPC connection
// holds a descriptor; the default soft limit of 1024 let 1,100 idle clients exhaust it.
std::string RaiseDescriptorLimit() {
  rlimit limit{};
  if (getrlimit(RLIMIT_NOFILE, &limit) != 0) {
    return absl::StrCat("descriptors: getrlimit: ", std::strerror(errno));
  }
  const rlim_t before = limit.rlim_cur;
  if (before == limit.rlim_max) {
    return absl::StrCat("descriptors: limit ", before, " (soft = hard)");
  }
  limit.rlim_cur = limit.rlim_max;
  if (setrlimit(RLIMIT_NOFILE, &limit) != 0) {
    return absl::StrCat("descriptors: cannot raise the soft limit ", before, ": ",
                        std::strerror(errno));
  }
  return absl::StrCat("descriptors: soft limit raised from ", before, " to the hard limit ",
                      limit.rlim_max);
}

// gRPC's own log lines, in ours: its errors (an accept that failed, "Failed accept4: Too
// many open files") must reach the station's log whatever GRPC_VERBOSITY says. Nothing
// depends on them: the ListenerWatchdog finds a dead listener by itself.
void LogGrpc(gpr_log_func_args* args) {
  const LogLevel level = args->severity == GPR_LOG_SEVERITY_ERROR  ? LogLevel::kError
                         : args->severity == GPR_LOG_SEVERITY_INFO ? LogLevel::kInfo
                                                                   : LogLevel::kDebug;
  Log(level, absl::StrCat("grpc: ", args->message));
}

// HOST:PORT of `listen` with the port the server got (the same when it was not 0): where a
// restarted server listens again, so that clients find it where they found the first.
std::string BoundAddress(const std::string& listen, int port) {
  return absl::StrCat(listen.substr(0, listen.rfind(':')), ":", port);
}

const char* SignalName(int signal) {
  switch (signal) {
    case SIGTERM:
      return "SIGTERM";
    case SIGINT:
      return "SIGINT";
    case SIGHUP:
      return "SIGHUP";
  }
  return "a signal";
}

// Sends WATCHDOG=1 at half systemd's interval for as long as the core answers a status
// query: a core wedged on its lock stops the pings and systemd restarts the daemon.
class Watchdog {
 public:
  Watchdog(const linecal::SystemdNotifier& notifier, linecal::StationCore* core) {
    const std::optional<std::chrono::microseconds> interval = notifier.watchdog_interval();
    if (!interval) return;
    thread_ = std::thread([this, &notifier, core, period = *interval / 2] {
      std::unique_lock<std::mutex> lock(mutex_);
      while (!stop_) {
        lock.unlock();
        (void)core->Status();
        if (absl::Status s = notifier.Notify("WATCHDOG=1"); !s.ok())
          Log(LogLevel::kWarning, std::string(s.message()));
        lock.lock();
        stopped_.wait_for(lock, period, [this] { return stop_; });
      }
    });
  }
  ~Watchdog() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    stopped_.notify_all();
    if (thread_.joinable()) thread_.join();
  }

 private:
  std::mutex mutex_;
  std::condition_variable stopped_;
  bool stop_ = false;
  std::thread thread_;
};

// The command line's values (empty: not given).
struct CommandLine {
  std::string config_path, listen, db, log_level, web_listen, data_dir = "linecald-data";
};

// Parses argv; nullopt after --help (usage printed) or a wrong option (said on stderr) with
// the exit code in `exit_code`.
std::optional<CommandLine> ParseCommandLine(int argc, char** argv, int* exit_code) {
  CommandLine cl;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&](std::string* out) {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "linecald: %s needs a value\n%s", arg.c_str(), kUsage);
        *exit_code = 2;
        return false;
      }
      *out = argv[++i];
      return true;
    };
    bool ok = true;
    if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      *exit_code = 0;
      return std::nullopt;
    } else if (arg == "--config") {
      ok = value(&cl.config_path);
    } else if (arg == "--listen") {
      ok = value(&cl.listen);
    } else if (arg == "--db") {
      ok = value(&cl.db);
    } else if (arg == "--log-level") {
      ok = value(&cl.log_level);
    } else if (arg == "--data-dir") {
      ok = value(&cl.data_dir);
    } else if (arg == "--web-listen") {
      ok = value(&cl.web_listen);
    } else {
      std::fprintf(stderr, "linecald: unknown option '%s'\n%s", arg.c_str(), kUsage);
      *exit_code = 2;
      return std::nullopt;
    }
    if (!ok) return std::nullopt;
  }
  return cl;
}

// The configuration: the file's (or the demo station's), with the command line's overrides.
// Errors as linecald prints them after "linecald: ".
absl::StatusOr<linecal::DaemonConfig> LoadConfig(const CommandLine& cl) {
  absl::StatusOr<linecal::DaemonConfig> config =
      cl.config_path.empty() ? absl::StatusOr<linecal::DaemonConfig>(
                                   linecal::DefaultDaemonConfig(LINECAL_DEPLOY_DIR, cl.data_dir))
                             : linecal::ReadDaemonConfig(cl.config_path);
  if (!config.ok()) return config.status();
  if (!cl.listen.empty()) config->listen = cl.listen;
  if (!cl.db.empty()) config->core.db_path = cl.db;
  if (!cl.log_level.empty()) config->log_level = cl.log_level;
  if (!cl.web_listen.empty()) {
    if (!config->web) config->web.emplace();
    config->web->listen = cl.web_listen;
  }
  config->core.input_budget = config->input_budget;
  if (!linecal::ParseLogLevel(config->log_level)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--log-level: must be debug, info, warning or error, got '", config->log_level, "'"));
  }
  return config;
}

// The station console beside the gRPC server when the configuration has a `web` section
// (else null); the error as linecald prints it.
absl::StatusOr<std::unique_ptr<linecal::WebServer>> StartConsole(
    const linecal::DaemonConfig& config, linecal::StationCore* core) {
  if (!config.web) return nullptr;
  const std::string pages = linecal::FindStaticDir(config.web->static_dir, LINECAL_WEB_STATIC_DIR);
  linecal::WebServerOptions options{config.web->listen, config.web->tls, pages, config.auth_token,
                                    LINECAL_VERSION};
  options.operator_token = config.web->operator_token;
  absl::StatusOr<std::unique_ptr<linecal::WebServer>> web =
      linecal::WebServer::Start(core, std::move(options));
  if (!web.ok()) return web.status();
  const char* login = config.auth_token.empty() ? " (no login)" : " (login with the token)";
  Log(LogLevel::kInfo, absl::StrCat("console on ", config.web->tls ? "https://" : "http://",
                                    BoundAddress(config.web->listen, (*web)->port()), "/", login,
                                    ", pages from ", pages));
  return web;
}

// Serves until one of `signals` arrives (returned): the systemd watchdog pings and the
// listener watchdog that restarts a dead gRPC listener run meanwhile.
int ServeUntilSignal(const linecal::DaemonConfig& config, linecal::StationCore* core,
                     linecal::RunningServer* server, const linecal::SystemdNotifier& notifier,
                     const sigset_t& signals) {
  int signal = 0;
  const Watchdog watchdog(notifier, core);
  // Destroyed first: joins its thread, after which `server` is the caller's again.
  const std::string address = BoundAddress(config.listen, server->port);
  const linecal::ListenerWatchdog listener(
      server, address,
      [&] {
        return linecal::StartServer(core, address, config.auth_token, LINECAL_VERSION, config.tls);
      },
      LogWords);
  sigwait(&signals, &signal);
  return signal;
}

// The stop after `signal`: the running cycle cancelled, the servers shut within kDrainTime,
// the cycle's end and the plant's queue given the time left. The exit code: 0, or 1 when the
// cycle did not end in time (it is aborted at the next start).
int Drain(int signal, std::unique_ptr<linecal::StationCore> core, linecal::RunningServer* server,
          std::unique_ptr<linecal::WebServer> web, const linecal::SystemdNotifier& notifier) {
  Log(LogLevel::kInfo, std::string("stopping on ") + SignalName(signal));
  notifier.Notify("STOPPING=1").IgnoreError();
  if (const std::optional<int64_t> running = core->Status().running_cycle) {
    // Ends as cancelled at its next step; a cycle that ended meanwhile needs nothing.
    core->CancelCycle(*running).IgnoreError();
  }
  const auto drain_deadline = std::chrono::system_clock::now() + kDrainTime;
  if (server->server) server->server->Shutdown(drain_deadline);
  *server = {};
  web.reset();  // its event streams end with the cancelled cycle
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
      drain_deadline - std::chrono::system_clock::now());
  if (!core->WaitIdleFor(std::max(left, std::chrono::milliseconds(0)))) {
    // A cycle that does not end within the drain time is left running; the next start
    // stores it as aborted. Better than being killed by systemd with nothing said.
    Log(LogLevel::kError, "the running cycle did not end within the drain time of " +
                              std::to_string(kDrainTime.count()) +
                              " s; exiting, it is aborted at the next start");
    std::_Exit(1);
  }
  // Cycles not yet at the plant database are shipped while drain time is left and the plant
  // answers; the outbox keeps the rest for the next start.
  const auto forwarding_deadline =
      std::chrono::steady_clock::now() + (drain_deadline - std::chrono::system_clock::now());
  if (const int64_t queued = core->StopForwarding(forwarding_deadline); queued > 0) {
    Log(LogLevel::kWarning, absl::StrCat(queued,
                                         " cycles stay queued for the plant database; they are "
                                         "sent after the next start"));
  }
  core.reset();  // joins the calibrations stopped by the cancel
  Log(LogLevel::kInfo, "stopped");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // Two malloc arenas instead of glibc's 8 per core: each cycle computes its sensors on new
  // threads, and with an arena each the allocator kept every arena's peak of frames and
  // clouds after the cycle, so the resident set climbed to 170 MB over the soak's cycles
  // with under 9 MB in use; with two it stays near 60-110 MB, no slower (docs/reliability.md).
  mallopt(M_ARENA_MAX, 2);
  int exit_code = 0;
  const std::optional<CommandLine> cl = ParseCommandLine(argc, argv, &exit_code);
  if (!cl) return exit_code;
  absl::StatusOr<linecal::DaemonConfig> config = LoadConfig(*cl);
  if (!config.ok()) {
    std::fprintf(stderr, "linecald: %s\n", std::string(config.status().message()).c_str());
    return 2;
  }
  // Every record from here on, the core's and gRPC's too, at the configured level and above.
  linecal::InstallDaemonLog(*linecal::ParseLogLevel(config->log_level));
  Log(LogLevel::kInfo, RaiseDescriptorLimit());
  gpr_set_log_function(LogGrpc);

  // Signals are taken by a waiting thread, not by handlers: the shutdown runs in normal code.
  sigset_t signals;
  sigemptyset(&signals);
  for (int s : {SIGTERM, SIGINT, SIGHUP}) sigaddset(&signals, s);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  absl::StatusOr<std::unique_ptr<linecal::StationCore>> core =
      linecal::StationCore::Create(config->core);
  if (!core.ok()) {
    std::fprintf(stderr, "linecald: %s\n", std::string(core.status().message()).c_str());
    return 2;
  }
  if ((*core)->store().aborted_at_open() > 0) {
    Log(LogLevel::kWarning, std::to_string((*core)->store().aborted_at_open()) +
                                " cycles interrupted by the last stop are stored as aborted");
  }
  if (config->core.plant) {
    Log(LogLevel::kInfo,
        absl::StrCat("forwarding cycles to the plant database as station ",
                     config->core.plant->station_id, ", batches of ", config->core.plant->batch));
  }
  absl::StatusOr<linecal::RunningServer> server = linecal::StartServer(
      core->get(), config->listen, config->auth_token, LINECAL_VERSION, config->tls);
  if (!server.ok()) {
    std::fprintf(stderr, "linecald: %s\n", std::string(server.status().message()).c_str());
    return 1;
  }
  absl::StatusOr<std::unique_ptr<linecal::WebServer>> web = StartConsole(*config, core->get());
  if (!web.ok()) {
    std::fprintf(stderr, "linecald: %s\n", std::string(web.status().message()).c_str());
    return 1;
  }
  // gRPC's errors belong in the log: GRPC_VERBOSITY=NONE (read by gRPC's first init, which
  // StartServer did) would hide them, so errors are let through.
  if (!gpr_should_log(GPR_LOG_SEVERITY_ERROR)) gpr_set_log_verbosity(GPR_LOG_SEVERITY_ERROR);
  const std::string listening =
      "listening on " + config->listen + " (port " + std::to_string(server->port) + ")";
  const char* tls = !config->tls                       ? ", insecure"
                    : config->tls->require_client_cert ? ", mutual TLS"
                                                       : ", TLS";
  Log(LogLevel::kInfo, listening + ", database " + config->core.db_path + tls +
                           (config->auth_token.empty() ? ", no token" : ", token authentication"));
  const linecal::SystemdNotifier notifier = linecal::SystemdNotifier::FromEnvironment();
  if (absl::Status s = notifier.Notify("READY=1\nSTATUS=" + listening); !s.ok())
    Log(LogLevel::kWarning, std::string(s.message()));
  const int signal = ServeUntilSignal(*config, core->get(), &*server, notifier, signals);
  return Drain(signal, *std::move(core), &*server, *std::move(web), notifier);
}

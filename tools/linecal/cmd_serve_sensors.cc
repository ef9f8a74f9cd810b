// linecal serve-sensors: serves a capture as live sensors (daemon/simstation) until SIGINT or
// SIGTERM, and writes a linecald configuration that points every sensor at what serves it.
#include <signal.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "daemon/simstation/sensor_server.h"
#include "station/io/json_reader.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"

namespace linecal::tools {
namespace {

namespace fs = std::filesystem;
constexpr char kCommand[] = "serve-sensors";

std::string Absolute(const std::string& path) {
  return fs::absolute(path).lexically_normal().string();
}

}  // namespace

int RunServeSensors(const Args& args) {
  cli::CommandLine cl(
      "linecal serve-sensors --capture DIR --write-config FILE --data-root DIR [options]",
      "Serves a capture as live sensors over the real protocols: a fake GigE Vision camera per "
      "camera "
      "(Aravis, one IPv4 address each), the LiDARs' packets over UDP (looped, recorded timing), "
      "the "
      "radars' candump logs. Writes a linecald configuration using them, then serves until SIGINT "
      "or "
      "SIGTERM (docs/daemon.md, \"Live sources\").",
      {{"capture", "DIR", "the capture to serve (e.g. one written by `linecal sim`)", true},
       {"write-config", "FILE",
        "linecald configuration to write (station and car of the capture, live sources)", true},
       {"data-root", "DIR", "the configuration's data_root (database and captures)", true},
       {"camera-addresses", "A,B",
        "one IPv4 address per camera sensor, in the capture's order (default 127.0.0.1)"},
       {"lost-ratio", "R",
        "share of GigE stream packets the fake cameras drop, [0, 1) (default 0)"},
       {"lidar-port", "P", "UDP port of the first LiDAR; the next ones follow (default 2368)"},
       {"lidar-speed", "S",
        "LiDAR replay speed, 1 = recorded timing, 0 = as fast as possible (default 1)"}});
  if (auto code = cli::ParseOrExit(cl, kCommand, args)) return *code;

  SensorServerOptions o;
  o.capture_dir = cl.Get("capture");
  if (std::string a = cl.Get("camera-addresses"); !a.empty()) {
    o.camera_addresses = absl::StrSplit(a, ',', absl::SkipEmpty());
  }
  absl::StatusOr<double> lost = cl.GetDouble("lost-ratio", o.camera_lost_ratio);
  absl::StatusOr<int> port = cl.GetInt("lidar-port", o.lidar_first_port);
  absl::StatusOr<double> speed = cl.GetDouble("lidar-speed", o.lidar_speed);
  for (const absl::Status& s : {lost.status(), port.status(), speed.status()}) {
    if (!s.ok()) return cli::BadInput(kCommand, std::string(s.message()));
  }
  if (*port < 1 || *port > 65535)
    return cli::BadInput(kCommand, absl::StrCat("--lidar-port ", *port, ": not a port"));
  o.camera_lost_ratio = *lost;
  o.lidar_first_port = static_cast<std::uint16_t>(*port);
  o.lidar_speed = *speed;

  // SIGINT and SIGTERM are taken by sigwait below; blocked before any thread starts, so that
  // no camera or sender thread receives them.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  absl::StatusOr<std::unique_ptr<SensorServer>> server = SensorServer::Start(o);
  if (!server.ok()) return cli::BadInput(kCommand, std::string(server.status().message()));
  const Capture& capture = (*server)->capture();
  const nlohmann::json config = {
      {"station_id", "simulated"},
      {"station", Absolute(fs::path(capture.dir) / kCaptureStationFile)},
      {"car_models", {Absolute(fs::path(capture.dir) / kCaptureCarFile)}},
      {"data_root", Absolute(cl.Get("data-root"))},
      {"source", (*server)->LiveSourceConfig()}};
  // Written (atomically) only once everything serves: a script waiting for the file can start
  // linecald at once.
  if (absl::Status s = WriteJsonFile(cl.Get("write-config"), config); !s.ok()) {
    return cli::BadInput(kCommand, std::string(s.message()));
  }
  std::fprintf(stderr, "linecal %s: serving %s; configuration %s\n", kCommand, capture.dir.c_str(),
               cl.Get("write-config").c_str());
  int signal = 0;
  sigwait(&signals, &signal);
  std::fprintf(stderr, "linecal %s: stopping after %lld LiDAR datagrams\n", kCommand,
               static_cast<long long>((*server)->lidar_datagrams_sent()));
  return cli::kExitOk;
}

}  // namespace linecal::tools

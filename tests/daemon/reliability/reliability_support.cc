#include "tests/daemon/reliability/reliability_support.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <thread>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "station/sim/simulator.h"

namespace linecal::reliability {
namespace {

namespace fs = std::filesystem;

const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";

std::string ReadAll(const std::string& path, std::uintmax_t from = 0) {
  std::ifstream in(path, std::ios::binary);
  in.seekg(static_cast<std::streamoff>(from));
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

}  // namespace

absl::StatusOr<ProcessStatus> ReadProcessStatus(const std::string& pid) {
  const std::string path = "/proc/" + pid + "/status";
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": no such process"));
  ProcessStatus s;
  int found = 0;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    std::string key;
    std::int64_t value = 0;
    fields >> key >> value;
    if (key == "VmRSS:") s.rss_kb = value, found |= 1;
    if (key == "VmHWM:") s.hwm_kb = value, found |= 2;
    if (key == "Threads:") s.threads = static_cast<int>(value), found |= 4;
  }
  if (found != 7)
    return absl::InternalError(absl::StrCat(path, ": VmRSS, VmHWM or Threads missing"));
  return s;
}

int SettledEntryCount(const std::string& proc_dir) {
  const auto count = [&] {
    std::error_code ec;
    int n = 0;
    for (fs::directory_iterator it(proc_dir, ec), end; !ec && it != end; it.increment(ec)) ++n;
    return n;
  };
  int last = count(), same = 1;
  // 50 samples of 20 ms: 1 s, far longer than a finished thread takes to leave.
  for (int i = 0; i < 50 && same < 3; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const int now = count();
    same = now == last ? same + 1 : 1;
    last = now;
  }
  return last;
}

std::string ReferenceStationPath() { return kDeploy + "/stations/reference.json"; }

absl::StatusOr<ProgramFlags> ParseProgramFlags(int argc, char** argv, ProgramFlags defaults,
                                               const std::vector<std::string>& own_flags) {
  ProgramFlags f = std::move(defaults);
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (i + 1 >= argc) return absl::InvalidArgumentError(absl::StrCat(flag, ": needs a value"));
    const std::string value = argv[++i];
    bool ok = true;
    if (flag == "--cycles") {
      ok = absl::SimpleAtoi(value, &f.cycles) && f.cycles >= 1;
    } else if (flag == "--seed") {
      ok = absl::SimpleAtoi(value, &f.seed);
    } else if (flag == "--sensors") {
      f.sensors = absl::StrSplit(value, ',', absl::SkipEmpty());
    } else if (flag == "--dir") {
      f.dir = value;
    } else if (std::find(own_flags.begin(), own_flags.end(), flag) != own_flags.end()) {
      f.own[flag] = value;
    } else {
      return absl::InvalidArgumentError(absl::StrCat("unknown option '", flag, "'"));
    }
    if (!ok)
      return absl::InvalidArgumentError(absl::StrCat(flag, " = '", value, "': not a valid value"));
  }
  return f;
}

absl::StatusOr<Workspace> PrepareWorkspace(const ProgramFlags& flags, const std::string& program,
                                           const std::string& car_id, const std::string& capture) {
  Workspace w;
  w.owned = flags.dir.empty();
  w.dir = w.owned ? fs::temp_directory_path() / absl::StrCat("linecal_", program, "_", ::getpid())
                  : fs::path(flags.dir);
  std::error_code ec;
  fs::remove_all(w.dir, ec);
  fs::create_directories(w.dir / "data", ec);
  if (ec) return absl::InternalError(absl::StrCat(w.dir.string(), ": ", ec.message()));
  w.car_path = (w.dir / "car.json").string();

  const std::string reference = kDeploy + "/cars/reference.json";
  std::ifstream in(reference);
  nlohmann::json car = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (car.is_discarded()) return absl::InternalError(absl::StrCat(reference, ": not JSON"));
  // The car file moves: files it names relative to itself (LiDAR angle tables) stay where
  // they are.
  for (nlohmann::json& s : car["sensors"]) {
    if (s.contains("angles_file") && fs::path(s["angles_file"].get<std::string>()).is_relative()) {
      s["angles_file"] =
          (fs::path(reference).parent_path() / s["angles_file"].get<std::string>()).string();
    }
  }
  nlohmann::json kept = nlohmann::json::array();
  for (const std::string& name : flags.sensors) {
    bool found = false;
    for (const nlohmann::json& s : car["sensors"]) {
      if (s["name"] == name) kept.push_back(s), found = true;
    }
    if (!found)
      return absl::InvalidArgumentError(
          absl::StrCat("sensor '", name, "': not a sensor of ", reference));
  }
  if (!flags.sensors.empty()) car["sensors"] = kept;
  car["id"] = car_id;
  std::ofstream out(w.car_path);
  out << car.dump(2);
  out.close();
  if (!out) return absl::InternalError(absl::StrCat(w.car_path, ": cannot write"));

  absl::StatusOr<StationLayout> station = ReadStationLayout(ReferenceStationPath());
  if (!station.ok()) return station.status();
  absl::StatusOr<CarModel> model = ReadCarModel(w.car_path);
  if (!model.ok()) return model.status();
  SimulatorOptions o;
  o.camera_frames = 1;  // the daemon's default frames per sensor
  o.lidar.rotations = 1;
  if (absl::Status s =
          SimulateCapture(*station, *model, o, flags.seed, (w.dir / capture).string()).status();
      !s.ok()) {
    return s;
  }
  return w;
}

std::uint64_t FillFileSystem(const std::string& path) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) return 0;
  std::uint64_t written = 0;
  // 64 KiB blocks while they fit, then single bytes for the last partial page.
  const std::string block(1 << 16, 'x');
  for (size_t size : {block.size(), size_t{1}}) {
    while (true) {
      const ssize_t n = ::write(fd, block.data(), size);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;
      written += static_cast<std::uint64_t>(n);
    }
  }
  ::close(fd);
  return written;
}

absl::Status WriteLongCameraCapture(const std::string& dir, int frames) {
  absl::StatusOr<StationLayout> station = ReadStationLayout(ReferenceStationPath());
  if (!station.ok()) return station.status();
  absl::StatusOr<CarModel> car = ReadCarModel(kDeploy + "/cars/reference.json");
  if (!car.ok()) return car.status();
  SimulatorOptions o;
  o.sensors = {"front_camera"};
  if (absl::Status s = SimulateCapture(*station, *car, o, 9, dir).status(); !s.ok()) return s;
  const fs::path manifest_path = fs::path(dir) / "manifest.json";
  std::ifstream in(manifest_path);
  nlohmann::json manifest = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (manifest.is_discarded()) return absl::InternalError(manifest_path.string() + ": not JSON");
  nlohmann::json& list = manifest["sensors"][0]["frames"];
  const nlohmann::json first = list[0];
  const std::string first_path = first["path"].get<std::string>();
  for (int k = 1; k < frames; ++k) {
    nlohmann::json frame = first;
    frame["path"] = absl::StrCat("front_camera/frame-link-", k, ".png");
    std::error_code ec;
    const fs::path link = fs::path(dir) / frame["path"].get<std::string>();
    fs::create_hard_link(fs::path(dir) / first_path, link, ec);
    if (ec) return absl::InternalError(absl::StrCat(dir, ": hard link: ", ec.message()));
    list.push_back(frame);
  }
  std::ofstream out(manifest_path);
  out << manifest.dump(2);
  out.close();
  if (!out) return absl::InternalError(manifest_path.string() + ": cannot write");
  return absl::OkStatus();
}

absl::StatusOr<std::unique_ptr<LinecaldProcess>> LinecaldProcess::Spawn(
    const std::string& binary, const std::vector<std::string>& args, const std::string& log_path,
    std::uint64_t descriptor_limit) {
  std::error_code ec;
  const std::uintmax_t offset = fs::exists(log_path, ec) ? fs::file_size(log_path, ec) : 0;
  std::vector<std::string> argv_strings = {binary};
  argv_strings.insert(argv_strings.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : argv_strings) argv.push_back(a.data());
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) return absl::InternalError(absl::StrCat("fork: ", std::strerror(errno)));
  if (pid == 0) {
    // Only async-signal-safe calls between fork and exec (the parent has threads).
    const int fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (fd < 0 || ::dup2(fd, STDERR_FILENO) < 0) ::_exit(126);
    const rlimit limit{descriptor_limit, descriptor_limit};
    if (descriptor_limit > 0 && ::setrlimit(RLIMIT_NOFILE, &limit) != 0) ::_exit(125);
    ::execv(binary.c_str(), argv.data());
    ::_exit(127);
  }
  return std::unique_ptr<LinecaldProcess>(new LinecaldProcess(pid, log_path, offset));
}

LinecaldProcess::~LinecaldProcess() {
  if (!reaped_) {
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
  }
}

std::string LinecaldProcess::NewLog() const { return ReadAll(log_path_, log_offset_); }

absl::Status LinecaldProcess::WaitForLog(const std::string& text,
                                         std::chrono::milliseconds timeout) const {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (true) {
    const std::string log = NewLog();
    if (log.find(text) != std::string::npos) return absl::OkStatus();
    if (std::chrono::steady_clock::now() > deadline) {
      return absl::DeadlineExceededError(absl::StrCat("linecald did not log '", text, "' within ",
                                                      timeout.count(), " ms; its log:\n", log));
    }
    // 20 ms between reads of a small log file.
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

LinearTrend FitLinearTrend(const std::vector<double>& x, const std::vector<double>& y) {
  LinearTrend t;
  const size_t n = std::min(x.size(), y.size());
  if (n < 3) return t;
  double mx = 0, my = 0;
  for (size_t i = 0; i < n; ++i) {
    mx += x[i];
    my += y[i];
  }
  mx /= n;
  my /= n;
  double sxx = 0, sxy = 0;
  for (size_t i = 0; i < n; ++i) {
    sxx += (x[i] - mx) * (x[i] - mx);
    sxy += (x[i] - mx) * (y[i] - my);
  }
  if (sxx == 0) return t;
  t.samples = static_cast<int>(n);
  t.slope = sxy / sxx;
  t.intercept = my - t.slope * mx;
  std::vector<double> residuals(n);
  double squares = 0, lagged = 0;
  for (size_t i = 0; i < n; ++i) {
    residuals[i] = y[i] - (t.intercept + t.slope * x[i]);
    squares += residuals[i] * residuals[i];
    if (i > 0) lagged += residuals[i] * residuals[i - 1];
  }
  // n - 2: two parameters fitted.
  t.scatter = std::sqrt(squares / static_cast<double>(n - 2));
  // 0.95 at most: beyond it the widening (6.2x) would hide any trend in a short series.
  t.autocorrelation = squares > 0 ? std::clamp(lagged / squares, 0.0, 0.95) : 0;
  t.slope_error =
      t.scatter / std::sqrt(sxx) * std::sqrt((1 + t.autocorrelation) / (1 - t.autocorrelation));
  return t;
}

MemoryGrowth JudgeMemoryGrowth(const std::vector<double>& cycles, const std::vector<double>& mb,
                               double max_growth_per_1000, double min_significance) {
  MemoryGrowth g;
  g.trend = FitLinearTrend(cycles, mb);
  if (g.trend.samples < 3) return g;
  g.run_growth = g.trend.slope * (cycles[g.trend.samples - 1] - cycles[0]);
  g.growth_per_1000 = g.trend.slope * 1000;
  // A perfect line (no scatter) is as significant as a slope can be.
  g.significance = g.trend.slope_error > 0 ? g.trend.slope / g.trend.slope_error
                   : g.trend.slope > 0     ? std::numeric_limits<double>::infinity()
                                           : 0;
  g.leak = g.growth_per_1000 > max_growth_per_1000 && g.significance > min_significance;
  return g;
}

absl::Status IdleConnections::Open(int port, int count) {
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  for (int i = 0; i < count; ++i) {
    const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0 || ::connect(fd, reinterpret_cast<const sockaddr*>(&address), sizeof address) != 0) {
      const int error = errno;
      if (fd >= 0) ::close(fd);
      return absl::InternalError(absl::StrCat(fd < 0 ? "socket" : "connect", " to port ", port,
                                              " with ", fds_.size(),
                                              " open: ", std::strerror(error)));
    }
    fds_.push_back(fd);
  }
  return absl::OkStatus();
}

void IdleConnections::Close() {
  for (int fd : fds_) ::close(fd);
  fds_.clear();
}

absl::StatusOr<int> LinecaldProcess::WaitReady(std::chrono::milliseconds timeout) {
  // linecald's "listening on HOST:PORT (port N)" line, logged once calls are served.
  static const std::regex kPort("\\(port ([0-9]+)\\)");
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (true) {
    const std::string log = NewLog();
    std::smatch m;
    int port = 0;
    if (std::regex_search(log, m, kPort) && absl::SimpleAtoi(m[1].str(), &port)) return port;
    siginfo_t info{};
    // WNOWAIT: only look; Wait reaps, so the pid cannot be reused while we hold it.
    if (::waitid(P_PID, static_cast<id_t>(pid_), &info, WEXITED | WNOHANG | WNOWAIT) == 0 &&
        info.si_pid == pid_) {
      return absl::AbortedError(
          absl::StrCat("linecald exited before it was ready; its log:\n", log));
    }
    if (std::chrono::steady_clock::now() > deadline) {
      return absl::DeadlineExceededError(
          absl::StrCat("linecald not ready after ", timeout.count(), " ms; its log:\n", log));
    }
    // 10 ms: start-up takes tens of milliseconds; polling finer only burns the shared cores.
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

void LinecaldProcess::Signal(int signal) const {
  if (!reaped_) ::kill(pid_, signal);
}

int LinecaldProcess::Wait() {
  if (!reaped_ && ::waitpid(pid_, &status_, 0) == pid_) reaped_ = true;
  return status_;
}

std::string DescribeWaitStatus(int status) {
  if (WIFEXITED(status)) return absl::StrCat("exit ", WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return absl::StrCat("killed by signal ", WTERMSIG(status));
  return absl::StrCat("wait status ", status);
}

}  // namespace linecal::reliability

#include "daemon/service/listener_watchdog.h"

#include <arpa/inet.h>
#include <dirent.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

// True when `fd` is a listening TCP socket bound to `port`.
bool IsListenerOn(int fd, int port) {
  int listening = 0, type = 0;
  socklen_t len = sizeof listening;
  if (getsockopt(fd, SOL_SOCKET, SO_ACCEPTCONN, &listening, &len) != 0 || !listening) return false;
  len = sizeof type;
  if (getsockopt(fd, SOL_SOCKET, SO_TYPE, &type, &len) != 0 || type != SOCK_STREAM) return false;
  sockaddr_storage address{};
  len = sizeof address;
  if (getsockname(fd, reinterpret_cast<sockaddr*>(&address), &len) != 0) return false;
  if (address.ss_family == AF_INET) {
    return ntohs(reinterpret_cast<const sockaddr_in&>(address).sin_port) == port;
  }
  if (address.ss_family == AF_INET6) {
    return ntohs(reinterpret_cast<const sockaddr_in6&>(address).sin6_port) == port;
  }
  return false;
}

// Descriptors open in this process and its limit, for the restart's log line.
std::string DescriptorUse() {
  rlimit limit{};
  getrlimit(RLIMIT_NOFILE, &limit);
  int open = 0;
  if (DIR* dir = opendir("/proc/self/fd")) {
    while (readdir(dir) != nullptr) ++open;
    closedir(dir);
    open -= 3;  // ".", ".." and the directory's own descriptor
    return absl::StrCat(open, " of ", limit.rlim_cur, " descriptors open");
  }
  return absl::StrCat("descriptors: /proc/self/fd: ", std::strerror(errno), " (limit ",
                      limit.rlim_cur, ")");
}

}  // namespace

absl::StatusOr<std::vector<int>> ListeningSockets(int port) {
  DIR* dir = opendir("/proc/self/fd");
  if (dir == nullptr) {
    const int error = errno;
    const std::string message = absl::StrCat("/proc/self/fd: ", std::strerror(error));
    return error == EMFILE || error == ENFILE ? absl::ResourceExhaustedError(message)
                                              : absl::InternalError(message);
  }
  const int own = dirfd(dir);
  std::vector<int> fds;
  while (const dirent* entry = readdir(dir)) {
    int fd = -1;
    if (!absl::SimpleAtoi(entry->d_name, &fd) || fd == own) continue;
    if (IsListenerOn(fd, port)) fds.push_back(fd);
  }
  closedir(dir);
  std::sort(fds.begin(), fds.end());
  return fds;
}

absl::StatusOr<int> AcceptQueueLength(int fd, int port) {
  if (!IsListenerOn(fd, port)) {
    return absl::FailedPreconditionError(
        absl::StrCat("descriptor ", fd, " is no listening TCP socket on port ", port));
  }
  tcp_info info{};
  socklen_t len = sizeof info;
  if (getsockopt(fd, IPPROTO_TCP, TCP_INFO, &info, &len) != 0) {
    return absl::FailedPreconditionError(
        absl::StrCat("descriptor ", fd, ": TCP_INFO: ", std::strerror(errno)));
  }
  // For a listening socket Linux reports the accept queue's length in tcpi_unacked
  // (net/ipv4/tcp.c, tcp_get_info) and its capacity in tcpi_sacked.
  return static_cast<int>(info.tcpi_unacked);
}

void DescriptorReserve::Take() {
  while (static_cast<int>(fds_.size()) < size_) {
    const int fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
    if (fd < 0) return;
    fds_.push_back(fd);
  }
}

void DescriptorReserve::Release() {
  for (int fd : fds_) ::close(fd);
  fds_.clear();
}

ListenerWatchdog::ListenerWatchdog(RunningServer* server, std::string address, StartFn start,
                                   LogFn log)
    : server_(server),
      address_(std::move(address)),
      start_(std::move(start)),
      log_(std::move(log)) {
  thread_ = std::thread([this] { Loop(); });
}

ListenerWatchdog::~ListenerWatchdog() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  stop_changed_.notify_all();
  thread_.join();
}

int ListenerWatchdog::restarts() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return restarts_;
}

bool ListenerWatchdog::SleepUnlessStopped(std::chrono::milliseconds d) {
  std::unique_lock<std::mutex> lock(mutex_);
  return !stop_changed_.wait_for(lock, d, [this] { return stop_; });
}

bool ListenerWatchdog::ListenerStuck() {
  if (listeners_.empty()) {
    // Found once per server; while descriptors are exhausted this cannot look, and tries
    // again at the next sample.
    absl::StatusOr<std::vector<int>> found = ListeningSockets(server_->port);
    if (!found.ok()) return false;
    listeners_ = *std::move(found);
  }
  int queued = 0;
  for (int fd : listeners_) {
    absl::StatusOr<int> n = AcceptQueueLength(fd, server_->port);
    if (!n.ok()) {  // not gRPC's listener any more: look again
      listeners_.clear();
      stuck_samples_ = 0;
      return false;
    }
    queued += *n;
  }
  stuck_samples_ = queued > 0 ? stuck_samples_ + 1 : 0;
  last_queued_ = queued;
  return stuck_samples_ >= kStuckSamples;
}

bool ListenerWatchdog::Restart(int queued) {
  reserve_.Release();  // before DescriptorUse, which needs one
  log_("error", absl::StrCat("gRPC's listener on ", address_, " stopped accepting (", queued,
                             " connections waiting unaccepted for ", kStuckSamples - 1,
                             " s or more; gRPC 1.51 stops listening after an accept error such as "
                             "EMFILE); ",
                             DescriptorUse(),
                             "; restarting the gRPC server on the same address (calls in "
                             "flight get ",
                             kRestartGrace.count(), " ms, then clients reconnect)"));
  if (server_->server) {
    server_->server->Shutdown(std::chrono::system_clock::now() + kRestartGrace);
  }
  *server_ = {};
  listeners_.clear();
  stuck_samples_ = 0;
  std::string last_error;
  while (true) {
    absl::StatusOr<RunningServer> again = start_();
    if (again.ok()) {
      *server_ = *std::move(again);
      break;
    }
    // Said once per restart, not every retry.
    if (std::string error(again.status().message()); error != last_error) {
      log_("warning", absl::StrCat("restarting the gRPC server: ", error, "; retrying every ",
                                   kRetryInterval.count(), " ms"));
      last_error = std::move(error);
    }
    if (!SleepUnlessStopped(kRetryInterval)) return false;
  }
  reserve_.Take();
  int n = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    n = ++restarts_;
  }
  log_("info", absl::StrCat("listening again on ", address_, " (restart ", n, ")"));
  return true;
}

void ListenerWatchdog::Loop() {
  while (SleepUnlessStopped(kSampleInterval)) {
    if (reserve_.held() < kReserveDescriptors) reserve_.Take();
    if (ListenerStuck() && !Restart(last_queued_)) return;
  }
}

}  // namespace linecal

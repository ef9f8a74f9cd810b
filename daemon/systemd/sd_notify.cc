#include "daemon/systemd/sd_notify.h"

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"

namespace linecal {

SystemdNotifier::SystemdNotifier(std::string socket,
                                 std::optional<std::chrono::microseconds> watchdog)
    : socket_(std::move(socket)), watchdog_(watchdog) {}

SystemdNotifier SystemdNotifier::FromEnvironment() {
  const char* socket = std::getenv("NOTIFY_SOCKET");
  std::optional<std::chrono::microseconds> watchdog;
  std::uint64_t usec = 0;
  const char* usec_text = std::getenv("WATCHDOG_USEC");
  const char* pid_text = std::getenv("WATCHDOG_PID");
  std::int64_t pid = 0;
  const bool ours = pid_text == nullptr || (absl::SimpleAtoi(pid_text, &pid) && pid == ::getpid());
  if (usec_text != nullptr && absl::SimpleAtoi(usec_text, &usec) && usec > 0 && ours) {
    watchdog = std::chrono::microseconds(usec);
  }
  return SystemdNotifier(socket == nullptr ? "" : socket, watchdog);
}

absl::Status SystemdNotifier::Notify(std::string_view state) const {
  if (!enabled()) return absl::OkStatus();
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  if (socket_.size() >= sizeof(address.sun_path) || (socket_[0] != '/' && socket_[0] != '@')) {
    return absl::InvalidArgumentError(
        absl::StrCat("NOTIFY_SOCKET '", socket_, "': not a socket path"));
  }
  std::memcpy(address.sun_path, socket_.data(), socket_.size());
  // "@name" is Linux's abstract namespace: a leading NUL, and the length counts exactly.
  if (socket_[0] == '@') address.sun_path[0] = '\0';
  const socklen_t length = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + socket_.size());
  const int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0)
    return absl::UnavailableError(absl::StrCat("NOTIFY_SOCKET: socket(): ", std::strerror(errno)));
  const ssize_t sent = ::sendto(fd, state.data(), state.size(), MSG_NOSIGNAL,
                                reinterpret_cast<const sockaddr*>(&address), length);
  const int error = errno;
  ::close(fd);
  if (sent != static_cast<ssize_t>(state.size())) {
    return absl::UnavailableError(
        absl::StrCat("NOTIFY_SOCKET '", socket_, "': ", std::strerror(error)));
  }
  return absl::OkStatus();
}

}  // namespace linecal

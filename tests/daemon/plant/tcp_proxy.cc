#include "tests/daemon/plant/tcp_proxy.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>

#include "absl/strings/str_cat.h"

namespace linecal::testing_plant {
namespace {

absl::Status Errno(const std::string& what) {
  return absl::InternalError(absl::StrCat("tcp proxy: ", what, ": ", std::strerror(errno)));
}

sockaddr_in Loopback(int port) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<uint16_t>(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  return a;
}

// Closes with a reset rather than a FIN: the peer sees a dropped connection.
void Reset(int fd) {
  const linger l{1, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_LINGER, &l, sizeof l);
  ::close(fd);
}

// Relays what `from` has to `to`; false when either side is done (EOF or error).
bool Relay(int from, int to) {
  char buffer[64 * 1024];
  const ssize_t n = ::read(from, buffer, sizeof buffer);
  if (n <= 0) return false;
  for (ssize_t sent = 0; sent < n;) {
    const ssize_t w = ::send(to, buffer + sent, static_cast<size_t>(n - sent), MSG_NOSIGNAL);
    if (w <= 0) return false;
    sent += w;
  }
  return true;
}

}  // namespace

int ClosedLoopbackPort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a = Loopback(0);
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t length = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &length);
  ::close(fd);
  return ntohs(a.sin_port);
}

absl::StatusOr<std::unique_ptr<TcpProxy>> TcpProxy::Start(int target_port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return Errno("socket");
  sockaddr_in a = Loopback(0);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || ::listen(fd, 64) != 0) {
    const absl::Status s = Errno("bind/listen");
    ::close(fd);
    return s;
  }
  socklen_t length = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &length);
  int wake[2];
  if (::pipe2(wake, O_CLOEXEC | O_NONBLOCK) != 0) {
    const absl::Status s = Errno("pipe");
    ::close(fd);
    return s;
  }
  std::unique_ptr<TcpProxy> proxy(
      new TcpProxy(fd, ntohs(a.sin_port), wake[0], wake[1], target_port));
  proxy->thread_ = std::thread(&TcpProxy::Run, proxy.get());
  return proxy;
}

TcpProxy::~TcpProxy() {
  stop_ = true;
  Wake();
  thread_.join();
  for (const Pair& p : pairs_) {
    ::close(p.client);
    ::close(p.server);
  }
  ::close(listen_fd_);
  ::close(wake_read_);
  ::close(wake_write_);
}

void TcpProxy::Wake() const {
  const char c = 1;
  (void)!::write(wake_write_, &c, 1);
}

void TcpProxy::SetStalled(bool stalled) {
  stalled_ = stalled;
  Wake();
}

void TcpProxy::DropAll() {
  drop_ = true;
  Wake();
}

void TcpProxy::Run() {
  while (!stop_) {
    if (drop_.exchange(false)) {
      for (const Pair& p : pairs_) {
        Reset(p.client);
        Reset(p.server);
      }
      pairs_.clear();
    }
    std::vector<pollfd> fds = {{wake_read_, POLLIN, 0}, {listen_fd_, POLLIN, 0}};
    const bool stalled = stalled_;
    const size_t polled = stalled ? 0 : pairs_.size();  // pairs accepted below wait a round
    if (!stalled) {
      for (const Pair& p : pairs_) {
        fds.push_back({p.client, POLLIN, 0});
        fds.push_back({p.server, POLLIN, 0});
      }
    }
    if (::poll(fds.data(), fds.size(), -1) < 0) continue;
    if (fds[0].revents != 0) {
      char drain[64];
      while (::read(wake_read_, drain, sizeof drain) > 0) {
      }
    }
    if (fds[1].revents & POLLIN) {
      const int client = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
      if (client >= 0) {
        ++accepted_;
        const int server = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
        const sockaddr_in target = Loopback(target_port_);
        if (server >= 0 &&
            ::connect(server, reinterpret_cast<const sockaddr*>(&target), sizeof target) == 0) {
          pairs_.push_back({client, server});
        } else {
          Reset(client);  // the target is down: the client sees it refused, as without us
          if (server >= 0) ::close(server);
        }
      }
    }
    std::vector<Pair> open;
    for (size_t i = 0; i < pairs_.size(); ++i) {
      if (i >= polled) {
        open.push_back(pairs_[i]);
        continue;
      }
      const Pair& p = pairs_[i];
      const short from_client = fds[2 + 2 * i].revents;
      const short from_server = fds[3 + 2 * i].revents;
      bool alive = true;
      if (from_client != 0) alive = Relay(p.client, p.server);
      if (alive && from_server != 0) alive = Relay(p.server, p.client);
      if (alive) {
        open.push_back(p);
      } else {
        ::close(p.client);
        ::close(p.server);
      }
    }
    pairs_ = std::move(open);
  }
}

}  // namespace linecal::testing_plant

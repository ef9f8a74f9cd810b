#pragma once
// A TCP proxy of the tests' own, on real loopback sockets, between the forwarder and the
// plant's PostgreSQL: relays bytes both ways until told to stall (connections stay open,
// nothing moves: a server or network that hangs) or to drop every connection (reset: a
// server or link that goes away mid-call). One thread, poll(2) over every socket.

#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"

namespace linecal::testing_plant {

// A loopback port with nothing listening on it (bound, then closed again): connections to it
// are refused, as to a plant server that is down.
int ClosedLoopbackPort();

class TcpProxy {
 public:
  // Listens on 127.0.0.1 (a free port) and relays each connection to 127.0.0.1:target_port.
  // Internal naming the call when a socket cannot be made.
  static absl::StatusOr<std::unique_ptr<TcpProxy>> Start(int target_port);
  ~TcpProxy();  // closes everything, joins the thread
  TcpProxy(const TcpProxy&) = delete;
  TcpProxy& operator=(const TcpProxy&) = delete;

  int port() const { return port_; }
  // While stalled, no byte is relayed in either direction; new connections are accepted
  // (and connected to the target) but stay silent too.
  void SetStalled(bool stalled);
  // Resets (RST) every open connection, at once; later connections are relayed as usual.
  void DropAll();
  // Connections accepted since Start.
  int64_t accepted() const { return accepted_; }

 private:
  TcpProxy(int listen_fd, int port, int wake_read, int wake_write, int target_port)
      : listen_fd_(listen_fd),
        port_(port),
        wake_read_(wake_read),
        wake_write_(wake_write),
        target_port_(target_port) {}
  void Run();
  void Wake() const;

  struct Pair {
    int client = -1;
    int server = -1;
  };
  const int listen_fd_;
  const int port_;
  const int wake_read_, wake_write_;  // a pipe: wakes poll when a setting changes
  const int target_port_;
  std::atomic<bool> stalled_{false};
  std::atomic<bool> drop_{false};
  std::atomic<bool> stop_{false};
  std::atomic<int64_t> accepted_{0};
  std::vector<Pair> pairs_;  // the thread's own
  std::thread thread_;
};

}  // namespace linecal::testing_plant

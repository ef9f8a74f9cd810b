#pragma once
// Keeps linecald accepting connections after gRPC's listener died (issue 21, item 2).
//
// gRPC 1.51 (Debian 12) stops polling a listening socket for good when accept4 fails with
// anything but EAGAIN, ECONNABORTED or EINTR (EMFILE: descriptors exhausted; its
// src/core/lib/iomgr/tcp_server_posix.cc): the process stays alive, the connections it has
// keep working, and no new one is ever accepted, even once descriptors free up. Nothing in
// gRPC's API says so; its one sign is a log line.
//
// The watchdog tells a dead listener from a live one below gRPC and below TLS, in the
// kernel: the accept queue of the listening socket (TCP_INFO on a listening socket gives the
// number of connections whose handshake completed and that no accept4 has taken yet). A live
// gRPC listener empties it within milliseconds of each arrival; a dead one never takes
// anything from it, and the connection that met EMFILE stays in it. So a queue that is not
// empty at kStuckSamples samples kSampleInterval apart means the listener is dead. No traffic
// is sent, the same works for insecure, TLS and mutual TLS ports, and the check needs no new
// descriptor (the listening descriptors are found once per server, then only queried), so
// it also works while descriptors are exhausted.
//
// On a dead listener the watchdog restarts the gRPC server from its own thread (never from a
// gRPC thread): it logs it once at error, frees a small reserve of descriptors it holds for
// this moment (the shutdown, the new listening socket and, in sanitized builds, the
// sanitizers' own checks need a few while the process is out of them), shuts the old server
// down (calls in flight get kRestartGrace, then are cancelled; its connections close, which
// frees their descriptors), and starts a new server with new service objects on the same
// address, retrying every kRetryInterval until it listens. The station core is not touched:
// a running cycle goes on, and clients reconnect.

#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "daemon/service/station_service.h"

namespace linecal {

// This process's listening TCP sockets bound to `port` (any address; IPv4 and IPv6), by
// descriptor, ascending. Reads /proc/self/fd: ResourceExhausted when that cannot be opened
// (descriptors exhausted), Internal for another error. Cost: one getsockopt per descriptor.
absl::StatusOr<std::vector<int>> ListeningSockets(int port);

// Connections waiting in the accept queue of the listening socket `fd`: handshakes done,
// not yet taken by accept4. FailedPrecondition when `fd` is no longer a listening TCP socket
// on `port` (closed, or its number reused). Cost: three system calls, no descriptor.
absl::StatusOr<int> AcceptQueueLength(int fd, int port);

// Descriptors held for the moment they are needed most; Take and Release never fail (a
// reserve that could only be partly taken is smaller). Not thread-safe.
class DescriptorReserve {
 public:
  explicit DescriptorReserve(int size) : size_(size) { Take(); }
  ~DescriptorReserve() { Release(); }
  DescriptorReserve(const DescriptorReserve&) = delete;
  DescriptorReserve& operator=(const DescriptorReserve&) = delete;

  void Take();     // up to `size` descriptors (of /dev/null)
  void Release();  // all of them
  int held() const { return static_cast<int>(fds_.size()); }

 private:
  int size_;
  std::vector<int> fds_;
};

inline constexpr std::chrono::milliseconds kSampleInterval{1000};
// Three samples a second apart: a live listener takes a connection within milliseconds, so a
// queue never empty for two seconds is a dead listener (or a flood of connections that keeps
// gRPC's poller from accepting for seconds, where a restart costs little more).
inline constexpr int kStuckSamples = 3;
inline constexpr std::chrono::milliseconds kRestartGrace{1000};
inline constexpr std::chrono::milliseconds kRetryInterval{500};
// Descriptors the watchdog keeps free for a restart (see above).
inline constexpr int kReserveDescriptors = 8;

class ListenerWatchdog {
 public:
  using StartFn = std::function<absl::StatusOr<RunningServer>()>;
  using LogFn = std::function<void(const std::string& level, const std::string& message)>;

  // Watches `server` (listening on `address`, its port bound) and replaces it with `start()`
  // when its listener is dead. While the watchdog lives, only its thread touches `*server`;
  // after the destructor (which stops and joins it, within kRestartGrace plus a start) the
  // caller owns it again, and it may be empty when a restart had not yet listened again.
  ListenerWatchdog(RunningServer* server, std::string address, StartFn start, LogFn log);
  ~ListenerWatchdog();
  ListenerWatchdog(const ListenerWatchdog&) = delete;
  ListenerWatchdog& operator=(const ListenerWatchdog&) = delete;

  int restarts() const;  // servers started again so far

 private:
  void Loop();
  // One sample: true when every sample of the last kStuckSamples found a connection waiting.
  bool ListenerStuck();
  // Stops the old server and starts a new one; false when stopped before it listened.
  bool Restart(int queued);
  bool SleepUnlessStopped(std::chrono::milliseconds d);

  RunningServer* server_;
  const std::string address_;
  const StartFn start_;
  const LogFn log_;
  DescriptorReserve reserve_{kReserveDescriptors};
  std::vector<int> listeners_;  // the server's listening descriptors, once found
  int stuck_samples_ = 0;
  int last_queued_ = 0;

  mutable std::mutex mutex_;
  std::condition_variable stop_changed_;
  bool stop_ = false;
  int restarts_ = 0;
  std::thread thread_;
};

}  // namespace linecal

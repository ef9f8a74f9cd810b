// The listener watchdog's parts on real loopback sockets: the kernel's accept queue as the
// watchdog reads it, the descriptor reserve, and a listener that never accepts (as gRPC's
// after EMFILE) found dead and replaced (daemon/service/listener_watchdog.h). The whole path
// with gRPC under a real descriptor limit is
// LinecaldProcessTest.AcceptsAgainAfterDescriptorsRanOut.
#include "daemon/service/listener_watchdog.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace linecal {
namespace {

sockaddr_in Loopback(int port) {
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  return address;
}

// A listening socket on 127.0.0.1 (a free port); closed with the object.
struct Listener {
  Listener() {
    fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in address = Loopback(0);
    socklen_t len = sizeof address;
    if (::bind(fd, reinterpret_cast<sockaddr*>(&address), len) == 0 && ::listen(fd, 16) == 0 &&
        ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &len) == 0) {
      port = ntohs(address.sin_port);
    }
  }
  ~Listener() { ::close(fd); }
  int fd = -1;
  int port = 0;
};

// A connection to `port` (the kernel completes it into the backlog); -1 on failure.
int Connect(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  const sockaddr_in address = Loopback(port);
  if (::connect(fd, reinterpret_cast<const sockaddr*>(&address), sizeof address) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

TEST(ListenerWatchdogTest, AcceptQueueCountsConnectionsNotYetAccepted) {
  Listener listener;
  ASSERT_NE(listener.port, 0);
  const absl::StatusOr<std::vector<int>> found = ListeningSockets(listener.port);
  ASSERT_TRUE(found.ok()) << found.status();
  EXPECT_EQ(*found, std::vector<int>{listener.fd});
  EXPECT_EQ(*AcceptQueueLength(listener.fd, listener.port), 0);

  const int a = Connect(listener.port), b = Connect(listener.port);
  ASSERT_GE(a, 0);
  ASSERT_GE(b, 0);
  EXPECT_EQ(*AcceptQueueLength(listener.fd, listener.port), 2);
  const int accepted = ::accept4(listener.fd, nullptr, nullptr, SOCK_CLOEXEC);
  ASSERT_GE(accepted, 0);
  EXPECT_EQ(*AcceptQueueLength(listener.fd, listener.port), 1);
  // An accepted connection is no listener, and a listener on another port is not ours.
  EXPECT_EQ(AcceptQueueLength(accepted, listener.port).status().code(),
            absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(AcceptQueueLength(listener.fd, listener.port + 1).status().code(),
            absl::StatusCode::kFailedPrecondition);
  for (int fd : {a, b, accepted}) ::close(fd);
}

TEST(ListenerWatchdogTest, ReserveHoldsDescriptorsUntilReleased) {
  DescriptorReserve reserve(4);
  EXPECT_EQ(reserve.held(), 4);
  reserve.Release();
  EXPECT_EQ(reserve.held(), 0);
  reserve.Take();
  EXPECT_EQ(reserve.held(), 4);
}

// A listener that never accepts, with a connection waiting: found dead within
// kStuckSamples samples, stopped and replaced by what `start` returns, on the same port.
TEST(ListenerWatchdogTest, ListenerThatNeverAcceptsIsReplaced) {
  auto dead = std::make_unique<Listener>();
  ASSERT_NE(dead->port, 0);
  const int port = dead->port;
  RunningServer server;
  server.port = port;
  std::mutex mutex;
  std::vector<std::string> lines;
  int starts = 0;
  const int waiting = Connect(port);
  ASSERT_GE(waiting, 0);
  const auto t0 = std::chrono::steady_clock::now();
  int restarts = 0;
  {
    ListenerWatchdog watchdog(
        &server, "127.0.0.1:" + std::to_string(port),
        [&]() -> absl::StatusOr<RunningServer> {
          std::lock_guard<std::mutex> lock(mutex);
          ++starts;
          dead.reset();  // the old listener goes as the old server would
          RunningServer again;
          again.port = port;
          return again;
        },
        [&](const std::string& level, const std::string& message) {
          std::lock_guard<std::mutex> lock(mutex);
          lines.push_back(level + ": " + message);
        });
    while (watchdog.restarts() == 0 &&
           std::chrono::steady_clock::now() - t0 < std::chrono::seconds(10)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    restarts = watchdog.restarts();
  }
  const double after_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ::close(waiting);
  EXPECT_EQ(restarts, 1);
  EXPECT_EQ(starts, 1);
  // Three samples a second apart see the connection: dead after 3 s, not before.
  EXPECT_GE(after_s, 0.001 * (kStuckSamples * kSampleInterval).count() - 0.1);
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[0].rfind("error: gRPC's listener on 127.0.0.1:" + std::to_string(port) +
                               " stopped accepting (1 connections waiting",
                           0),
            0u)
      << lines[0];
  EXPECT_EQ(lines[1],
            "info: listening again on 127.0.0.1:" + std::to_string(port) + " (restart 1)");
}

// A listener that accepts everything is never restarted, however many connections come.
TEST(ListenerWatchdogTest, ListenerThatAcceptsIsLeftAlone) {
  Listener live;
  ASSERT_NE(live.port, 0);
  RunningServer server;
  server.port = live.port;
  int starts = 0;
  {
    ListenerWatchdog watchdog(
        &server, "127.0.0.1:" + std::to_string(live.port),
        [&]() -> absl::StatusOr<RunningServer> {
          ++starts;
          return RunningServer{};
        },
        [](const std::string&, const std::string&) {});
    // Connections arriving and taken for longer than the watchdog's window.
    const auto end = std::chrono::steady_clock::now() + (kStuckSamples + 1) * kSampleInterval;
    while (std::chrono::steady_clock::now() < end) {
      const int client = Connect(live.port);
      ASSERT_GE(client, 0);
      const int accepted = ::accept4(live.fd, nullptr, nullptr, SOCK_CLOEXEC);
      ASSERT_GE(accepted, 0);
      ::close(accepted);
      ::close(client);
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }
  EXPECT_EQ(starts, 0);
}

}  // namespace
}  // namespace linecal

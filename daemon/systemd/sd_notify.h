#pragma once
// systemd's service notification protocol (sd_notify(3)) without libsystemd: a datagram of
// "KEY=value" lines to the AF_UNIX socket systemd names in NOTIFY_SOCKET. linecald sends
// READY=1 once it serves calls, WATCHDOG=1 while its core answers, STOPPING=1 on SIGTERM
// (deploy/linecald.service: Type=notify, WatchdogSec). Outside systemd (no NOTIFY_SOCKET)
// every call is a no-op.

#include <chrono>
#include <optional>
#include <string>
#include <string_view>

#include "absl/status/status.h"

namespace linecal {

class SystemdNotifier {
 public:
  // From NOTIFY_SOCKET (a path, or "@name" for an abstract socket), WATCHDOG_USEC and
  // WATCHDOG_PID (the watchdog is ours only when the PID is unset or this process's).
  static SystemdNotifier FromEnvironment();
  // `socket`: as NOTIFY_SOCKET; empty: disabled. `watchdog`: as WATCHDOG_USEC.
  SystemdNotifier(std::string socket, std::optional<std::chrono::microseconds> watchdog);

  bool enabled() const { return !socket_.empty(); }
  // How often systemd wants WATCHDOG=1 at the latest; nullopt: no watchdog.
  std::optional<std::chrono::microseconds> watchdog_interval() const { return watchdog_; }

  // Sends `state` ("READY=1\nSTATUS=..."). OK and nothing sent when disabled; Unavailable
  // naming the socket when it cannot be reached. One socket per call: rare messages.
  absl::Status Notify(std::string_view state) const;

 private:
  std::string socket_;
  std::optional<std::chrono::microseconds> watchdog_;
};

}  // namespace linecal

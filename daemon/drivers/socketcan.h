#pragma once
// Reading CAN frames from a Linux SocketCAN interface (raw socket, classic and CAN FD, with
// error frames and kernel receive timestamps).
//
// Opening tells apart the failures an installer meets (docs/sensors.md):
//   FailedPrecondition "kernel has no CAN support"  socket(PF_CAN) fails with EAFNOSUPPORT
//   NotFound           "no such interface"          if_nametoindex() = 0
//   FailedPrecondition "interface ... is down"      SIOCGIFFLAGS without IFF_UP
//   FailedPrecondition "not a CAN interface"        link type is not ARPHRD_CAN, or bind ENODEV
// Other system-call failures are Internal with the call and strerror.

#include <sys/socket.h>

#include <chrono>
#include <optional>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "station/io/candump.h"

struct canfd_frame;

namespace linecal {

// The system calls SocketCanReader::Open makes, replaceable by tests: this machine's kernel
// has no CAN, so the steps after socket(PF_CAN) can only be reached with stand-ins. The
// defaults are the real calls. Reading (poll, recvmsg) always uses the real calls on
// whatever descriptor `socket` returned.
struct SocketCanSyscalls {
  int (*socket)(int domain, int type, int protocol);
  unsigned (*if_nametoindex)(const char* name);
  // ioctl(fd, request, struct ifreq*) for SIOCGIFFLAGS and SIOCGIFHWADDR.
  int (*ioctl_ifreq)(int fd, unsigned long request, void* ifreq);
  int (*setsockopt)(int fd, int level, int name, const void* value, socklen_t size);
  int (*bind)(int fd, const sockaddr* address, socklen_t size);

  static SocketCanSyscalls Real();
};

// Converts a frame as the kernel delivers it (`bytes` = CAN_MTU for classic, CANFD_MTU for
// CAN FD) into a CanFrame. InvalidArgument (DataLoss for a bad size) when the kernel frame
// violates CanFrame's invariants. Cost: O(1).
absl::StatusOr<CanFrame> CanFrameFromKernel(const canfd_frame& kernel, size_t bytes,
                                            const std::string& interface, CanTime time);

class SocketCanReader {
 public:
  // Opens a raw CAN socket bound to `interface` (e.g. "can0"), receiving CAN FD frames where
  // the kernel supports them and error frames. Errors as listed at the top of this file;
  // InvalidArgument for a name longer than 15 characters. Owns the socket.
  static absl::StatusOr<SocketCanReader> Open(
      const std::string& interface, const SocketCanSyscalls& syscalls = SocketCanSyscalls::Real());

  SocketCanReader(SocketCanReader&& other) noexcept;
  SocketCanReader& operator=(SocketCanReader&& other) noexcept;
  SocketCanReader(const SocketCanReader&) = delete;
  SocketCanReader& operator=(const SocketCanReader&) = delete;
  ~SocketCanReader();

  // Waits up to `timeout` for one frame. nullopt when none arrived in time; the frame's time
  // is the kernel's receive timestamp (CLOCK_REALTIME; the time of reading when the kernel
  // gave none). DataLoss for a datagram of the wrong size; Internal for a failed poll/recvmsg.
  // Blocks for at most `timeout` (EINTR restarts the wait without extending it).
  absl::StatusOr<std::optional<CanFrame>> Read(std::chrono::milliseconds timeout);

  const std::string& interface() const { return interface_; }

 private:
  SocketCanReader(int fd, std::string interface) : fd_(fd), interface_(std::move(interface)) {}

  int fd_ = -1;
  std::string interface_;
};

}  // namespace linecal

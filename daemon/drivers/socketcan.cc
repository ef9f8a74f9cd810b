#include "daemon/drivers/socketcan.h"

#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <net/if_arp.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <utility>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

int RealIoctlIfreq(int fd, unsigned long request, void* ifreq) {
  return ::ioctl(fd, request, ifreq);
}

std::string Errno(int error) { return std::strerror(error); }

absl::Status SyscallError(const std::string& what, const std::string& interface, int error) {
  return absl::InternalError(absl::StrCat(interface, ": ", what, " failed: ", Errno(error)));
}

// Closes a descriptor unless released; keeps Open's early returns leak-free.
class FdGuard {
 public:
  explicit FdGuard(int fd) : fd_(fd) {}
  ~FdGuard() {
    if (fd_ >= 0) ::close(fd_);
  }
  int release() { return std::exchange(fd_, -1); }

 private:
  int fd_;
};

CanTime Now() {
  return std::chrono::time_point_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now());
}

}  // namespace

SocketCanSyscalls SocketCanSyscalls::Real() {
  return {::socket, ::if_nametoindex, RealIoctlIfreq, ::setsockopt, ::bind};
}

absl::StatusOr<CanFrame> CanFrameFromKernel(const canfd_frame& kernel, size_t bytes,
                                            const std::string& interface, CanTime time) {
  if (bytes != CAN_MTU && bytes != CANFD_MTU) {
    return absl::DataLossError(absl::StrCat(interface, ": CAN datagram of ", bytes,
                                            " bytes (expected ", CAN_MTU, " or ", CANFD_MTU, ")"));
  }
  CanFrame frame;
  frame.time = time;
  frame.interface = interface;
  if ((kernel.can_id & CAN_ERR_FLAG) != 0) {
    frame.error = true;
    frame.id = kernel.can_id & CAN_ERR_MASK;
  } else if ((kernel.can_id & CAN_EFF_FLAG) != 0) {
    frame.extended = true;
    frame.id = kernel.can_id & CAN_EFF_MASK;
  } else {
    frame.id = kernel.can_id & CAN_SFF_MASK;
  }
  frame.fd = bytes == CANFD_MTU;
  frame.remote = !frame.fd && (kernel.can_id & CAN_RTR_FLAG) != 0;
  // The flags nibble of candump's `##f`: BRS, ESI and FDF.
  constexpr uint8_t kFdFlagsMask = 0x0F;
  frame.fd_flags = frame.fd ? static_cast<uint8_t>(kernel.flags & kFdFlagsMask) : 0;
  frame.len = kernel.len;
  if (!frame.remote) {
    std::copy_n(kernel.data, std::min<size_t>(kernel.len, kCanFdMaxDataBytes), frame.data.begin());
  }
  if (absl::Status s = ValidateCanFrame(frame); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(interface, ": kernel frame: ", s.message()));
  }
  return frame;
}

absl::StatusOr<SocketCanReader> SocketCanReader::Open(const std::string& interface,
                                                      const SocketCanSyscalls& sys) {
  if (interface.empty() || interface.size() >= IFNAMSIZ) {
    return absl::InvalidArgumentError(absl::StrCat("CAN interface name '", interface,
                                                   "' must have 1..", IFNAMSIZ - 1, " characters"));
  }
  const int fd = sys.socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW);
  if (fd < 0) {
    const int error = errno;
    if (error == EAFNOSUPPORT) {
      return absl::FailedPreconditionError(absl::StrCat(
          interface, ": kernel has no CAN support (socket(PF_CAN) failed: ", Errno(error),
          "); load the can and can_raw modules (modprobe can_raw)"));
    }
    return SyscallError("socket(PF_CAN)", interface, error);
  }
  FdGuard guard(fd);

  const unsigned index = sys.if_nametoindex(interface.c_str());
  if (index == 0) {
    return absl::NotFoundError(
        absl::StrCat(interface, ": no such interface (ip link lists the interfaces)"));
  }
  ifreq request{};
  interface.copy(request.ifr_name, IFNAMSIZ - 1);
  if (sys.ioctl_ifreq(fd, SIOCGIFFLAGS, &request) < 0) {
    return SyscallError("SIOCGIFFLAGS", interface, errno);
  }
  if ((request.ifr_flags & IFF_UP) == 0) {
    return absl::FailedPreconditionError(absl::StrCat(
        interface, ": interface is down (ip link set ", interface, " up type can bitrate 500000)"));
  }
  if (sys.ioctl_ifreq(fd, SIOCGIFHWADDR, &request) < 0) {
    return SyscallError("SIOCGIFHWADDR", interface, errno);
  }
  if (request.ifr_hwaddr.sa_family != ARPHRD_CAN) {
    return absl::FailedPreconditionError(absl::StrCat(
        interface, ": not a CAN interface (link type ", request.ifr_hwaddr.sa_family, ")"));
  }
  // CAN FD frames are welcome where the kernel supports them; an old kernel without
  // CAN_RAW_FD_FRAMES (ENOPROTOOPT) still delivers classic frames.
  const int on = 1;
  if (sys.setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on) < 0 &&
      errno != ENOPROTOOPT) {
    return SyscallError("setsockopt(CAN_RAW_FD_FRAMES)", interface, errno);
  }
  // Every error class, so bus errors are recorded and counted rather than hidden.
  const can_err_mask_t all_errors = CAN_ERR_MASK;
  if (sys.setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &all_errors, sizeof all_errors) < 0) {
    return SyscallError("setsockopt(CAN_RAW_ERR_FILTER)", interface, errno);
  }
  if (sys.setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on) < 0) {
    return SyscallError("setsockopt(SO_TIMESTAMPNS)", interface, errno);
  }
  sockaddr_can address{};
  address.can_family = AF_CAN;
  address.can_ifindex = static_cast<int>(index);
  if (sys.bind(fd, reinterpret_cast<const sockaddr*>(&address), sizeof address) < 0) {
    const int error = errno;
    if (error == ENODEV) {
      return absl::FailedPreconditionError(
          absl::StrCat(interface, ": not a CAN interface (bind: ", Errno(error), ")"));
    }
    return SyscallError("bind", interface, error);
  }
  return SocketCanReader(guard.release(), interface);
}

SocketCanReader::SocketCanReader(SocketCanReader&& other) noexcept
    : fd_(std::exchange(other.fd_, -1)), interface_(std::move(other.interface_)) {}

SocketCanReader& SocketCanReader::operator=(SocketCanReader&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = std::exchange(other.fd_, -1);
    interface_ = std::move(other.interface_);
  }
  return *this;
}

SocketCanReader::~SocketCanReader() {
  if (fd_ >= 0) ::close(fd_);
}

absl::StatusOr<std::optional<CanFrame>> SocketCanReader::Read(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  pollfd waiting{fd_, POLLIN, 0};
  while (true) {
    // Rounded up: poll() counts whole milliseconds, and returning early is not a timeout.
    const auto left =
        std::chrono::ceil<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    const int ready = ::poll(&waiting, 1, static_cast<int>(std::max<int64_t>(0, left.count())));
    if (ready > 0) break;
    if (ready == 0) return std::nullopt;
    if (errno != EINTR) return SyscallError("poll", interface_, errno);
  }
  canfd_frame kernel{};
  iovec data{&kernel, sizeof kernel};
  // Room for one SCM_TIMESTAMPNS control message.
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec))];
  msghdr message{};
  message.msg_iov = &data;
  message.msg_iovlen = 1;
  message.msg_control = control;
  message.msg_controllen = sizeof control;
  ssize_t bytes;
  do {
    // MSG_TRUNC: a longer datagram reports its real size and is refused below.
    bytes = ::recvmsg(fd_, &message, MSG_TRUNC);
  } while (bytes < 0 && errno == EINTR);
  if (bytes < 0) return SyscallError("recvmsg", interface_, errno);
  CanTime time = Now();
  for (cmsghdr* c = CMSG_FIRSTHDR(&message); c != nullptr; c = CMSG_NXTHDR(&message, c)) {
    if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_TIMESTAMPNS) {
      timespec stamp;
      std::memcpy(&stamp, CMSG_DATA(c), sizeof stamp);
      time = CanTime(std::chrono::seconds(stamp.tv_sec) + std::chrono::nanoseconds(stamp.tv_nsec));
    }
  }
  absl::StatusOr<CanFrame> frame =
      CanFrameFromKernel(kernel, static_cast<size_t>(bytes), interface_, time);
  if (!frame.ok()) return frame.status();
  return std::optional<CanFrame>(*std::move(frame));
}

}  // namespace linecal

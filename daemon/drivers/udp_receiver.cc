#include "daemon/drivers/udp_receiver.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <utility>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

std::string ErrnoText(int e) { return std::strerror(e); }

bool ParseIpv4(const std::string& text, in_addr* out) {
  return inet_pton(AF_INET, text.c_str(), out) == 1;
}

std::int64_t RealtimeNowNs() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace

absl::Status UdpReceiverOptions::Validate() const {
  in_addr a{};
  if (!ParseIpv4(bind_address, &a)) {
    return absl::InvalidArgumentError(
        absl::StrCat("bind_address: '", bind_address, "' is not an IPv4 address"));
  }
  if (!multicast_group.empty()) {
    if (!ParseIpv4(multicast_group, &a) || !IN_MULTICAST(ntohl(a.s_addr))) {
      return absl::InvalidArgumentError(absl::StrCat("multicast_group: '", multicast_group,
                                                     "' is not an IPv4 multicast address"));
    }
    if (!ParseIpv4(multicast_interface, &a)) {
      return absl::InvalidArgumentError(
          absl::StrCat("multicast_interface: '", multicast_interface, "' is not an IPv4 address"));
    }
  }
  if (receive_buffer_bytes <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("receive_buffer_bytes: ", receive_buffer_bytes, " must be > 0"));
  }
  // The largest UDP payload over IPv4 is 65507 bytes; a buffer beyond it is never used.
  if (max_datagram_bytes == 0 || max_datagram_bytes > 65507) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_datagram_bytes: ", max_datagram_bytes, " must be in 1..65507"));
  }
  if (receive_timeout.count() <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("receive_timeout: ", receive_timeout.count(), " ms must be > 0"));
  }
  return absl::OkStatus();
}

UdpReceiver::UdpReceiver(int socket_fd, int wake_fd, UdpReceiverOptions options)
    : socket_fd_(socket_fd),
      wake_fd_(wake_fd),
      options_(std::move(options)),
      // One extra byte: a datagram that fills it is longer than the limit (MSG_TRUNC tells
      // too, but this keeps the check independent of it).
      buffer_(new std::uint8_t[options_.max_datagram_bytes + 1]) {}

UdpReceiver::~UdpReceiver() {
  close(socket_fd_);
  close(wake_fd_);
}

absl::StatusOr<std::unique_ptr<UdpReceiver>> UdpReceiver::Open(const UdpReceiverOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  const int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return absl::UnavailableError(absl::StrCat("socket: ", ErrnoText(errno)));
  const int wake = eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
  if (wake < 0) {
    const int e = errno;
    close(fd);
    return absl::UnavailableError(absl::StrCat("eventfd: ", ErrnoText(e)));
  }
  std::unique_ptr<UdpReceiver> r(new UdpReceiver(fd, wake, options));
  const std::string where = absl::StrCat(options.bind_address, ":", options.port);

  // Beyond net.core.rmem_max only with CAP_NET_ADMIN (SO_RCVBUFFORCE); otherwise the kernel
  // caps SO_RCVBUF there, and receive_buffer_bytes() reports what was granted.
  const int want = options.receive_buffer_bytes;
  if (setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &want, sizeof(want)) != 0) {
    setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &want, sizeof(want));
  }
  int granted = 0;
  socklen_t len = sizeof(granted);
  getsockopt(fd, SOL_SOCKET, SO_RCVBUF, &granted, &len);
  r->granted_buffer_bytes_ = granted;
  const int one = 1;
  // Kernel receive times and the kernel's drop counter, delivered with every datagram.
  if (setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof(one)) != 0 ||
      setsockopt(fd, SOL_SOCKET, SO_RXQ_OVFL, &one, sizeof(one)) != 0) {
    return absl::UnavailableError(absl::StrCat(where, ": setsockopt: ", ErrnoText(errno)));
  }
  if (!options.multicast_group.empty()) {
    // Several receivers (the daemon, a recorder) may listen to one group.
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
  }

  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(options.port);
  ParseIpv4(options.bind_address, &addr.sin_addr);
  if (bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0) {
    return absl::UnavailableError(absl::StrCat("bind ", where, ": ", ErrnoText(errno)));
  }
  sockaddr_in bound{};
  socklen_t bound_len = sizeof(bound);
  getsockname(fd, reinterpret_cast<sockaddr*>(&bound), &bound_len);
  r->port_ = ntohs(bound.sin_port);

  if (!options.multicast_group.empty()) {
    ip_mreq m{};
    ParseIpv4(options.multicast_group, &m.imr_multiaddr);
    ParseIpv4(options.multicast_interface, &m.imr_interface);
    if (setsockopt(fd, IPPROTO_IP, IP_ADD_MEMBERSHIP, &m, sizeof(m)) != 0) {
      return absl::UnavailableError(absl::StrCat("join ", options.multicast_group, " on ",
                                                 options.multicast_interface, ": ",
                                                 ErrnoText(errno)));
    }
  }
  return r;
}

absl::Status UdpReceiver::ReceiveOne(const Sink& sink) {
  if (stopped_.load()) return absl::CancelledError("receiver stopped");
  pollfd fds[2] = {{socket_fd_, POLLIN, 0}, {wake_fd_, POLLIN, 0}};
  const int ready = poll(fds, 2, static_cast<int>(options_.receive_timeout.count()));
  if (ready < 0) {
    if (errno == EINTR) return absl::DeadlineExceededError("interrupted");
    return absl::InternalError(absl::StrCat("poll: ", ErrnoText(errno)));
  }
  if (stopped_.load()) return absl::CancelledError("receiver stopped");
  if (ready == 0) {
    ++timeouts_;
    return absl::DeadlineExceededError(absl::StrCat("no datagram on port ", port_, " within ",
                                                    options_.receive_timeout.count(), " ms"));
  }

  iovec iov{buffer_.get(), options_.max_datagram_bytes + 1};
  // Room for SCM_TIMESTAMPNS (a timespec) and SO_RXQ_OVFL (a u32), with their headers.
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(std::uint32_t))];
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  msg.msg_controllen = sizeof(control);
  const ssize_t n = recvmsg(socket_fd_, &msg, MSG_DONTWAIT);
  if (n < 0) {
    if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) {
      return absl::DeadlineExceededError("no datagram after all");
    }
    return absl::InternalError(absl::StrCat("recvmsg on port ", port_, ": ", ErrnoText(errno)));
  }
  std::int64_t time_ns = 0;
  for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
    if (c->cmsg_level != SOL_SOCKET) continue;
    if (c->cmsg_type == SCM_TIMESTAMPNS) {
      timespec ts;
      std::memcpy(&ts, CMSG_DATA(c), sizeof(ts));
      time_ns = static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
    } else if (c->cmsg_type == SO_RXQ_OVFL) {
      std::uint32_t drops;
      std::memcpy(&drops, CMSG_DATA(c), sizeof(drops));
      kernel_drops_.store(drops);
    }
  }
  if (time_ns == 0) time_ns = RealtimeNowNs();
  if ((msg.msg_flags & MSG_TRUNC) != 0 ||
      static_cast<std::size_t>(n) > options_.max_datagram_bytes) {
    ++truncated_;
    return absl::OkStatus();
  }
  ++datagrams_;
  bytes_ += n;
  sink(std::span<const std::uint8_t>(buffer_.get(), static_cast<std::size_t>(n)), time_ns);
  return absl::OkStatus();
}

absl::Status UdpReceiver::Run(const Sink& sink) {
  while (true) {
    const absl::Status s = ReceiveOne(sink);
    if (s.ok() || absl::IsDeadlineExceeded(s)) continue;
    if (absl::IsCancelled(s)) return absl::OkStatus();
    return s;
  }
}

void UdpReceiver::Stop() {
  stopped_.store(true);
  const std::uint64_t one = 1;
  // Wakes a poll() in progress; a full counter (impossible after one write) is harmless.
  [[maybe_unused]] const ssize_t w = write(wake_fd_, &one, sizeof(one));
}

UdpReceiverStats UdpReceiver::stats() const {
  UdpReceiverStats s;
  s.datagrams = datagrams_.load();
  s.bytes = bytes_.load();
  s.truncated = truncated_.load();
  s.kernel_drops = kernel_drops_.load();
  s.timeouts = timeouts_.load();
  return s;
}

}  // namespace linecal

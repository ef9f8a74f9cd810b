#pragma once
// A UDP receiver for LiDAR packets: binds an IPv4 address and port (optionally joining a
// multicast group), asks for a large kernel receive buffer, and hands each datagram with its
// kernel receive time to a sink — typically LidarDecoder::AddPacket, exactly as
// DecodeLidarPcap does for recorded packets.
//
// Counters: datagrams and bytes delivered, datagrams longer than max_datagram_bytes (cut by
// the kernel; counted, not delivered), datagrams the kernel dropped because the receive
// buffer was full (SO_RXQ_OVFL), and receive timeouts.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace linecal {

struct UdpReceiverOptions {
  std::string bind_address = "0.0.0.0";  // IPv4 literal; 0.0.0.0 = every interface
  std::uint16_t port = 2368;             // 0: any free port (see UdpReceiver::port())
  // IPv4 multicast group to join (224.0.0.0/4), or empty for unicast/broadcast reception.
  std::string multicast_group;
  // Local IPv4 address of the interface to join the group on; 0.0.0.0 lets the kernel choose.
  std::string multicast_interface = "0.0.0.0";
  // A Pandar64 in dual-return mode sends about 7 MB/s; 8 MiB holds about a second of it, so
  // a consumer that stalls briefly loses nothing. The kernel caps the request at
  // net.core.rmem_max unless the process may override it (CAP_NET_ADMIN).
  int receive_buffer_bytes = 8 << 20;
  // Largest datagram delivered. LiDAR payloads are at most 1206 bytes; anything above this
  // is not a LiDAR packet.
  std::size_t max_datagram_bytes = 2048;
  // How long ReceiveOne waits for a datagram.
  std::chrono::milliseconds receive_timeout{100};

  // InvalidArgument naming the field: addresses that are not IPv4 literals, a group outside
  // 224.0.0.0/4, a non-positive buffer, size or timeout.
  absl::Status Validate() const;
};

struct UdpReceiverStats {
  std::int64_t datagrams = 0;     // delivered to the sink
  std::int64_t bytes = 0;         // payload bytes delivered
  std::int64_t truncated = 0;     // longer than max_datagram_bytes: not delivered
  std::int64_t kernel_drops = 0;  // dropped by the kernel, receive buffer full
  std::int64_t timeouts = 0;      // ReceiveOne calls that waited in vain
};

class UdpReceiver {
 public:
  // `payload` is valid during the call only; `receive_time_ns` is the kernel's receive time
  // (CLOCK_REALTIME, ns since the epoch).
  using Sink =
      std::function<void(std::span<const std::uint8_t> payload, std::int64_t receive_time_ns)>;

  // Creates, configures and binds the socket. InvalidArgument for bad options; Unavailable
  // naming the address and the errno text when the socket cannot be bound (port in use, no
  // such local address) or the group cannot be joined. Cost: a few system calls.
  static absl::StatusOr<std::unique_ptr<UdpReceiver>> Open(const UdpReceiverOptions& options);

  ~UdpReceiver();
  UdpReceiver(const UdpReceiver&) = delete;
  UdpReceiver& operator=(const UdpReceiver&) = delete;

  std::uint16_t port() const { return port_; }  // the bound port
  // The receive buffer the kernel granted (it reports twice the usable size).
  int receive_buffer_bytes() const { return granted_buffer_bytes_; }

  // Waits up to receive_timeout for one datagram and delivers it. OK when one was delivered
  // or one was too long (counted); DeadlineExceeded on timeout; Cancelled once Stop() was
  // called; Internal naming the errno text on a socket error. One thread at a time.
  absl::Status ReceiveOne(const Sink& sink);

  // Delivers datagrams until Stop(); returns OK then, or the first socket error.
  absl::Status Run(const Sink& sink);

  // Makes Run/ReceiveOne return promptly (wakes a waiting call). Thread-safe; idempotent.
  void Stop();

  // A consistent-enough snapshot (each counter atomic). Thread-safe.
  UdpReceiverStats stats() const;

 private:
  UdpReceiver(int socket_fd, int wake_fd, UdpReceiverOptions options);

  int socket_fd_;
  int wake_fd_;  // eventfd that Stop() signals
  UdpReceiverOptions options_;
  std::uint16_t port_ = 0;
  int granted_buffer_bytes_ = 0;
  std::atomic<bool> stopped_{false};
  std::atomic<std::int64_t> datagrams_{0}, bytes_{0}, truncated_{0}, kernel_drops_{0}, timeouts_{0};
  std::unique_ptr<std::uint8_t[]> buffer_;
};

}  // namespace linecal

#pragma once
// LiDAR packets over loopback for daemon tests and the soak: a free port on 127.0.0.1, a
// recording's UDP payloads, and a thread that sends them to the port, looped, at a LiDAR's
// pace, optionally losing, cutting or ceasing to send packets as a faulty link or sensor does.

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "station/io/pcap.h"

namespace linecal::testing_daemon {

using Payload = std::vector<std::uint8_t>;

// The UDP payloads of a pcap file, in order. Errors: PcapReader's (the file named).
inline absl::StatusOr<std::vector<Payload>> PcapPayloads(const std::string& pcap) {
  std::vector<Payload> out;
  absl::StatusOr<PcapReader> r = PcapReader::Open(pcap);
  if (!r.ok()) return r.status();
  PcapRecord rec;
  for (;;) {
    absl::StatusOr<bool> more = r->Next(&rec);
    if (!more.ok()) return more.status();
    if (!*more) return out;
    const UdpFrame f = ParseUdpFrame(r->info().link_type, rec.data);
    out.emplace_back(f.payload.begin(), f.payload.end());
  }
}

// A port on 127.0.0.1 that was free a moment ago.
inline std::uint16_t FreeUdpPort() {
  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  bind(fd, reinterpret_cast<const sockaddr*>(&a), sizeof(a));
  socklen_t size = sizeof(a);
  getsockname(fd, reinterpret_cast<sockaddr*>(&a), &size);
  close(fd);
  return ntohs(a.sin_port);
}

// Whether a UDP socket is bound to 127.0.0.1:port, from /proc/net/udp (without touching the
// port, so the owner's bind never races with the question).
inline bool UdpPortBound(std::uint16_t port) {
  std::ifstream in("/proc/net/udp");
  char wanted[16];
  std::snprintf(wanted, sizeof(wanted), "0100007F:%04X", port);  // little-endian 127.0.0.1
  std::string line;
  while (std::getline(in, line)) {
    if (line.find(wanted) != std::string::npos) return true;
  }
  return false;
}

enum class SendStart { kNow, kWhenBound };

// What goes wrong on the way, for the soak's live faults: each packet lost with probability
// `lose`, else cut to a random shorter length with probability `cut`; after `stop_after`
// packets the sender falls silent (a sensor unplugged mid-scan). Drawn from `seed`, so a
// fault is reproduced by its seed.
struct SendFaults {
  double lose = 0.0;
  double cut = 0.0;
  std::optional<std::size_t> stop_after;
  std::uint64_t seed = 0;
};

// Sends the payloads to 127.0.0.1:port over and over until destroyed, about 7,000 a second
// (a Pandar64 sends 6,000): slow enough for any receive buffer. kWhenBound: only from when
// a socket is bound to the port, so the receiver gets the recording from its first packet.
class LoopingSender {
 public:
  LoopingSender(std::uint16_t port, std::vector<Payload> payloads,
                SendStart start = SendStart::kNow, SendFaults faults = {})
      : payloads_(std::move(payloads)),
        faults_(faults),
        thread_([this, port, start] { Run(port, start); }) {}
  ~LoopingSender() {
    stop_ = true;
    thread_.join();
  }
  LoopingSender(const LoopingSender&) = delete;
  LoopingSender& operator=(const LoopingSender&) = delete;

 private:
  void Run(std::uint16_t port, SendStart start) {
    while (start == SendStart::kWhenBound && !stop_ && !UdpPortBound(port)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    const int fd = socket(AF_INET, SOCK_DGRAM, 0);
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(port);
    to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    std::mt19937_64 rng(faults_.seed);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::size_t sent = 0;
    for (size_t i = 0; !stop_ && !payloads_.empty(); i = (i + 1) % payloads_.size()) {
      if (faults_.stop_after && sent >= *faults_.stop_after) break;
      ++sent;
      const Payload& p = payloads_[i];
      if (unit(rng) >= faults_.lose) {
        const std::size_t size =
            unit(rng) < faults_.cut ? static_cast<std::size_t>(unit(rng) * p.size()) : p.size();
        sendto(fd, p.data(), size, 0, reinterpret_cast<const sockaddr*>(&to), sizeof(to));
      }
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
    close(fd);
  }

  const std::vector<Payload> payloads_;
  const SendFaults faults_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace linecal::testing_daemon

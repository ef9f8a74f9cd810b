#pragma once
// LiDAR packets over loopback for daemon tests: a free port on 127.0.0.1, a recording's UDP
// payloads, and a thread that sends them to the port, looped, at a LiDAR's pace.

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "station/io/pcap.h"

namespace linecal::testing_daemon {

using Payload = std::vector<std::uint8_t>;

// The UDP payloads of a pcap file, in order.
inline std::vector<Payload> PcapPayloads(const std::string& pcap) {
  std::vector<Payload> out;
  absl::StatusOr<PcapReader> r = PcapReader::Open(pcap);
  EXPECT_TRUE(r.ok()) << r.status();
  PcapRecord rec;
  while (r.ok() && *r->Next(&rec)) {
    const UdpFrame f = ParseUdpFrame(r->info().link_type, rec.data);
    out.emplace_back(f.payload.begin(), f.payload.end());
  }
  return out;
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

// Sends the payloads to 127.0.0.1:port over and over until destroyed, about 7,000 a second
// (a Pandar64 sends 6,000): slow enough for any receive buffer. kWhenBound: only from when
// a socket is bound to the port, so the receiver gets the recording from its first packet.
class LoopingSender {
 public:
  LoopingSender(std::uint16_t port, std::vector<Payload> payloads,
                SendStart start = SendStart::kNow)
      : payloads_(std::move(payloads)), thread_([this, port, start] { Run(port, start); }) {}
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
    for (size_t i = 0; !stop_ && !payloads_.empty(); i = (i + 1) % payloads_.size()) {
      sendto(fd, payloads_[i].data(), payloads_[i].size(), 0,
             reinterpret_cast<const sockaddr*>(&to), sizeof(to));
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
    close(fd);
  }

  const std::vector<Payload> payloads_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace linecal::testing_daemon

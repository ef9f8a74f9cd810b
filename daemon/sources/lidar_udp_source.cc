#include "daemon/sources/lidar_udp_source.h"

#include <arpa/inet.h>

#include <filesystem>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "station/io/pcap.h"
#include "station/sensors/lidar/pcd.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

// How long one receive waits: the latency of noticing a cancel or the deadline.
constexpr std::chrono::milliseconds kPollInterval{50};

std::string CountersText(const LidarUdpCounters& c) {
  std::string skipped;
  for (int r = 0; r < kLidarSkipReasonCount; ++r) {
    if (c.decoder.skipped[r] == 0) continue;
    absl::StrAppend(&skipped, skipped.empty() ? "" : " ",
                    LidarSkipReasonName(static_cast<LidarSkipReason>(r)), "=",
                    c.decoder.skipped[r]);
  }
  return absl::StrCat("datagrams ", c.receiver.datagrams, ", decoded ", c.decoder.packets_decoded,
                      ", skipped ", c.decoder.skipped_total(),
                      skipped.empty() ? "" : absl::StrCat(" (", skipped, ")"), ", too long ",
                      c.receiver.truncated, ", kernel drops ", c.receiver.kernel_drops);
}

std::uint32_t Ipv4HostOrder(const std::string& literal) {
  in_addr a{};
  return inet_pton(AF_INET, literal.c_str(), &a) == 1 ? ntohl(a.s_addr) : 0;
}

// The error of an acquisition that ended with fewer than request.frames rotations, saying
// which of the three it was: no packets at all, packets none of which decodes as the sensor's
// model, or too few rotations in the time given (waited since `start`).
absl::Status ShortOfRotations(const SensorModel& sensor, size_t rotations,
                              const AcquireRequest& request, const std::string& from,
                              std::chrono::steady_clock::time_point start,
                              const LidarUdpCounters& c) {
  const std::string waited =
      absl::StrFormat("%.1f s", std::chrono::duration<double>(request.deadline - start).count());
  if (c.receiver.datagrams == 0 && c.receiver.truncated == 0) {
    return absl::DeadlineExceededError(
        absl::StrCat(sensor.name, ": no packets from ", from, " in ", waited));
  }
  if (c.decoder.packets_decoded == 0) {
    return absl::DataLossError(absl::StrCat(sensor.name, ": ", c.receiver.datagrams,
                                            " packets from ", from, ", none decodes as ",
                                            sensor.model, " (", CountersText(c), ")"));
  }
  return absl::DeadlineExceededError(absl::StrCat(sensor.name, ": ", rotations, " of ",
                                                  request.frames, " rotations from ", from, " in ",
                                                  waited, " (", CountersText(c), ")"));
}

}  // namespace

absl::Status LidarUdpSourceConfig::Validate() const {
  UdpReceiverOptions o;
  o.bind_address = bind_address;
  o.port = port;
  o.multicast_group = multicast_group;
  o.receive_buffer_bytes = receive_buffer_bytes;
  return o.Validate();
}

std::string LidarUdpSource::Describe() const {
  return absl::StrCat(
      "udp ", config_.bind_address, ":", config_.port,
      config_.multicast_group.empty() ? "" : absl::StrCat(" group ", config_.multicast_group));
}

LidarUdpCounters LidarUdpSource::last_counters() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return last_;
}

absl::StatusOr<CaptureSensor> LidarUdpSource::Acquire(const SensorModel& sensor,
                                                      const AcquireRequest& request) {
  if (sensor.kind != SensorKind::kLidar) {
    return absl::InvalidArgumentError(absl::StrCat(
        sensor.name, ": a UDP LiDAR source cannot serve a ", SensorKindName(sensor.kind)));
  }
  absl::StatusOr<LidarBeamTable> table = LidarBeamTableOf(sensor);
  if (!table.ok())
    return absl::InvalidArgumentError(absl::StrCat(sensor.name, ": ", table.status().message()));
  absl::StatusOr<LidarDecoder> decoder = LidarDecoder::Create(*std::move(table));
  if (!decoder.ok())
    return absl::InvalidArgumentError(absl::StrCat(sensor.name, ": ", decoder.status().message()));

  const auto start = std::chrono::steady_clock::now();
  const std::string from = absl::StrCat(config_.bind_address, ":", config_.port);
  UdpReceiverOptions options;
  options.bind_address = config_.bind_address;
  options.port = config_.port;
  options.multicast_group = config_.multicast_group;
  options.receive_buffer_bytes = config_.receive_buffer_bytes;
  options.receive_timeout = kPollInterval;
  absl::StatusOr<std::unique_ptr<UdpReceiver>> receiver = UdpReceiver::Open(options);
  if (!receiver.ok()) {
    return absl::Status(receiver.status().code(),
                        absl::StrCat(sensor.name, ": ", receiver.status().message()));
  }

  const fs::path dir = fs::path(request.capture_dir) / request.sensor_dir;
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec)
    return absl::InternalError(
        absl::StrCat(sensor.name, ": cannot create '", dir.string(), "': ", ec.message()));
  const std::string pcap_rel = (fs::path(request.sensor_dir) / "packets.pcap").string();
  absl::StatusOr<PcapWriter> pcap = PcapWriter::Create(fs::path(request.capture_dir) / pcap_rel);
  if (!pcap.ok()) return pcap.status();
  UdpEndpoints endpoints;
  endpoints.src_ip = 0;  // the receiver does not report the sender; 0.0.0.0 says "unknown"
  endpoints.src_port = 0;
  endpoints.dst_ip = Ipv4HostOrder(config_.multicast_group.empty() ? config_.bind_address
                                                                   : config_.multicast_group);
  endpoints.dst_port = (*receiver)->port();

  std::vector<LidarScan> scans;
  std::vector<LidarScan> completed;
  std::int64_t first_packet_ns = 0;
  absl::Status write_status;
  const UdpReceiver::Sink sink = [&](std::span<const std::uint8_t> payload, std::int64_t time_ns) {
    if (first_packet_ns == 0) first_packet_ns = time_ns;
    write_status.Update(pcap->WriteUdp(time_ns, endpoints, payload));
    decoder->AddPacket(payload, time_ns, &completed);
    for (LidarScan& scan : completed) {
      if (static_cast<int>(scans.size()) < request.frames) scans.push_back(std::move(scan));
    }
    completed.clear();
  };
  const auto counters = [&] {
    LidarUdpCounters c{(*receiver)->stats(), decoder->stats()};
    std::lock_guard<std::mutex> lock(mutex_);
    last_ = c;
    return c;
  };
  const auto progress = [&](const std::string& detail) {
    if (request.progress) request.progress(detail);
  };

  while (static_cast<int>(scans.size()) < request.frames) {
    if (request.cancelled()) {
      counters();
      return absl::CancelledError(absl::StrCat(sensor.name, ": cancelled after ", scans.size(),
                                               " of ", request.frames, " rotations"));
    }
    if (std::chrono::steady_clock::now() >= request.deadline) break;
    const size_t before = scans.size();
    const absl::Status received = (*receiver)->ReceiveOne(sink);
    if (!received.ok() && !absl::IsDeadlineExceeded(received)) {
      counters();
      return absl::InternalError(absl::StrCat(sensor.name, ": ", received.message()));
    }
    if (!write_status.ok()) return write_status;
    if (scans.size() > before) {
      progress(absl::StrCat("rotation ", scans.size(), "/", request.frames, ": ",
                            CountersText(counters())));
    }
  }
  const LidarUdpCounters c = counters();
  if (static_cast<int>(scans.size()) < request.frames) {
    return ShortOfRotations(sensor, scans.size(), request, from, start, c);
  }
  if (absl::Status s = pcap->Close(); !s.ok()) return s;

  CaptureSensor out;
  out.name = sensor.name;
  out.kind = SensorKind::kLidar;
  out.packets = CaptureFile{pcap_rel, first_packet_ns};
  for (size_t k = 0; k < scans.size(); ++k) {
    const std::string rel =
        (fs::path(request.sensor_dir) / absl::StrCat("scan_", k, ".pcd")).string();
    if (absl::Status s = WritePcd(fs::path(request.capture_dir) / rel, scans[k].points); !s.ok())
      return s;
    // A rotation without points has no time of its own (stamp 0): it takes its predecessor's,
    // so frame times stay non-decreasing as the capture format requires.
    const std::int64_t t = scans[k].stamp_ns != 0 ? scans[k].stamp_ns
                           : out.frames.empty()   ? first_packet_ns
                                                  : out.frames.back().t_ns;
    out.frames.push_back({rel, t});
  }
  progress(absl::StrCat(scans.size(), " rotations: ", CountersText(c)));
  return out;
}

}  // namespace linecal

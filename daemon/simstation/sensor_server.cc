#include "daemon/simstation/sensor_server.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <span>
#include <utility>

#include "absl/strings/str_cat.h"
#include "station/io/image_io.h"
#include "station/io/pcap.h"
#include "station/sensors/lidar/lidar_decoder.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// The longest a sender sleeps at once, so that the destructor's stop is seen promptly.
constexpr auto kSenderPoll = std::chrono::milliseconds(50);
// Frame retries written into the configuration of each fake camera's source (LiveSourceConfig).
constexpr int kFakeCameraFrameRetries = 10;

struct Datagram {
  std::int64_t offset_ns = 0;  // since the recording's first packet
  std::vector<std::uint8_t> payload;
};

// The UDP payloads of a pcap file with their times relative to the first; NotFound /
// InvalidArgument / DataLoss from the reader, InvalidArgument when it holds no UDP datagram.
absl::StatusOr<std::vector<Datagram>> ReadDatagrams(const std::string& path) {
  absl::StatusOr<PcapReader> reader = PcapReader::Open(path);
  if (!reader.ok()) return reader.status();
  std::vector<Datagram> out;
  std::int64_t t0 = 0;
  PcapRecord record;
  while (true) {
    absl::StatusOr<bool> more = reader->Next(&record);
    if (!more.ok()) return more.status();
    if (!*more) break;
    const UdpFrame frame = ParseUdpFrame(reader->info().link_type, record.data);
    if (frame.kind != FrameKind::kUdp || frame.payload_truncated) continue;
    if (out.empty()) t0 = record.time_ns;
    out.push_back({record.time_ns - t0, {frame.payload.begin(), frame.payload.end()}});
  }
  if (out.empty())
    return absl::InvalidArgumentError(absl::StrCat(path, ": no UDP datagram to replay"));
  return out;
}

// The datagrams of whole rotations only: from the packet that completed the first rotation to
// the one that completed the last. A recording that starts or ends mid-rotation, looped,
// would otherwise show a receiver a short rotation at every seam (the azimuth falls back
// there as it does when passing 0°). InvalidArgument when fewer than one whole rotation is in
// the recording.
absl::StatusOr<std::vector<Datagram>> WholeRotations(std::vector<Datagram> datagrams,
                                                     const SensorModel& sensor,
                                                     const std::string& name) {
  absl::StatusOr<LidarBeamTable> table = LidarBeamTableOf(sensor);
  if (!table.ok()) return table.status();
  absl::StatusOr<LidarDecoder> decoder = LidarDecoder::Create(*std::move(table));
  if (!decoder.ok()) return decoder.status();
  std::vector<std::size_t> ends;  // packets that completed a rotation
  std::vector<LidarScan> completed;
  for (std::size_t i = 0; i < datagrams.size(); ++i) {
    completed.clear();
    decoder->AddPacket(datagrams[i].payload, datagrams[i].offset_ns, &completed);
    if (!completed.empty()) ends.push_back(i);
  }
  if (ends.size() < 2) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": the recording holds no whole rotation to replay"));
  }
  std::vector<Datagram> whole(std::make_move_iterator(datagrams.begin() + ends.front()),
                              std::make_move_iterator(datagrams.begin() + ends.back()));
  const std::int64_t t0 = whole.front().offset_ns;
  for (Datagram& d : whole) d.offset_ns -= t0;
  return whole;
}

}  // namespace

absl::Status SensorServerOptions::Validate() const {
  if (capture_dir.empty()) return absl::InvalidArgumentError("capture_dir: empty");
  if (!(camera_lost_ratio >= 0 && camera_lost_ratio < 1)) {
    return absl::InvalidArgumentError(
        absl::StrCat("camera_lost_ratio = ", camera_lost_ratio, ": must be in [0, 1)"));
  }
  in_addr a{};
  if (inet_pton(AF_INET, lidar_address.c_str(), &a) != 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("lidar_address '", lidar_address, "': not an IPv4 address"));
  }
  for (const std::string& c : camera_addresses) {
    if (inet_pton(AF_INET, c.c_str(), &a) != 1) {
      return absl::InvalidArgumentError(
          absl::StrCat("camera_addresses: '", c, "' is not an IPv4 address"));
    }
  }
  if (!(lidar_speed >= 0))
    return absl::InvalidArgumentError(
        absl::StrCat("lidar_speed = ", lidar_speed, ": must be >= 0"));
  if (lidar_first_port == 0)
    return absl::InvalidArgumentError("lidar_first_port: must be a port, not 0");
  return absl::OkStatus();
}

SensorServer::SensorServer(SensorServerOptions options, Capture capture)
    : options_(std::move(options)), capture_(std::move(capture)) {}

absl::StatusOr<std::unique_ptr<SensorServer>> SensorServer::Start(
    const SensorServerOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  absl::StatusOr<Capture> capture = ReadCapture(options.capture_dir);
  if (!capture.ok()) return capture.status();
  const auto cameras =
      std::count_if(capture->manifest.sensors.begin(), capture->manifest.sensors.end(),
                    [](const CaptureSensor& s) { return s.kind == SensorKind::kCamera; });
  if (static_cast<std::size_t>(cameras) > options.camera_addresses.size()) {
    return absl::InvalidArgumentError(
        absl::StrCat("camera_addresses: ", options.camera_addresses.size(),
                     " given for the capture's ", cameras, " cameras (one address each)"));
  }
  std::unique_ptr<SensorServer> server(new SensorServer(options, *std::move(capture)));
  std::size_t next_address = 0;
  std::uint16_t next_port = options.lidar_first_port;
  for (const CaptureSensor& sensor : server->capture_.manifest.sensors) {
    if (sensor.kind == SensorKind::kCamera) {
      if (sensor.frames.empty())
        return absl::InvalidArgumentError(absl::StrCat(sensor.name, ": no frame to serve"));
      absl::StatusOr<Image8> image = ReadCaptureImage(server->capture_, sensor.frames.front());
      if (!image.ok()) return image.status();
      const std::string& address = options.camera_addresses[next_address++];
      // The serial becomes the device id "Aravis-Fake-<serial>": the sensor name makes it
      // readable in linecald's status and logs.
      absl::StatusOr<std::unique_ptr<FakeGigeCamera>> camera = FakeGigeCamera::Start(
          address, sensor.name, *std::move(image), options.camera_lost_ratio, options.camera_fps);
      if (!camera.ok()) return camera.status();
      server->cameras_.emplace_back(sensor.name, *std::move(camera));
    } else if (sensor.kind == SensorKind::kLidar) {
      if (!sensor.packets)
        return absl::InvalidArgumentError(absl::StrCat(sensor.name, ": no packets to replay"));
      if (absl::Status s = server->StartLidar(sensor, next_port); !s.ok()) return s;
      ++next_port;
    }
  }
  return server;
}

absl::Status SensorServer::StartLidar(const CaptureSensor& sensor, std::uint16_t port) {
  absl::StatusOr<std::vector<Datagram>> datagrams = ReadDatagrams(capture_.PathOf(*sensor.packets));
  if (!datagrams.ok()) return datagrams.status();
  const SensorModel* model = capture_.car.FindSensor(sensor.name);
  if (model == nullptr)
    return absl::InvalidArgumentError(
        absl::StrCat(sensor.name, ": not in the capture's car model"));
  datagrams = WholeRotations(*std::move(datagrams), *model, sensor.name);
  if (!datagrams.ok()) return datagrams.status();
  const int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return absl::InternalError(absl::StrCat("socket(): ", strerror(errno)));
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(port);
  inet_pton(AF_INET, options_.lidar_address.c_str(), &to.sin_addr);
  lidar_ports_.emplace_back(sensor.name, port);
  // One loop of the recording lasts its span plus one mean packet interval, so that the
  // next loop's first packet keeps the recorded rate.
  const std::vector<Datagram>& d = *datagrams;
  const std::int64_t span_ns =
      d.back().offset_ns +
      (d.size() > 1 ? d.back().offset_ns / static_cast<std::int64_t>(d.size() - 1) : 0);
  senders_.emplace_back([this, fd, to, d = *std::move(datagrams), span_ns] {
    const Clock::time_point start = Clock::now();
    for (std::int64_t loop = 0; !stop_; ++loop) {
      for (const Datagram& g : d) {
        if (options_.lidar_speed > 0) {
          const auto due =
              start +
              std::chrono::nanoseconds(static_cast<std::int64_t>(
                  static_cast<double>(loop * span_ns + g.offset_ns) / options_.lidar_speed));
          while (!stop_ && Clock::now() < due)
            std::this_thread::sleep_until(std::min(due, Clock::now() + kSenderPoll));
        }
        if (stop_) break;
        // Nobody listening is normal (linecald listens only while it acquires): the datagram
        // is dropped by the kernel, as a real LiDAR's would be.
        if (sendto(fd, g.payload.data(), g.payload.size(), 0,
                   reinterpret_cast<const sockaddr*>(&to), sizeof to) >= 0) {
          datagrams_sent_.fetch_add(1);
        }
      }
    }
    close(fd);
  });
  return absl::OkStatus();
}

SensorServer::~SensorServer() {
  stop_ = true;
  for (std::thread& t : senders_) t.join();
}

nlohmann::json SensorServer::LiveSourceConfig() const {
  nlohmann::json sensors = nlohmann::json::object();
  for (const auto& [name, camera] : cameras_) {
    // Retries: on loopback the first frame after the stream starts arrives incomplete (the
    // fake camera sends it in one burst before Aravis sizes the socket buffer, docs/sensors.md)
    // and a loaded machine loses a few more; a real camera's default of 3 stays for real ones.
    sensors[name] = {{"type", "aravis"},
                     {"device_id", camera->device_id()},
                     {"pixel_format", "Mono8"},
                     {"frame_retries", kFakeCameraFrameRetries}};
  }
  for (const auto& [name, port] : lidar_ports_) {
    sensors[name] = {{"type", "udp"}, {"bind", options_.lidar_address}, {"port", port}};
  }
  for (const CaptureSensor& s : capture_.manifest.sensors) {
    if (s.kind == SensorKind::kRadar && s.can_log) {
      sensors[s.name] = {
          {"type", "candump"},
          {"log", fs::absolute(capture_.PathOf(*s.can_log)).lexically_normal().string()}};
    }
  }
  return {{"type", "live"}, {"sensors", sensors}};
}

}  // namespace linecal

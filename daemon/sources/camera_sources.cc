#include "daemon/sources/camera_sources.h"

#include <filesystem>
#include <functional>
#include <system_error>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "daemon/drivers/aravis_camera.h"
#include "daemon/drivers/camera_frame.h"
#include "daemon/drivers/v4l2_camera.h"
#include "station/io/image_io.h"

namespace linecal {
namespace {

absl::Status ValidateCommon(std::chrono::milliseconds frame_timeout, int frame_retries) {
  if (frame_timeout.count() <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("frame_timeout: must be > 0 ms, got ", frame_timeout.count()));
  }
  if (frame_retries < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("frame_retries: must be >= 0, got ", frame_retries));
  }
  return absl::OkStatus();
}

// What both camera sources check before opening their device.
absl::Status CheckRequest(const SensorModel& sensor, const AcquireRequest& request,
                          const std::string& source) {
  if (sensor.kind != SensorKind::kCamera) {
    return absl::InvalidArgumentError(absl::StrCat("sensor '", sensor.name, "' is a ",
                                                   SensorKindName(sensor.kind), "; ", source,
                                                   " serves cameras only"));
  }
  if (request.frames < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("frames: must be >= 1 for camera '", sensor.name, "', got ", request.frames));
  }
  if (request.cancelled()) {
    return absl::CancelledError(absl::StrCat(source, ": cancelled"));
  }
  return absl::OkStatus();
}

using GrabFn = std::function<absl::StatusOr<CameraFrame>(
    std::chrono::steady_clock::time_point deadline, const std::atomic<bool>* cancel)>;

// Grabs request.frames frames and writes each as <sensor_dir>/frame_<k>.png.
absl::StatusOr<CaptureSensor> RecordFrames(const SensorModel& sensor, const AcquireRequest& request,
                                           const GrabFn& grab) {
  const std::filesystem::path dir = std::filesystem::path(request.capture_dir) / request.sensor_dir;
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    return absl::InternalError(absl::StrCat(dir.string(), ": cannot create: ", ec.message()));
  }
  CaptureSensor out;
  out.name = sensor.name;
  out.kind = SensorKind::kCamera;
  for (int k = 0; k < request.frames; ++k) {
    absl::StatusOr<CameraFrame> frame = grab(request.deadline, request.cancel);
    if (!frame.ok()) {
      return absl::Status(frame.status().code(), absl::StrCat(frame.status().message(), " (frame ",
                                                              k + 1, "/", request.frames, ")"));
    }
    const std::string name = absl::StrCat("frame_", k, ".png");
    const std::string relative = (std::filesystem::path(request.sensor_dir) / name).string();
    if (absl::Status s = WritePng8((dir / name).string(), frame->image.view()); !s.ok()) return s;
    out.frames.push_back({relative, frame->t_ns});
    if (request.progress) {
      request.progress(absl::StrCat("frame ", k + 1, "/", request.frames));
    }
  }
  return out;
}

class AravisCameraSource : public SensorSource {
 public:
  explicit AravisCameraSource(AravisCameraSourceConfig config) : config_(std::move(config)) {}
  ~AravisCameraSource() override { JoinReleaser(); }

  absl::StatusOr<CaptureSensor> Acquire(const SensorModel& sensor,
                                        const AcquireRequest& request) override {
    JoinReleaser();  // the camera of the last cycle must let go before it is opened again
    if (absl::Status s = config_.Validate(); !s.ok()) return s;
    if (absl::Status s = CheckRequest(sensor, request, Describe()); !s.ok()) return s;
    AravisCameraOptions options;
    options.device_id = config_.device_id;
    options.pixel_format = config_.pixel_format;
    options.exposure_us = config_.exposure_us;
    options.frame_timeout = config_.frame_timeout;
    options.frame_retries = config_.frame_retries;
    // Sources of several cameras acquire at once (docs/sensors.md, "Several cameras at once").
    absl::StatusOr<std::unique_ptr<AravisCamera>> camera = AravisCamera::Open(options);
    if (!camera.ok()) return camera.status();
    absl::StatusOr<CaptureSensor> result =
        RecordFrames(sensor, request,
                     [&](auto deadline, auto cancel) { return (*camera)->Grab(deadline, cancel); });
    if (result.status().code() == absl::StatusCode::kDeadlineExceeded) {
      // The camera may have vanished, and releasing it then waits seconds for control
      // requests nobody answers (AravisCamera's destructor): not on the cycle's time.
      releaser_ = std::thread([vanished = *std::move(camera)]() mutable { vanished.reset(); });
    }
    return result;
  }

  std::string Describe() const override { return "aravis " + config_.device_id; }

 private:
  void JoinReleaser() {
    if (releaser_.joinable()) releaser_.join();
  }

  AravisCameraSourceConfig config_;
  std::thread releaser_;  // releasing the camera of a cycle that ended by a deadline
};

class V4l2CameraSource : public SensorSource {
 public:
  explicit V4l2CameraSource(V4l2CameraSourceConfig config) : config_(std::move(config)) {}

  absl::StatusOr<CaptureSensor> Acquire(const SensorModel& sensor,
                                        const AcquireRequest& request) override {
    if (absl::Status s = config_.Validate(); !s.ok()) return s;
    if (absl::Status s = CheckRequest(sensor, request, Describe()); !s.ok()) return s;
    V4l2CameraOptions options;
    options.device = config_.device;
    options.pixel_format = config_.pixel_format;
    options.width = config_.width;
    options.height = config_.height;
    options.frame_timeout = config_.frame_timeout;
    options.frame_retries = config_.frame_retries;
    absl::StatusOr<std::unique_ptr<V4l2Camera>> camera = V4l2Camera::Open(options);
    if (!camera.ok()) return camera.status();
    return RecordFrames(sensor, request, [&](auto deadline, auto cancel) {
      return (*camera)->Grab(deadline, cancel);
    });
  }

  std::string Describe() const override { return "v4l2 " + config_.device; }

 private:
  V4l2CameraSourceConfig config_;
};

}  // namespace

absl::Status AravisCameraSourceConfig::Validate() const {
  if (device_id.empty()) return absl::InvalidArgumentError("device_id: empty");
  if (pixel_format.empty()) return absl::InvalidArgumentError("pixel_format: empty");
  if (!(exposure_us >= 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("exposure_us: must be >= 0 (0 leaves the camera's), got ", exposure_us));
  }
  return ValidateCommon(frame_timeout, frame_retries);
}

absl::Status V4l2CameraSourceConfig::Validate() const {
  if (device.empty()) return absl::InvalidArgumentError("device: empty");
  if (absl::StatusOr<std::uint32_t> f = V4l2PixelFormat(pixel_format); !f.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("pixel_format: ", f.status().message()));
  }
  if (width < 0 || height < 0 || width > kMaxImageSide || height > kMaxImageSide ||
      (width == 0) != (height == 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("width, height: both 0 (the device's size) or both 1..", kMaxImageSide,
                     ", got ", width, " x ", height));
  }
  return ValidateCommon(frame_timeout, frame_retries);
}

std::unique_ptr<SensorSource> MakeAravisCameraSource(const AravisCameraSourceConfig& config) {
  return std::make_unique<AravisCameraSource>(config);
}

std::unique_ptr<SensorSource> MakeV4l2CameraSource(const V4l2CameraSourceConfig& config) {
  return std::make_unique<V4l2CameraSource>(config);
}

}  // namespace linecal

#pragma once
// Camera sources (sensor_source.h): GigE Vision cameras through Aravis, and V4L2 cameras.
// Both write each frame as an 8-bit grey PNG, `<sensor_dir>/frame_<k>.png`, with the time the
// frame arrived; colour and Bayer formats are converted to grey, as the detectors need.

#include <chrono>
#include <memory>
#include <string>

#include "absl/status/status.h"
#include "daemon/sources/sensor_source.h"

namespace linecal {

struct AravisCameraSourceConfig {
  std::string
      device_id;  // Aravis device id ("Basler-21234567", "Aravis-Fake-TEST01") or IP address
  std::string pixel_format = "Mono8";  // GenICam PixelFormat name the camera is set to
  double exposure_us = 0;              // 0: leave the camera's exposure as it is
  // How long one frame may take to arrive before it counts as missing.
  std::chrono::milliseconds frame_timeout{2000};
  // Incomplete or missing frames grabbed again, per frame, before the sensor is given up
  // (DataLoss naming the buffer status).
  int frame_retries = 3;

  // InvalidArgument naming the field ("device_id: empty").
  absl::Status Validate() const;
};

struct V4l2CameraSourceConfig {
  std::string device = "/dev/video0";
  std::string pixel_format = "GREY";  // V4L2 fourcc: GREY, YUYV
  int width = 0;                      // 0: the device's current format
  int height = 0;
  std::chrono::milliseconds frame_timeout{2000};
  int frame_retries = 3;

  absl::Status Validate() const;
};

// The sources; the device is opened at each Acquire (a camera that was unplugged and
// plugged back works on the next cycle), so constructing one does no I/O. Acquire opens the
// camera (Aravis discovery: up to about 1 s for an absent camera), grabs request.frames
// frames (progress "frame k/n" after each is written) and returns CaptureSensor::frames.
// An Aravis camera whose Acquire ended DeadlineExceeded may have vanished, and releasing it
// then takes seconds of unanswered control requests: that happens on a thread of the source,
// which the next Acquire and the destructor wait for.
std::unique_ptr<SensorSource> MakeAravisCameraSource(const AravisCameraSourceConfig& config);
std::unique_ptr<SensorSource> MakeV4l2CameraSource(const V4l2CameraSourceConfig& config);

}  // namespace linecal

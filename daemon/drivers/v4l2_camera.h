#pragma once
// Capturing frames from a V4L2 camera (docs/sensors.md "V4L2"): memory-mapped streaming, frames
// converted to 8-bit grey.
//
// Opening tells apart what an installer meets, all Unavailable with the device path:
//   "no such device"                 stat() ENOENT
//   "not a character device"         a regular file, a directory, ...
//   "permission denied (... group video)"  open() EACCES
//   "not a V4L2 device"              VIDIOC_QUERYCAP fails with ENOTTY or EINVAL
//   "cannot capture video" / "cannot stream"  the capabilities lack VIDEO_CAPTURE / STREAMING
// InvalidArgument when the device does not take the pixel format or gives a frame larger
// than kMaxImageSide; Internal for other system-call failures (call and strerror).
// Grabbing: DeadlineExceeded (no frame within frame_timeout, or the caller's deadline),
// DataLoss (frame_retries + 1 frames in a row flagged V4L2_BUF_FLAG_ERROR or short),
// Cancelled. Every ioctl is retried on EINTR.

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "daemon/drivers/camera_frame.h"
#include "detectors/core/image_view.h"

namespace linecal {

struct V4l2CameraOptions {
  std::string device = "/dev/video0";
  std::string pixel_format = "GREY";  // V4L2 fourcc: GREY or YUYV
  int width = 0;                      // 0 (with height 0): keep the device's current size
  int height = 0;
  std::chrono::milliseconds frame_timeout{2000};
  int frame_retries = 3;
};

// The fourcc of a four-character name ("GREY" -> V4L2_PIX_FMT_GREY); InvalidArgument unless
// it is GREY or YUYV, the formats V4l2FrameToGrey converts.
absl::StatusOr<std::uint32_t> V4l2PixelFormat(const std::string& name);

// Converts one frame to grey: GREY as is, YUYV (Y0 U Y1 V) by its Y samples. `bytes_per_line`
// is the row stride (>= width for GREY, >= 2 * width for YUYV). InvalidArgument for another
// format, a size outside 1..kMaxImageSide, a too small stride, or fewer bytes than
// (height - 1) * bytes_per_line + one row. Cost: one pass over the pixels.
absl::StatusOr<Image8> V4l2FrameToGrey(std::uint32_t fourcc, const std::uint8_t* data,
                                       std::size_t size, int width, int height,
                                       std::size_t bytes_per_line);

class V4l2Camera {
 public:
  // Opens the device, sets the format, maps kBuffers buffers and starts streaming. Errors as
  // at the top of this file. Owns the descriptor and the mappings.
  static absl::StatusOr<std::unique_ptr<V4l2Camera>> Open(const V4l2CameraOptions& options);

  ~V4l2Camera();  // stops streaming, unmaps, closes
  V4l2Camera(const V4l2Camera&) = delete;
  V4l2Camera& operator=(const V4l2Camera&) = delete;

  // The next complete frame; returns by `deadline` plus at most kPollInterval, and within
  // kPollInterval of `cancel` turning true.
  absl::StatusOr<CameraFrame> Grab(std::chrono::steady_clock::time_point deadline,
                                   const std::atomic<bool>* cancel);

  static constexpr int kBuffers = 4;  // enough to keep the driver filling while one is converted
  static constexpr std::chrono::milliseconds kPollInterval{50};  // bounds cancel latency

 private:
  struct Mapping {
    void* start = nullptr;
    std::size_t length = 0;
  };
  explicit V4l2Camera(V4l2CameraOptions options) : options_(std::move(options)) {}

  V4l2CameraOptions options_;
  int fd_ = -1;
  bool streaming_ = false;
  std::vector<Mapping> mappings_;
  std::uint32_t fourcc_ = 0;
  int width_ = 0;
  int height_ = 0;
  std::size_t bytes_per_line_ = 0;
  std::size_t frame_bytes_ = 0;  // sizeimage: what a complete frame fills
};

}  // namespace linecal

#pragma once
// Grabbing frames from a GigE Vision (or USB3 Vision) camera through Aravis 0.8
// (docs/sensors.md "GigE Vision cameras"), converted to 8-bit grey for the detectors.
//
// Errors, each naming the camera:
//   Unavailable       "camera 'X' not found" (no camera answers to the id), or the camera
//                     refused the connection (another controller holds it)
//   InvalidArgument   the camera does not know the pixel format, or delivers one this driver
//                     cannot convert, or a frame larger than kMaxImageSide
//   DeadlineExceeded  no frame within frame_timeout (a silent or vanished camera), or the
//                     caller's deadline passed
//   DataLoss          frame_retries + 1 frames in a row arrived incomplete ("MISSING_PACKETS")
//   Cancelled         the caller's cancel flag was set
//   Internal          another Aravis failure, with its message
// Aravis's own diagnostics stay quiet: buffer fields are read only from complete buffers.

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "daemon/drivers/camera_frame.h"
#include "detectors/core/image_view.h"

struct _ArvCamera;
struct _ArvStream;

namespace linecal {

struct AravisCameraOptions {
  // Aravis device id ("Basler-21234567", "Aravis-Fake-TEST01") or the camera's IP address.
  std::string device_id;
  std::string pixel_format = "Mono8";  // GenICam PixelFormat the camera is set to
  double exposure_us = 0;              // > 0: set ExposureTime; 0: leave it
  std::chrono::milliseconds frame_timeout{2000};
  int frame_retries = 3;
};

class AravisCamera {
 public:
  // Opens the camera, sets pixel format and exposure, creates the stream with its buffers
  // and starts acquisition (continuous). Blocks for Aravis's discovery, up to about 1 s when
  // the camera does not answer. Errors as at the top of this file. Owns the camera.
  static absl::StatusOr<std::unique_ptr<AravisCamera>> Open(const AravisCameraOptions& options);

  // Stops acquisition and releases stream, buffers and camera. Blocks for the control
  // requests this takes: milliseconds for a camera that answers; for one that vanished each
  // request waits out Aravis's GVCP retries (6 x 500 ms, not configurable in 0.8), about
  // 7.5 s measured when a Grab ended by frame_timeout (acquisition is then not stopped) and
  // 11.5 s otherwise.
  ~AravisCamera();
  AravisCamera(const AravisCamera&) = delete;
  AravisCamera& operator=(const AravisCamera&) = delete;

  // The next complete frame. Incomplete frames are dropped and waited for again, up to
  // frame_retries times, then DataLoss naming the last buffer status. Returns by `deadline`
  // (plus one poll interval, kPollInterval) and within kPollInterval of `cancel` turning true.
  // Cost: one copy/conversion of the frame.
  absl::StatusOr<CameraFrame> Grab(std::chrono::steady_clock::time_point deadline,
                                   const std::atomic<bool>* cancel);

  // Incomplete frames dropped since Open.
  int incomplete_frames() const { return incomplete_frames_; }
  const std::string& device_id() const { return options_.device_id; }

  // How long one wait for a buffer blocks at most: short enough for a prompt cancel, long
  // enough not to spin.
  static constexpr std::chrono::milliseconds kPollInterval{50};

 private:
  AravisCamera(AravisCameraOptions options, _ArvCamera* camera);

  AravisCameraOptions options_;
  _ArvCamera* camera_ = nullptr;  // owned
  _ArvStream* stream_ = nullptr;  // owned; owns the buffers pushed to it
  bool acquiring_ = false;
  bool silent_ = false;  // a Grab saw no frame for frame_timeout
  int incomplete_frames_ = 0;
};

// GenICam PFNC pixel format codes this driver converts (the values of ArvPixelFormat).
inline constexpr std::uint32_t kPfncMono8 = 0x01080001;
inline constexpr std::uint32_t kPfncMono16 = 0x01100007;
inline constexpr std::uint32_t kPfncRgb8 = 0x02180014;
inline constexpr std::uint32_t kPfncBgr8 = 0x02180015;
inline constexpr std::uint32_t kPfncBayerGr8 = 0x01080008;
inline constexpr std::uint32_t kPfncBayerRg8 = 0x01080009;
inline constexpr std::uint32_t kPfncBayerGb8 = 0x0108000A;
inline constexpr std::uint32_t kPfncBayerBg8 = 0x0108000B;

// Converts one frame's bytes to 8-bit grey: Mono8 as is, Mono16 (little-endian, as GigE
// Vision sends it) rounded to v / 257, RGB8/BGR8 with the BT.601 luma weights of
// station/io/image_io.h, Bayer 8-bit (GR, RG, GB, BG: the colours of the top-left 2 x 2)
// demosaiced bilinearly (each missing colour the mean of its nearest samples in the 3 x 3
// neighbourhood, mirrored at the border, so the grey image stays centred on the pixel grid)
// and then the same luma. Rows are packed (no padding). InvalidArgument for an unsupported
// format, a size above kMaxImageSide or non-positive, or fewer than the frame's bytes.
// Cost: one pass over the pixels.
absl::StatusOr<Image8> GigeFrameToGrey(std::uint32_t pixel_format, const std::uint8_t* data,
                                       std::size_t size, int width, int height);

}  // namespace linecal

#pragma once
// Aravis's in-process fake GigE Vision camera, serving an image the owner chooses over the
// real GigE Vision path (GVCP control, GVSP stream on UDP). For tests and the demo's sensor
// server: a client opens it as `device_id()` (or by `address`) like any GigE camera.
//
// The camera answers on `address`:3956. Only one fake camera can listen per IP address (Start
// checks that the port is free): 127.0.0.1 always exists; 127.0.0.2 and up need
// `ip addr add 127.0.0.N/8 dev lo` (root) first. Tests that start one serialise on the CTest
// resource lock `gige_loopback`.
//
// Frames are Mono8, the served image's size, at the fake camera's default 25 frames/s. The
// pixels are written by Aravis's fake camera thread (the fill-pattern callback); SetImage
// may be called from any thread at any time.

#include <memory>
#include <mutex>
#include <string>

#include "absl/status/statusor.h"
#include "detectors/core/image_view.h"

struct _ArvBuffer;
struct _ArvGvFakeCamera;

namespace linecal {

class FakeGigeCamera {
 public:
  // Starts a fake camera on the IPv4 `address` with the serial number `serial` (1..15
  // characters, Aravis's limit), serving `initial`, and dropping each stream packet with
  // probability `lost_ratio` (0..1; the fake camera never resends, so a frame that lost a
  // packet arrives as incomplete), at `frames_per_second` (0.1..100; Aravis's default is 25:
  // several full-HD fake cameras at that rate overrun loopback's default socket buffers on a
  // small machine).
  // Errors: InvalidArgument (empty or too large image, serial length, ratio outside 0..1, rate,
  // not an IPv4 address), Unavailable "cannot listen on ADDRESS:3956: ..." (no local
  // interface has the address, or another camera or program holds the port). Cost: binds
  // a few UDP sockets and starts a thread.
  static absl::StatusOr<std::unique_ptr<FakeGigeCamera>> Start(const std::string& address,
                                                               const std::string& serial,
                                                               Image8 initial,
                                                               double lost_ratio = 0.0,
                                                               double frames_per_second = 25.0);

  // Stops the camera thread and closes its sockets: a client streaming from it stops
  // receiving frames and its control requests go unanswered.
  ~FakeGigeCamera();
  FakeGigeCamera(const FakeGigeCamera&) = delete;
  FakeGigeCamera& operator=(const FakeGigeCamera&) = delete;

  // Serves `image` from the next frame on. The camera's Width/Height registers follow the
  // image; a client reads them when it starts acquiring, so a new size reaches clients that
  // (re)open the camera, and frames of an acquisition already running when the size changed
  // arrive black. InvalidArgument for an empty image or one wider or taller than
  // kMaxImageSide.
  absl::Status SetImage(Image8 image);

  // "Aravis-Fake-<serial>", the id Aravis discovers it under.
  std::string device_id() const { return "Aravis-Fake-" + serial_; }
  const std::string& address() const { return address_; }

 private:
  FakeGigeCamera(std::string address, std::string serial);
  // Aravis's ArvFakeCameraFillPattern (guint32 is unsigned int); `self` is the camera.
  static void Fill(_ArvBuffer* buffer, void* self, unsigned exposure_us, unsigned gain,
                   unsigned pixel_format);

  std::string address_;
  std::string serial_;
  _ArvGvFakeCamera* camera_ = nullptr;  // owned (one GObject reference)
  std::mutex mutex_;                    // guards image_
  Image8 image_;
};

}  // namespace linecal

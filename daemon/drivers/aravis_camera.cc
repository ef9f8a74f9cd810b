#include "daemon/drivers/aravis_camera.h"

#include <arpa/inet.h>
#include <arv.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <mutex>
#include <utility>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

// GigE Vision's control port (GVCP, UDP); only used to ask the kernel for a route.
constexpr std::uint16_t kGvcpPort = 3956;

// Buffers queued on the stream: the stream fills one while the driver converts another, and
// a slow conversion does not make the camera's frames miss a buffer.
constexpr int kStreamBuffers = 4;

// The stream's UDP receive buffer holds a whole frame (the kernel doubles SO_RCVBUF for its
// bookkeeping, which covers the per-datagram overhead), so a stream thread that is not
// scheduled for a while loses no packets; at least 1 MiB, since Aravis 0.8's own "auto" size
// (the payload) is too small for small frames: a 64 x 48 frame's three datagrams did not fit.
// The kernel caps it at net.core.rmem_max.
constexpr guint kMinStreamSocketBuffer = 1u << 20;

// Owns a GError.
struct ErrorHolder {
  GError* error = nullptr;
  ~ErrorHolder() { g_clear_error(&error); }
  GError** out() {
    g_clear_error(&error);
    return &error;
  }
  std::string message() const { return error != nullptr ? error->message : "unknown error"; }
};

const char* BufferStatusName(ArvBufferStatus status) {
  switch (status) {
    case ARV_BUFFER_STATUS_SUCCESS:
      return "SUCCESS";
    case ARV_BUFFER_STATUS_CLEARED:
      return "CLEARED";
    case ARV_BUFFER_STATUS_TIMEOUT:
      return "TIMEOUT";
    case ARV_BUFFER_STATUS_MISSING_PACKETS:
      return "MISSING_PACKETS";
    case ARV_BUFFER_STATUS_WRONG_PACKET_ID:
      return "WRONG_PACKET_ID";
    case ARV_BUFFER_STATUS_SIZE_MISMATCH:
      return "SIZE_MISMATCH";
    case ARV_BUFFER_STATUS_FILLING:
      return "FILLING";
    case ARV_BUFFER_STATUS_ABORTED:
      return "ABORTED";
    default:
      return "UNKNOWN";
  }
}

std::int64_t UnixNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// The local IPv4 address the kernel sends from to reach `device` (connect() on a UDP socket
// sends nothing). Empty when there is no route.
std::string LocalAddressTowards(GInetAddress* device) {
  if (g_inet_address_get_family(device) != G_SOCKET_FAMILY_IPV4) return {};
  sockaddr_in remote{};
  remote.sin_family = AF_INET;
  remote.sin_port = htons(kGvcpPort);
  std::memcpy(&remote.sin_addr, g_inet_address_to_bytes(device), sizeof remote.sin_addr);
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return {};
  sockaddr_in local{};
  socklen_t local_size = sizeof local;
  std::string result;
  if (::connect(fd, reinterpret_cast<const sockaddr*>(&remote), sizeof remote) == 0 &&
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&local), &local_size) == 0) {
    char text[INET_ADDRSTRLEN] = "";
    if (::inet_ntop(AF_INET, &local.sin_addr, text, sizeof text) != nullptr) result = text;
  }
  ::close(fd);
  return result;
}

std::string InetToString(GSocketAddress* address) {
  GInetAddress* inet = g_inet_socket_address_get_address(G_INET_SOCKET_ADDRESS(address));
  gchar* text = g_inet_address_to_string(inet);
  std::string result = text;
  g_free(text);
  return result;
}

// Opens the device. Discovery by id takes the first answer; a camera that listens on
// 255.255.255.255 (Aravis's fake camera, on loopback) also answers broadcasts sent from other
// interfaces, and the stream then goes to that interface's address, where the camera's
// packets never arrive. So a GigE device found through an interface other than the one the
// kernel routes to it through is opened again on the routed one.
absl::StatusOr<ArvDevice*> OpenDevice(const std::string& id) {
  ErrorHolder error;
  ArvDevice* device = arv_open_device(id.c_str(), error.out());
  if (device == nullptr) {
    if (error.error != nullptr && error.error->domain == ARV_DEVICE_ERROR &&
        error.error->code == ARV_DEVICE_ERROR_NOT_FOUND) {
      return absl::UnavailableError(absl::StrCat("camera '", id, "' not found"));
    }
    return absl::UnavailableError(absl::StrCat("camera '", id, "': ", error.message()));
  }
  if (!ARV_IS_GV_DEVICE(device)) return device;
  ArvGvDevice* gv = ARV_GV_DEVICE(device);
  GSocketAddress* device_address = arv_gv_device_get_device_address(gv);
  GSocketAddress* interface_address = arv_gv_device_get_interface_address(gv);
  GInetAddress* device_inet =
      g_inet_socket_address_get_address(G_INET_SOCKET_ADDRESS(device_address));
  const std::string routed = LocalAddressTowards(device_inet);
  if (routed.empty() || routed == InetToString(interface_address)) return device;

  g_object_ref(device_inet);
  g_object_unref(device);  // releases control of the camera before taking it again
  GInetAddress* routed_inet = g_inet_address_new_from_string(routed.c_str());
  ArvDevice* reopened = arv_gv_device_new(routed_inet, device_inet, error.out());
  g_object_unref(routed_inet);
  g_object_unref(device_inet);
  if (reopened == nullptr) {
    return absl::UnavailableError(absl::StrCat("camera '", id, "': ", error.message()));
  }
  return reopened;
}

// Aravis 0.8 creates a device with process-wide state and no lock around it: its GenICam
// parser keeps the document being built in one static variable (arvdomparser.c,
// _parse_memory), so two devices created at once on two threads build their feature nodes
// into each other's document: opens fail ("Port not found for node", "[AcquisitionStart] Not
// ..."), the process crashes, or a camera reads and writes another camera's registers
// (docs/sensors.md, "Several cameras at once"). Every device creation in the process holds
// this lock; configuring, streaming and grabbing touch only the camera's own objects and run
// in parallel.
std::mutex& DeviceCreationMutex() {
  static std::mutex mutex;
  return mutex;
}

// Opens the device (OpenDevice) and wraps it in an ArvCamera: the only steps of Open that
// create Aravis devices, under DeviceCreationMutex. About 10 ms per fake camera on loopback
// (two creations when OpenDevice opens it again on the routed interface). Unavailable as
// OpenDevice gives it, or when Aravis cannot make a camera of the device.
absl::StatusOr<ArvCamera*> CreateCamera(const std::string& id) {
  std::lock_guard<std::mutex> lock(DeviceCreationMutex());
  absl::StatusOr<ArvDevice*> device = OpenDevice(id);
  if (!device.ok()) return device.status();
  ErrorHolder error;
  ArvCamera* camera = arv_camera_new_with_device(*device, error.out());
  g_object_unref(*device);  // the camera holds its own reference
  if (camera == nullptr) {
    return absl::UnavailableError(absl::StrCat("camera '", id, "': ", error.message()));
  }
  return camera;
}

static_assert(kPfncMono8 == ARV_PIXEL_FORMAT_MONO_8 && kPfncMono16 == ARV_PIXEL_FORMAT_MONO_16 &&
              kPfncRgb8 == ARV_PIXEL_FORMAT_RGB_8_PACKED &&
              kPfncBgr8 == ARV_PIXEL_FORMAT_BGR_8_PACKED &&
              kPfncBayerGr8 == ARV_PIXEL_FORMAT_BAYER_GR_8 &&
              kPfncBayerRg8 == ARV_PIXEL_FORMAT_BAYER_RG_8 &&
              kPfncBayerGb8 == ARV_PIXEL_FORMAT_BAYER_GB_8 &&
              kPfncBayerBg8 == ARV_PIXEL_FORMAT_BAYER_BG_8);

std::uint8_t Luma(double r, double g, double b) {
  return static_cast<std::uint8_t>(std::lround(0.299 * r + 0.587 * g + 0.114 * b));
}

// The colour (0 red, 1 green, 2 blue) of the Bayer pattern's top-left 2 x 2 cells, row-major.
struct BayerPattern {
  int cell[4];
  int At(int x, int y) const { return cell[2 * (y & 1) + (x & 1)]; }
};

BayerPattern PatternOf(std::uint32_t pixel_format) {
  switch (pixel_format) {
    case kPfncBayerGr8:
      return {{1, 0, 2, 1}};
    case kPfncBayerRg8:
      return {{0, 1, 1, 2}};
    case kPfncBayerGb8:
      return {{1, 2, 0, 1}};
    default:  // kPfncBayerBg8
      return {{2, 1, 1, 0}};
  }
}

// Bilinear demosaicing, then luma. Mirroring (-1 -> 1, w -> w - 2) keeps the pattern's
// parity at the border, so every 3 x 3 neighbourhood holds all three colours.
void BayerToGrey(const std::uint8_t* data, int width, int height, BayerPattern pattern,
                 Image8* out) {
  auto mirror = [](int i, int n) { return i < 0 ? -i : (i >= n ? 2 * n - 2 - i : i); };
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const int own = pattern.At(x, y);
      double sum[3] = {0, 0, 0};
      int count[3] = {0, 0, 0};
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const int c = pattern.At(x + dx, y + dy);
          if (c == own && (dx != 0 || dy != 0)) continue;  // a sample's own colour is its own
          sum[c] += data[static_cast<std::size_t>(mirror(y + dy, height)) * width +
                         mirror(x + dx, width)];
          ++count[c];
        }
      }
      out->at(x, y) = Luma(sum[0] / count[0], sum[1] / count[1], sum[2] / count[2]);
    }
  }
}

}  // namespace

absl::StatusOr<Image8> GigeFrameToGrey(std::uint32_t pixel_format, const std::uint8_t* data,
                                       std::size_t size, int width, int height) {
  if (width <= 0 || height <= 0 || width > kMaxImageSide || height > kMaxImageSide) {
    return absl::InvalidArgumentError(absl::StrCat("frame size ", width, " x ", height,
                                                   ": must be 1..", kMaxImageSide, " per side"));
  }
  const bool bayer = pixel_format == kPfncBayerGr8 || pixel_format == kPfncBayerRg8 ||
                     pixel_format == kPfncBayerGb8 || pixel_format == kPfncBayerBg8;
  if (bayer && (width < 2 || height < 2)) {
    return absl::InvalidArgumentError(
        absl::StrCat("Bayer frame of ", width, " x ", height, ": needs at least 2 x 2 pixels"));
  }
  std::size_t bytes_per_pixel = 0;
  switch (pixel_format) {
    case kPfncMono8:
    case kPfncBayerGr8:
    case kPfncBayerRg8:
    case kPfncBayerGb8:
    case kPfncBayerBg8:
      bytes_per_pixel = 1;
      break;
    case kPfncMono16:
      bytes_per_pixel = 2;
      break;
    case kPfncRgb8:
    case kPfncBgr8:
      bytes_per_pixel = 3;
      break;
    default:
      return absl::InvalidArgumentError(absl::StrCat(
          "pixel format 0x", absl::Hex(pixel_format),
          " cannot be converted to grey (Mono8, Mono16, RGB8, BGR8, Bayer 8-bit can)"));
  }
  const std::size_t pixels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  if (data == nullptr || size < pixels * bytes_per_pixel) {
    return absl::InvalidArgumentError(absl::StrCat("frame of ", width, " x ", height, " needs ",
                                                   pixels * bytes_per_pixel, " bytes, got ",
                                                   data == nullptr ? 0 : size));
  }
  Image8 out(width, height);
  switch (pixel_format) {
    case kPfncMono8:
      std::memcpy(out.pixels.data(), data, pixels);
      break;
    case kPfncMono16:
      for (std::size_t i = 0; i < pixels; ++i) {
        const unsigned v = data[2 * i] | (static_cast<unsigned>(data[2 * i + 1]) << 8);
        // 65535 / 257 = 255: the full 16-bit range onto the full 8-bit range.
        out.pixels[i] = static_cast<std::uint8_t>(std::lround(v / 257.0));
      }
      break;
    case kPfncRgb8:
    case kPfncBgr8: {
      const bool rgb = pixel_format == kPfncRgb8;
      for (std::size_t i = 0; i < pixels; ++i) {
        const std::uint8_t* p = data + 3 * i;
        out.pixels[i] = rgb ? Luma(p[0], p[1], p[2]) : Luma(p[2], p[1], p[0]);
      }
      break;
    }
    default:
      BayerToGrey(data, width, height, PatternOf(pixel_format), &out);
      break;
  }
  return out;
}

AravisCamera::AravisCamera(AravisCameraOptions options, _ArvCamera* camera)
    : options_(std::move(options)), camera_(camera) {}

absl::StatusOr<std::unique_ptr<AravisCamera>> AravisCamera::Open(
    const AravisCameraOptions& options) {
  const std::string& id = options.device_id;
  absl::StatusOr<ArvCamera*> created = CreateCamera(id);
  if (!created.ok()) return created.status();
  ArvCamera* camera = *created;
  std::unique_ptr<AravisCamera> self(new AravisCamera(options, camera));
  ErrorHolder error;

  arv_camera_set_pixel_format_from_string(camera, options.pixel_format.c_str(), error.out());
  if (error.error != nullptr) {
    return absl::InvalidArgumentError(absl::StrCat("camera '", id, "': pixel format '",
                                                   options.pixel_format, "': ", error.message()));
  }
  if (options.exposure_us > 0) {
    arv_camera_set_exposure_time(camera, options.exposure_us, error.out());
    if (error.error != nullptr) {
      return absl::InvalidArgumentError(absl::StrCat(
          "camera '", id, "': exposure ", options.exposure_us, " us: ", error.message()));
    }
  }
  const guint payload = arv_camera_get_payload(camera, error.out());
  if (error.error != nullptr) {
    return absl::InternalError(absl::StrCat("camera '", id, "': payload: ", error.message()));
  }
  // The stream on a UDP socket of its own, never on Aravis's packet socket (used when the
  // process may open one, as root): that socket takes every packet of the host from its
  // creation until Aravis attaches its filter, so the frames of cameras already streaming
  // were assembled into this one's buffers (docs/sensors.md, "Several cameras at once").
  if (arv_camera_is_gv_device(camera)) {
    arv_camera_gv_set_stream_options(camera, ARV_GV_STREAM_OPTION_PACKET_SOCKET_DISABLED);
  }
  self->stream_ = arv_camera_create_stream(camera, nullptr, nullptr, error.out());
  if (self->stream_ == nullptr) {
    return absl::InternalError(absl::StrCat("camera '", id, "': stream: ", error.message()));
  }
  if (ARV_IS_GV_STREAM(self->stream_)) {
    const int socket_buffer = static_cast<int>(std::max<guint>(payload, kMinStreamSocketBuffer));
    g_object_set(self->stream_, "socket-buffer", ARV_GV_STREAM_SOCKET_BUFFER_FIXED,
                 "socket-buffer-size", socket_buffer, nullptr);
  }
  for (int i = 0; i < kStreamBuffers; ++i) {
    arv_stream_push_buffer(self->stream_, arv_buffer_new_allocate(payload));
  }
  arv_camera_start_acquisition(camera, error.out());
  if (error.error != nullptr) {
    return absl::InternalError(
        absl::StrCat("camera '", id, "': start acquisition: ", error.message()));
  }
  self->acquiring_ = true;
  return self;
}

AravisCamera::~AravisCamera() {
  // A camera that went silent is most likely gone: each unanswered control request costs
  // Aravis's GVCP retries (6 x 500 ms), and stopping it would change nothing.
  if (acquiring_ && !silent_) {
    ErrorHolder ignored;  // releasing the camera below is what matters
    arv_camera_stop_acquisition(camera_, ignored.out());
  }
  // The stream's thread is joined and its queued buffers freed with the stream.
  if (stream_ != nullptr) g_object_unref(stream_);
  g_object_unref(camera_);
}

absl::StatusOr<CameraFrame> AravisCamera::Grab(std::chrono::steady_clock::time_point deadline,
                                               const std::atomic<bool>* cancel) {
  const std::string& id = options_.device_id;
  CameraFrame frame;
  auto frame_deadline = std::chrono::steady_clock::now() + options_.frame_timeout;
  ArvBufferStatus last_status = ARV_BUFFER_STATUS_SUCCESS;
  while (true) {
    if (cancel != nullptr && cancel->load()) {
      return absl::CancelledError(absl::StrCat("camera '", id, "': cancelled"));
    }
    const auto now = std::chrono::steady_clock::now();
    if (now >= deadline) {
      return absl::DeadlineExceededError(
          absl::StrCat("camera '", id, "': deadline passed before the frame was complete"));
    }
    if (now >= frame_deadline) {
      silent_ = true;
      return absl::DeadlineExceededError(absl::StrCat("camera '", id, "': no frame within ",
                                                      options_.frame_timeout.count(), " ms"));
    }
    const auto wait = std::min(kPollInterval, std::chrono::ceil<std::chrono::milliseconds>(
                                                  std::min(deadline, frame_deadline) - now));
    ArvBuffer* buffer = arv_stream_timeout_pop_buffer(
        stream_, static_cast<guint64>(std::chrono::microseconds(wait).count()));
    if (buffer == nullptr) continue;
    ++frame.attempts;
    const ArvBufferStatus status = arv_buffer_get_status(buffer);
    if (status != ARV_BUFFER_STATUS_SUCCESS) {
      arv_stream_push_buffer(stream_, buffer);
      ++incomplete_frames_;
      last_status = status;
      if (frame.attempts > options_.frame_retries) {
        return absl::DataLossError(absl::StrCat("camera '", id, "': ", frame.attempts,
                                                " frames in a row incomplete, last ",
                                                BufferStatusName(last_status)));
      }
      frame_deadline = std::chrono::steady_clock::now() + options_.frame_timeout;
      continue;
    }
    frame.t_ns = UnixNowNs();
    std::size_t size = 0;
    const void* data = arv_buffer_get_data(buffer, &size);
    absl::StatusOr<Image8> image = GigeFrameToGrey(
        arv_buffer_get_image_pixel_format(buffer), static_cast<const std::uint8_t*>(data), size,
        arv_buffer_get_image_width(buffer), arv_buffer_get_image_height(buffer));
    arv_stream_push_buffer(stream_, buffer);
    if (!image.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat("camera '", id, "': ", image.status().message()));
    }
    frame.image = *std::move(image);
    return frame;
  }
}

}  // namespace linecal

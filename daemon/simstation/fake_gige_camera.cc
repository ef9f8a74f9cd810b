#include "daemon/simstation/fake_gige_camera.h"

#include <arpa/inet.h>
#include <arv.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <utility>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

// GigE Vision's bootstrap register block holds the serial number in 16 bytes, NUL included.
constexpr std::size_t kMaxSerialLength = 15;

absl::Status CheckImage(const Image8& image) {
  if (image.width <= 0 || image.height <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("fake camera image: empty (", image.width, " x ", image.height, ")"));
  }
  if (image.width > kMaxImageSide || image.height > kMaxImageSide) {
    return absl::InvalidArgumentError(absl::StrCat("fake camera image: too large: ", image.width,
                                                   " x ", image.height, " pixels (max ",
                                                   kMaxImageSide, " per side)"));
  }
  return absl::OkStatus();
}

// GigE Vision's control port (GVCP, UDP).
constexpr std::uint16_t kGvcpPort = 3956;

// Whether `address`:3956 can be bound. Aravis binds the fake camera's control socket with
// address reuse, so a second fake camera on the same address would start and share the
// port with the first (each would get some of the requests); a plain bind finds out first.
absl::Status CheckControlPortFree(const std::string& address) {
  sockaddr_in local{};
  local.sin_family = AF_INET;
  local.sin_port = htons(kGvcpPort);
  if (::inet_pton(AF_INET, address.c_str(), &local.sin_addr) != 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("fake camera address '", address, "': not an IPv4 address"));
  }
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    return absl::InternalError(absl::StrCat("fake camera: socket failed: ", std::strerror(errno)));
  }
  const int result = ::bind(fd, reinterpret_cast<const sockaddr*>(&local), sizeof local);
  const int error = errno;
  ::close(fd);
  if (result == 0) return absl::OkStatus();
  if (error == EADDRINUSE) {
    return absl::UnavailableError(absl::StrCat("fake camera: cannot listen on ", address,
                                               ":3956: another camera or program listens there"));
  }
  return absl::UnavailableError(
      absl::StrCat("fake camera: cannot listen on ", address, ":3956: ", std::strerror(error)));
}

// The fake camera bounds Width/Height by the sensor registers, and sends Width x Height
// pixels from offset (0, 0) without binning: set all of them so a frame is the whole image.
void WriteSizeRegisters(ArvFakeCamera* camera, int width, int height) {
  const auto w = static_cast<guint32>(width);
  const auto h = static_cast<guint32>(height);
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_SENSOR_WIDTH, w);
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_SENSOR_HEIGHT, h);
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_X_OFFSET, 0);
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_Y_OFFSET, 0);
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_BINNING_HORIZONTAL, 1);
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_BINNING_VERTICAL, 1);
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_WIDTH, w);
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_HEIGHT, h);
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_PIXEL_FORMAT,
                                 ARV_PIXEL_FORMAT_MONO_8);
}

}  // namespace

FakeGigeCamera::FakeGigeCamera(std::string address, std::string serial)
    : address_(std::move(address)), serial_(std::move(serial)) {}

absl::StatusOr<std::unique_ptr<FakeGigeCamera>> FakeGigeCamera::Start(const std::string& address,
                                                                      const std::string& serial,
                                                                      Image8 initial,
                                                                      double lost_ratio,
                                                                      double frames_per_second) {
  if (serial.empty() || serial.size() > kMaxSerialLength) {
    return absl::InvalidArgumentError(absl::StrCat("fake camera serial '", serial, "': must be 1..",
                                                   kMaxSerialLength, " characters"));
  }
  if (!(lost_ratio >= 0.0 && lost_ratio <= 1.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("fake camera gvsp-lost-ratio ", lost_ratio, ": must be in 0..1"));
  }
  if (!(frames_per_second >= 0.1 && frames_per_second <= 100.0)) {
    return absl::InvalidArgumentError(absl::StrCat("fake camera frame rate ", frames_per_second,
                                                   ": must be in 0.1..100 frames/s"));
  }
  if (absl::Status s = CheckImage(initial); !s.ok()) return s;
  if (absl::Status s = CheckControlPortFree(address); !s.ok()) return s;

  std::unique_ptr<FakeGigeCamera> fake(new FakeGigeCamera(address, serial));
  fake->image_ = std::move(initial);
  // The constructor binds the sockets and starts the thread; is_running says whether it
  // found the address among the machine's interfaces and could bind there.
  fake->camera_ = arv_gv_fake_camera_new(address.c_str(), serial.c_str());
  if (fake->camera_ == nullptr || !arv_gv_fake_camera_is_running(fake->camera_)) {
    return absl::UnavailableError(absl::StrCat("fake camera: cannot listen on ", address,
                                               ":3956: no interface has that address"));
  }
  g_object_set(fake->camera_, "gvsp-lost-ratio", lost_ratio, nullptr);
  ArvFakeCamera* camera = arv_gv_fake_camera_get_fake_camera(fake->camera_);
  WriteSizeRegisters(camera, fake->image_.width, fake->image_.height);
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_ACQUISITION_FRAME_PERIOD_US,
                                 static_cast<guint32>(std::lround(1e6 / frames_per_second)));
  arv_fake_camera_set_fill_pattern(camera, &FakeGigeCamera::Fill, fake.get());
  return fake;
}

FakeGigeCamera::~FakeGigeCamera() {
  // Finalising joins the camera thread, so Fill never runs after this.
  if (camera_ != nullptr) g_object_unref(camera_);
}

absl::Status FakeGigeCamera::SetImage(Image8 image) {
  if (absl::Status s = CheckImage(image); !s.ok()) return s;
  std::lock_guard<std::mutex> lock(mutex_);
  WriteSizeRegisters(arv_gv_fake_camera_get_fake_camera(camera_), image.width, image.height);
  image_ = std::move(image);
  return absl::OkStatus();
}

void FakeGigeCamera::Fill(_ArvBuffer* buffer, void* self, unsigned /*exposure_us*/,
                          unsigned /*gain*/, unsigned /*pixel_format*/) {
  auto* fake = static_cast<FakeGigeCamera*>(self);
  // The fake camera set the buffer's size from its registers and checked that the buffer
  // holds that many bytes before calling.
  const int width = arv_buffer_get_image_width(buffer);
  const int height = arv_buffer_get_image_height(buffer);
  auto* data = static_cast<std::uint8_t*>(const_cast<void*>(arv_buffer_get_data(buffer, nullptr)));
  const std::size_t bytes = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  std::lock_guard<std::mutex> lock(fake->mutex_);
  if (width == fake->image_.width && height == fake->image_.height) {
    std::memcpy(data, fake->image_.pixels.data(), bytes);
  } else {
    // The size changed between the fake camera reading its registers and this call.
    std::memset(data, 0, bytes);
  }
}

}  // namespace linecal

#include "daemon/drivers/v4l2_camera.h"

#include <fcntl.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <utility>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

int Ioctl(int fd, unsigned long request, void* arg) {
  int result;
  do {
    result = ::ioctl(fd, request, arg);
  } while (result < 0 && errno == EINTR);
  return result;
}

absl::Status SyscallError(const std::string& device, const std::string& what, int error) {
  return absl::InternalError(absl::StrCat(device, ": ", what, " failed: ", std::strerror(error)));
}

std::string FourccName(std::uint32_t fourcc) {
  std::string name(4, ' ');
  for (int i = 0; i < 4; ++i) name[i] = static_cast<char>((fourcc >> (8 * i)) & 0xFF);
  return name;
}

std::int64_t UnixNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace

absl::StatusOr<std::uint32_t> V4l2PixelFormat(const std::string& name) {
  if (name == "GREY") return V4L2_PIX_FMT_GREY;
  if (name == "YUYV") return V4L2_PIX_FMT_YUYV;
  return absl::InvalidArgumentError(
      absl::StrCat("pixel format '", name, "': must be GREY or YUYV"));
}

absl::StatusOr<Image8> V4l2FrameToGrey(std::uint32_t fourcc, const std::uint8_t* data,
                                       std::size_t size, int width, int height,
                                       std::size_t bytes_per_line) {
  if (fourcc != V4L2_PIX_FMT_GREY && fourcc != V4L2_PIX_FMT_YUYV) {
    return absl::InvalidArgumentError(
        absl::StrCat("pixel format '", FourccName(fourcc), "' cannot be converted to grey"));
  }
  if (width <= 0 || height <= 0 || width > kMaxImageSide || height > kMaxImageSide) {
    return absl::InvalidArgumentError(absl::StrCat("frame size ", width, " x ", height,
                                                   ": must be 1..", kMaxImageSide, " per side"));
  }
  const std::size_t bytes_per_pixel = fourcc == V4L2_PIX_FMT_YUYV ? 2 : 1;
  const std::size_t row_bytes = static_cast<std::size_t>(width) * bytes_per_pixel;
  if (bytes_per_line < row_bytes) {
    return absl::InvalidArgumentError(
        absl::StrCat("bytes per line ", bytes_per_line, " below the row's ", row_bytes));
  }
  const std::size_t needed = static_cast<std::size_t>(height - 1) * bytes_per_line + row_bytes;
  if (data == nullptr || size < needed) {
    return absl::InvalidArgumentError(absl::StrCat("frame of ", width, " x ", height, " needs ",
                                                   needed, " bytes, got ",
                                                   data == nullptr ? 0 : size));
  }
  Image8 out(width, height);
  for (int y = 0; y < height; ++y) {
    const std::uint8_t* row = data + static_cast<std::size_t>(y) * bytes_per_line;
    std::uint8_t* dst = &out.pixels[static_cast<std::size_t>(y) * width];
    if (bytes_per_pixel == 1) {
      std::memcpy(dst, row, row_bytes);
    } else {
      for (int x = 0; x < width; ++x) dst[x] = row[2 * x];  // Y0 U Y1 V: luma at even bytes
    }
  }
  return out;
}

absl::StatusOr<std::unique_ptr<V4l2Camera>> V4l2Camera::Open(const V4l2CameraOptions& options) {
  const std::string& dev = options.device;
  absl::StatusOr<std::uint32_t> fourcc = V4l2PixelFormat(options.pixel_format);
  if (!fourcc.ok())
    return absl::InvalidArgumentError(absl::StrCat(dev, ": ", fourcc.status().message()));

  struct stat st {};
  if (::stat(dev.c_str(), &st) != 0) {
    const int error = errno;
    if (error == ENOENT) return absl::UnavailableError(absl::StrCat(dev, ": no such device"));
    return absl::UnavailableError(absl::StrCat(dev, ": stat failed: ", std::strerror(error)));
  }
  if (!S_ISCHR(st.st_mode)) {
    return absl::UnavailableError(absl::StrCat(dev, ": not a character device"));
  }
  std::unique_ptr<V4l2Camera> self(new V4l2Camera(options));
  self->fd_ = ::open(dev.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
  if (self->fd_ < 0) {
    const int error = errno;
    if (error == EACCES) {
      return absl::UnavailableError(absl::StrCat(
          dev, ": permission denied (the daemon's user must be in the group 'video')"));
    }
    return absl::UnavailableError(absl::StrCat(dev, ": open failed: ", std::strerror(error)));
  }
  const int fd = self->fd_;

  v4l2_capability cap{};
  if (Ioctl(fd, VIDIOC_QUERYCAP, &cap) < 0) {
    const int error = errno;
    if (error == ENOTTY || error == EINVAL) {
      return absl::UnavailableError(absl::StrCat(dev, ": not a V4L2 device"));
    }
    return SyscallError(dev, "VIDIOC_QUERYCAP", error);
  }
  // device_caps describe this node; capabilities the whole physical device.
  const std::uint32_t caps =
      (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
  const std::string card(reinterpret_cast<const char*>(cap.card),
                         strnlen(reinterpret_cast<const char*>(cap.card), sizeof cap.card));
  if ((caps & V4L2_CAP_VIDEO_CAPTURE) == 0) {
    return absl::UnavailableError(absl::StrCat(dev, ": cannot capture video (", card, ")"));
  }
  if ((caps & V4L2_CAP_STREAMING) == 0) {
    return absl::UnavailableError(absl::StrCat(dev, ": cannot stream (", card, ")"));
  }

  v4l2_format format{};
  format.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (Ioctl(fd, VIDIOC_G_FMT, &format) < 0) return SyscallError(dev, "VIDIOC_G_FMT", errno);
  format.fmt.pix.pixelformat = *fourcc;
  if (options.width > 0 && options.height > 0) {
    format.fmt.pix.width = static_cast<std::uint32_t>(options.width);
    format.fmt.pix.height = static_cast<std::uint32_t>(options.height);
  }
  format.fmt.pix.field = V4L2_FIELD_NONE;
  if (Ioctl(fd, VIDIOC_S_FMT, &format) < 0) return SyscallError(dev, "VIDIOC_S_FMT", errno);
  // The driver answers with what it chose, which may differ from what was asked.
  if (format.fmt.pix.pixelformat != *fourcc) {
    return absl::InvalidArgumentError(absl::StrCat(dev, ": does not deliver ", options.pixel_format,
                                                   " (offers ",
                                                   FourccName(format.fmt.pix.pixelformat), ")"));
  }
  if (options.width > 0 && (static_cast<int>(format.fmt.pix.width) != options.width ||
                            static_cast<int>(format.fmt.pix.height) != options.height)) {
    return absl::InvalidArgumentError(
        absl::StrCat(dev, ": does not deliver ", options.width, " x ", options.height, " (offers ",
                     format.fmt.pix.width, " x ", format.fmt.pix.height, ")"));
  }
  if (format.fmt.pix.width == 0 || format.fmt.pix.height == 0 ||
      format.fmt.pix.width > static_cast<std::uint32_t>(kMaxImageSide) ||
      format.fmt.pix.height > static_cast<std::uint32_t>(kMaxImageSide)) {
    return absl::InvalidArgumentError(absl::StrCat(dev, ": frame size ", format.fmt.pix.width,
                                                   " x ", format.fmt.pix.height, ": must be 1..",
                                                   kMaxImageSide, " per side"));
  }
  self->fourcc_ = *fourcc;
  self->width_ = static_cast<int>(format.fmt.pix.width);
  self->height_ = static_cast<int>(format.fmt.pix.height);
  const std::size_t min_line =
      static_cast<std::size_t>(self->width_) * (*fourcc == V4L2_PIX_FMT_YUYV ? 2 : 1);
  self->bytes_per_line_ = std::max<std::size_t>(format.fmt.pix.bytesperline, min_line);
  self->frame_bytes_ = std::max<std::size_t>(
      format.fmt.pix.sizeimage, self->bytes_per_line_ * static_cast<std::size_t>(self->height_));

  v4l2_requestbuffers request{};
  request.count = kBuffers;
  request.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  request.memory = V4L2_MEMORY_MMAP;
  if (Ioctl(fd, VIDIOC_REQBUFS, &request) < 0) return SyscallError(dev, "VIDIOC_REQBUFS", errno);
  if (request.count == 0) {
    return absl::UnavailableError(absl::StrCat(dev, ": no memory-mapped buffers"));
  }
  for (std::uint32_t i = 0; i < request.count; ++i) {
    v4l2_buffer buffer{};
    buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buffer.memory = V4L2_MEMORY_MMAP;
    buffer.index = i;
    if (Ioctl(fd, VIDIOC_QUERYBUF, &buffer) < 0) return SyscallError(dev, "VIDIOC_QUERYBUF", errno);
    void* start =
        ::mmap(nullptr, buffer.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd, buffer.m.offset);
    if (start == MAP_FAILED) return SyscallError(dev, "mmap", errno);
    self->mappings_.push_back({start, buffer.length});
    if (Ioctl(fd, VIDIOC_QBUF, &buffer) < 0) return SyscallError(dev, "VIDIOC_QBUF", errno);
  }
  v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (Ioctl(fd, VIDIOC_STREAMON, &type) < 0) return SyscallError(dev, "VIDIOC_STREAMON", errno);
  self->streaming_ = true;
  return self;
}

V4l2Camera::~V4l2Camera() {
  if (streaming_) {
    v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    Ioctl(fd_, VIDIOC_STREAMOFF, &type);  // closing stops streaming too; this is the orderly way
  }
  for (const Mapping& m : mappings_) ::munmap(m.start, m.length);
  if (fd_ >= 0) ::close(fd_);
}

absl::StatusOr<CameraFrame> V4l2Camera::Grab(std::chrono::steady_clock::time_point deadline,
                                             const std::atomic<bool>* cancel) {
  const std::string& dev = options_.device;
  CameraFrame frame;
  auto frame_deadline = std::chrono::steady_clock::now() + options_.frame_timeout;
  while (true) {
    if (cancel != nullptr && cancel->load()) {
      return absl::CancelledError(absl::StrCat(dev, ": cancelled"));
    }
    const auto now = std::chrono::steady_clock::now();
    if (now >= deadline) {
      return absl::DeadlineExceededError(
          absl::StrCat(dev, ": deadline passed before the frame was complete"));
    }
    if (now >= frame_deadline) {
      return absl::DeadlineExceededError(
          absl::StrCat(dev, ": no frame within ", options_.frame_timeout.count(), " ms"));
    }
    const auto wait = std::min(kPollInterval, std::chrono::ceil<std::chrono::milliseconds>(
                                                  std::min(deadline, frame_deadline) - now));
    pollfd pfd{fd_, POLLIN, 0};
    const int ready = ::poll(&pfd, 1, static_cast<int>(wait.count()));
    if (ready < 0) {
      if (errno == EINTR) continue;
      return SyscallError(dev, "poll", errno);
    }
    if (ready == 0) continue;
    if ((pfd.revents & (POLLERR | POLLHUP | POLLNVAL)) != 0 && (pfd.revents & POLLIN) == 0) {
      return absl::UnavailableError(absl::StrCat(dev, ": device gone (poll error)"));
    }
    v4l2_buffer buffer{};
    buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buffer.memory = V4L2_MEMORY_MMAP;
    if (Ioctl(fd_, VIDIOC_DQBUF, &buffer) < 0) {
      if (errno == EAGAIN) continue;
      if (errno == ENODEV) return absl::UnavailableError(absl::StrCat(dev, ": device gone"));
      return SyscallError(dev, "VIDIOC_DQBUF", errno);
    }
    ++frame.attempts;
    const bool complete = (buffer.flags & V4L2_BUF_FLAG_ERROR) == 0 &&
                          buffer.bytesused >= frame_bytes_ && buffer.index < mappings_.size();
    if (!complete) {
      const std::uint32_t used = buffer.bytesused;
      if (Ioctl(fd_, VIDIOC_QBUF, &buffer) < 0) return SyscallError(dev, "VIDIOC_QBUF", errno);
      if (frame.attempts > options_.frame_retries) {
        return absl::DataLossError(absl::StrCat(dev, ": ", frame.attempts,
                                                " frames in a row incomplete (last ", used, " of ",
                                                frame_bytes_, " bytes)"));
      }
      frame_deadline = std::chrono::steady_clock::now() + options_.frame_timeout;
      continue;
    }
    frame.t_ns = UnixNowNs();
    absl::StatusOr<Image8> image =
        V4l2FrameToGrey(fourcc_, static_cast<const std::uint8_t*>(mappings_[buffer.index].start),
                        buffer.bytesused, width_, height_, bytes_per_line_);
    if (Ioctl(fd_, VIDIOC_QBUF, &buffer) < 0) return SyscallError(dev, "VIDIOC_QBUF", errno);
    if (!image.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(dev, ": ", image.status().message()));
    }
    frame.image = *std::move(image);
    return frame;
  }
}

}  // namespace linecal

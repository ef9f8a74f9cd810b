// V4L2: this machine has no video device, so the open errors are tested on real paths that
// are not V4L2 devices, and the conversion on byte buffers laid out as drivers deliver them.
#include "daemon/drivers/v4l2_camera.h"

#include <linux/videodev2.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <vector>

#include "gtest/gtest.h"

namespace linecal {
namespace {

absl::Status OpenError(const std::string& device) {
  V4l2CameraOptions options;
  options.device = device;
  return V4l2Camera::Open(options).status();
}

TEST(V4l2CameraTest, MissingPathIsUnavailable) {
  const absl::Status s = OpenError("/dev/video-linecal-none");
  EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(s.message(), "/dev/video-linecal-none: no such device");
}

TEST(V4l2CameraTest, RegularFileIsNotACharacterDevice) {
  const std::string path = ::testing::TempDir() + "/v4l2_regular_file";
  std::ofstream(path) << "not a camera";
  const absl::Status s = OpenError(path);
  EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(s.message(), path + ": not a character device");
  std::filesystem::remove(path);
}

TEST(V4l2CameraTest, DirectoryIsNotACharacterDevice) {
  EXPECT_EQ(OpenError("/dev").message(), "/dev: not a character device");
}

TEST(V4l2CameraTest, DevNullIsNotAV4l2Device) {
  // A character device whose driver knows no VIDIOC_QUERYCAP: the kernel answers ENOTTY.
  const absl::Status s = OpenError("/dev/null");
  EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(s.message(), "/dev/null: not a V4L2 device");
}

TEST(V4l2CameraTest, UnknownPixelFormatIsInvalidArgument) {
  V4l2CameraOptions options;
  options.device = "/dev/null";
  options.pixel_format = "MJPG";
  const absl::Status s = V4l2Camera::Open(options).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(), "/dev/null: pixel format 'MJPG': must be GREY or YUYV");
}

TEST(V4l2PixelFormatTest, NamesTheTwoFormats) {
  EXPECT_EQ(*V4l2PixelFormat("GREY"), V4L2_PIX_FMT_GREY);
  EXPECT_EQ(*V4l2PixelFormat("YUYV"), V4L2_PIX_FMT_YUYV);
  EXPECT_EQ(V4l2PixelFormat("grey").status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(V4l2FrameToGreyTest, GreyRowsWithPadding) {
  // 3 x 2 pixels, rows padded to 4 bytes (padding bytes 0xEE must not show).
  const std::vector<std::uint8_t> bytes = {1, 2, 3, 0xEE, 4, 5, 6, 0xEE};
  auto grey = V4l2FrameToGrey(V4L2_PIX_FMT_GREY, bytes.data(), bytes.size(), 3, 2, 4);
  ASSERT_TRUE(grey.ok()) << grey.status();
  EXPECT_EQ(grey->pixels, (std::vector<std::uint8_t>{1, 2, 3, 4, 5, 6}));
  // The last row needs no padding: 4 + 3 bytes suffice.
  grey = V4l2FrameToGrey(V4L2_PIX_FMT_GREY, bytes.data(), 7, 3, 2, 4);
  ASSERT_TRUE(grey.ok()) << grey.status();
}

TEST(V4l2FrameToGreyTest, YuyvKeepsTheLuma) {
  // Y0 U Y1 V, 4 x 2 pixels, no padding.
  const std::vector<std::uint8_t> bytes = {10, 128, 20, 128, 30, 90,  40, 200,
                                           50, 0,   60, 255, 70, 128, 80, 128};
  auto grey = V4l2FrameToGrey(V4L2_PIX_FMT_YUYV, bytes.data(), bytes.size(), 4, 2, 8);
  ASSERT_TRUE(grey.ok()) << grey.status();
  EXPECT_EQ(grey->pixels, (std::vector<std::uint8_t>{10, 20, 30, 40, 50, 60, 70, 80}));
}

TEST(V4l2FrameToGreyTest, RefusesBadFrames) {
  const std::vector<std::uint8_t> bytes(16, 0);
  EXPECT_EQ(
      V4l2FrameToGrey(V4L2_PIX_FMT_GREY, bytes.data(), bytes.size(), 4, 5, 4).status().message(),
      "frame of 4 x 5 needs 20 bytes, got 16");
  EXPECT_EQ(
      V4l2FrameToGrey(V4L2_PIX_FMT_YUYV, bytes.data(), bytes.size(), 4, 2, 6).status().message(),
      "bytes per line 6 below the row's 8");
  EXPECT_EQ(
      V4l2FrameToGrey(V4L2_PIX_FMT_MJPEG, bytes.data(), bytes.size(), 4, 4, 4).status().message(),
      "pixel format 'MJPG' cannot be converted to grey");
  EXPECT_EQ(V4l2FrameToGrey(V4L2_PIX_FMT_GREY, bytes.data(), bytes.size(), kMaxImageSide + 1, 1,
                            kMaxImageSide + 1)
                .status()
                .code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace linecal

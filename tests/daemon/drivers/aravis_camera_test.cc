// The Aravis driver against Aravis's in-process fake GigE camera on 127.0.0.1: the real GVCP
// control and GVSP stream path over loopback UDP (ctest serialises these tests on the
// resource lock gige_loopback, since one fake camera at a time can listen there).
#include "daemon/drivers/aravis_camera.h"

#include <chrono>
#include <cstdint>
#include <thread>
#include <vector>

#include "daemon/simstation/fake_gige_camera.h"
#include "gtest/gtest.h"
#include "tests/daemon/random_image.h"

namespace linecal {
namespace {

using std::chrono::milliseconds;
using std::chrono::steady_clock;

constexpr char kLoopback[] = "127.0.0.1";

AravisCameraOptions OptionsFor(const FakeGigeCamera& fake) {
  AravisCameraOptions options;
  options.device_id = fake.device_id();
  return options;
}

double Seconds(steady_clock::duration d) { return std::chrono::duration<double>(d).count(); }

TEST(FakeGigeCameraTest, RefusesBadArguments) {
  EXPECT_EQ(FakeGigeCamera::Start(kLoopback, "", Image8(8, 8)).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(FakeGigeCamera::Start(kLoopback, "SIXTEEN_CHARS_XX", Image8(8, 8)).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(FakeGigeCamera::Start(kLoopback, "T", Image8()).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(FakeGigeCamera::Start(kLoopback, "T", Image8(8, 8), 1.5).status().code(),
            absl::StatusCode::kInvalidArgument);
  // 192.0.2.200 (TEST-NET-1) is no address of this machine: nothing to bind to.
  absl::StatusOr<std::unique_ptr<FakeGigeCamera>> elsewhere =
      FakeGigeCamera::Start("192.0.2.200", "T", Image8(8, 8));
  EXPECT_EQ(elsewhere.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(elsewhere.status().message().find("192.0.2.200:3956"), std::string::npos);
}

TEST(FakeGigeCameraTest, SecondCameraOnTheSameAddressIsUnavailable) {
  auto first = FakeGigeCamera::Start(kLoopback, "FIRST", Image8(8, 8));
  ASSERT_TRUE(first.ok()) << first.status();
  auto second = FakeGigeCamera::Start(kLoopback, "SECOND", Image8(8, 8));
  EXPECT_EQ(second.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ((*first)->device_id(), "Aravis-Fake-FIRST");
}

TEST(AravisCameraTest, FullHdFramesEqualTheServedImage) {
  const Image8 served = RandomImage(1920, 1080, 7);
  auto fake = FakeGigeCamera::Start(kLoopback, "FULLHD", served);
  ASSERT_TRUE(fake.ok()) << fake.status();
  const auto t_open = steady_clock::now();
  auto camera = AravisCamera::Open(OptionsFor(**fake));
  ASSERT_TRUE(camera.ok()) << camera.status();
  const auto t_opened = steady_clock::now();
  std::vector<double> grab_s;
  int first_attempts = 0;
  for (int k = 0; k < 5; ++k) {
    const auto t0 = steady_clock::now();
    absl::StatusOr<CameraFrame> frame = (*camera)->Grab(t0 + std::chrono::seconds(5), nullptr);
    grab_s.push_back(Seconds(steady_clock::now() - t0));
    ASSERT_TRUE(frame.ok()) << frame.status();
    EXPECT_EQ(frame->image.width, 1920);
    EXPECT_EQ(frame->image.height, 1080);
    // Aravis sizes the stream's socket buffer when a frame starts, so the fake camera's
    // first 1920 x 1080 burst after the start of acquisition can overflow the kernel's
    // default buffer on loopback and be retried once (docs/sensors.md, "Several cameras at
    // once"); every later frame comes whole at the first attempt.
    if (k == 0) {
      first_attempts = frame->attempts;
      EXPECT_GE(frame->attempts, 1);
      EXPECT_LE(frame->attempts, 2);
    } else {
      EXPECT_EQ(frame->attempts, 1) << "frame " << k;
    }
    EXPECT_TRUE(frame->image.pixels == served.pixels) << "frame " << k;
    EXPECT_GT(frame->t_ns, 0);
  }
  EXPECT_EQ((*camera)->incomplete_frames(), first_attempts - 1);
  // Measured numbers for docs/daemon.md: open, first frame (acquisition start), later frames
  // (the fake camera's 25 frames/s period).
  std::printf("open %.3f s, grab 1920x1080: first %.3f s, then %.3f %.3f %.3f %.3f s\n",
              Seconds(t_opened - t_open), grab_s[0], grab_s[1], grab_s[2], grab_s[3], grab_s[4]);
}

TEST(AravisCameraTest, OpensByAddressToo) {
  const Image8 served = RandomImage(64, 48, 3);
  auto fake = FakeGigeCamera::Start(kLoopback, "BYADDR", served);
  ASSERT_TRUE(fake.ok()) << fake.status();
  AravisCameraOptions options;
  options.device_id = kLoopback;
  auto camera = AravisCamera::Open(options);
  ASSERT_TRUE(camera.ok()) << camera.status();
  absl::StatusOr<CameraFrame> frame =
      (*camera)->Grab(steady_clock::now() + std::chrono::seconds(5), nullptr);
  ASSERT_TRUE(frame.ok()) << frame.status();
  EXPECT_TRUE(frame->image.pixels == served.pixels);
}

TEST(AravisCameraTest, SetImageReachesTheNextFrames) {
  const Image8 first = RandomImage(320, 240, 1);
  const Image8 second = RandomImage(320, 240, 2);
  auto fake = FakeGigeCamera::Start(kLoopback, "SWAP", first);
  ASSERT_TRUE(fake.ok()) << fake.status();
  auto camera = AravisCamera::Open(OptionsFor(**fake));
  ASSERT_TRUE(camera.ok()) << camera.status();
  auto frame = (*camera)->Grab(steady_clock::now() + std::chrono::seconds(5), nullptr);
  ASSERT_TRUE(frame.ok()) << frame.status();
  EXPECT_TRUE(frame->image.pixels == first.pixels);
  ASSERT_TRUE((*fake)->SetImage(second).ok());
  // Frames filled before SetImage may still be queued: the stream holds at most its four
  // buffers plus the one on the wire.
  int old_frames = 0;
  while (true) {
    frame = (*camera)->Grab(steady_clock::now() + std::chrono::seconds(5), nullptr);
    ASSERT_TRUE(frame.ok()) << frame.status();
    if (frame->image.pixels == second.pixels) break;
    EXPECT_TRUE(frame->image.pixels == first.pixels);
    ASSERT_LE(++old_frames, 5);
  }
}

TEST(AravisCameraTest, UnknownCameraIsUnavailable) {
  // A fake camera runs, but under another id: discovery must not take it for the asked one.
  auto fake = FakeGigeCamera::Start(kLoopback, "PRESENT", Image8(8, 8));
  ASSERT_TRUE(fake.ok()) << fake.status();
  AravisCameraOptions options;
  options.device_id = "Aravis-Fake-ABSENT42";
  const auto t0 = steady_clock::now();
  auto camera = AravisCamera::Open(options);
  EXPECT_EQ(camera.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(camera.status().message(), "camera 'Aravis-Fake-ABSENT42' not found");
  // Aravis's discovery waits one second for answers.
  EXPECT_LT(Seconds(steady_clock::now() - t0), 3.0);
}

TEST(AravisCameraTest, UnknownPixelFormatIsInvalidArgument) {
  auto fake = FakeGigeCamera::Start(kLoopback, "PIXFMT", Image8(8, 8));
  ASSERT_TRUE(fake.ok()) << fake.status();
  AravisCameraOptions options = OptionsFor(**fake);
  options.pixel_format = "Mono42";
  auto camera = AravisCamera::Open(options);
  EXPECT_EQ(camera.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(camera.status().message().find("pixel format 'Mono42'"), std::string::npos)
      << camera.status();
}

// 1920 x 1080 Mono8 is 1512 stream packets of 1372 bytes (Aravis's default 1400-byte packets
// less headers) plus leader and trailer: at 5 % loss a frame is complete with probability
// 0.95^1514 < 1e-33, so every frame is incomplete and the retries run out.
TEST(AravisCameraTest, LossyFullHdStreamIsDataLossAfterTheRetries) {
  auto fake = FakeGigeCamera::Start(kLoopback, "LOSSY", RandomImage(1920, 1080, 5), 0.05);
  ASSERT_TRUE(fake.ok()) << fake.status();
  AravisCameraOptions options = OptionsFor(**fake);
  options.frame_retries = 3;
  auto camera = AravisCamera::Open(options);
  ASSERT_TRUE(camera.ok()) << camera.status();
  absl::StatusOr<CameraFrame> frame =
      (*camera)->Grab(steady_clock::now() + std::chrono::seconds(10), nullptr);
  EXPECT_EQ(frame.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_EQ(frame.status().message(),
            "camera 'Aravis-Fake-LOSSY': 4 frames in a row incomplete, last MISSING_PACKETS");
  EXPECT_EQ((*camera)->incomplete_frames(), 4);
}

// 64 x 16 Mono8 is one data packet plus leader and trailer: at 10 % loss a frame is
// complete with probability 0.9^3 = 0.73. With 10 retries a frame fails with probability
// 0.27^11 < 1e-6, and 40 frames all arrive complete at the first try with probability
// 0.73^40 < 1e-5: the retries are exercised and every delivered frame is exact.
TEST(AravisCameraTest, LossySmallStreamIsRepairedByRetries) {
  const Image8 served = RandomImage(64, 16, 9);
  auto fake = FakeGigeCamera::Start(kLoopback, "RETRY", served, 0.1);
  ASSERT_TRUE(fake.ok()) << fake.status();
  AravisCameraOptions options = OptionsFor(**fake);
  options.frame_retries = 10;
  auto camera = AravisCamera::Open(options);
  ASSERT_TRUE(camera.ok()) << camera.status();
  constexpr int kFrames = 40;
  int attempts = 0;
  for (int k = 0; k < kFrames; ++k) {
    absl::StatusOr<CameraFrame> frame =
        (*camera)->Grab(steady_clock::now() + std::chrono::seconds(10), nullptr);
    ASSERT_TRUE(frame.ok()) << frame.status();
    EXPECT_TRUE(frame->image.pixels == served.pixels) << "frame " << k;
    attempts += frame->attempts;
  }
  EXPECT_EQ(attempts, kFrames + (*camera)->incomplete_frames());
  EXPECT_GT((*camera)->incomplete_frames(), 0);
  std::printf("10%% loss: %d incomplete frames retried for %d complete ones\n",
              (*camera)->incomplete_frames(), kFrames);
}

TEST(AravisCameraTest, VanishedCameraEndsTheGrabByTheFrameTimeout) {
  auto fake = FakeGigeCamera::Start(kLoopback, "VANISH", RandomImage(64, 48, 4));
  ASSERT_TRUE(fake.ok()) << fake.status();
  AravisCameraOptions options = OptionsFor(**fake);
  options.frame_timeout = milliseconds(500);
  auto camera = AravisCamera::Open(options);
  ASSERT_TRUE(camera.ok()) << camera.status();
  ASSERT_TRUE((*camera)->Grab(steady_clock::now() + std::chrono::seconds(5), nullptr).ok());
  fake->reset();
  // Frames already queued may still come; then nothing does.
  const auto t0 = steady_clock::now();
  absl::StatusOr<CameraFrame> frame;
  for (int k = 0; k < 10 && (frame = (*camera)->Grab(t0 + std::chrono::seconds(5), nullptr)).ok();
       ++k) {
  }
  EXPECT_EQ(frame.status().code(), absl::StatusCode::kDeadlineExceeded);
  EXPECT_EQ(frame.status().message(), "camera 'Aravis-Fake-VANISH': no frame within 500 ms");
  // 500 ms after the last queued frame (at most 4 x 40 ms), plus one poll interval.
  EXPECT_LT(Seconds(steady_clock::now() - t0), 0.5 + 0.2 + 0.1);
  const auto t_close = steady_clock::now();
  camera->reset();
  std::printf("releasing a vanished camera took %.3f s\n", Seconds(steady_clock::now() - t_close));
}

TEST(AravisCameraTest, CancelAndDeadlineEndTheWait) {
  auto fake = FakeGigeCamera::Start(kLoopback, "WAIT", RandomImage(64, 48, 4));
  ASSERT_TRUE(fake.ok()) << fake.status();
  auto camera = AravisCamera::Open(OptionsFor(**fake));
  ASSERT_TRUE(camera.ok()) << camera.status();
  std::atomic<bool> cancel{true};
  auto t0 = steady_clock::now();
  EXPECT_EQ((*camera)->Grab(t0 + std::chrono::seconds(5), &cancel).status().code(),
            absl::StatusCode::kCancelled);
  EXPECT_LT(Seconds(steady_clock::now() - t0), 0.1);
  // A deadline already passed.
  t0 = steady_clock::now();
  EXPECT_EQ((*camera)->Grab(t0, nullptr).status().code(), absl::StatusCode::kDeadlineExceeded);
  EXPECT_LT(Seconds(steady_clock::now() - t0), 0.1);
}

TEST(GigeFrameToGreyTest, ConvertsMono8Mono16AndRgb) {
  const std::vector<std::uint8_t> mono8 = {0, 1, 254, 255, 7, 9};
  auto grey = GigeFrameToGrey(kPfncMono8, mono8.data(), mono8.size(), 3, 2);
  ASSERT_TRUE(grey.ok()) << grey.status();
  EXPECT_EQ(grey->pixels, mono8);

  // Little-endian 16-bit: 0, 257 (-> 1), 65535 (-> 255), 128 (0.498 -> 0), 129 (0.502 -> 1).
  const std::vector<std::uint8_t> mono16 = {0, 0, 0x01, 0x01, 0xFF, 0xFF, 128, 0, 129, 0};
  grey = GigeFrameToGrey(kPfncMono16, mono16.data(), mono16.size(), 5, 1);
  ASSERT_TRUE(grey.ok()) << grey.status();
  EXPECT_EQ(grey->pixels, (std::vector<std::uint8_t>{0, 1, 255, 0, 1}));

  // Pure red, green, blue and white: 0.299 * 255 = 76.2, 0.587 * 255 = 149.7, 0.114 * 255 = 29.1.
  const std::vector<std::uint8_t> rgb = {255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255};
  grey = GigeFrameToGrey(kPfncRgb8, rgb.data(), rgb.size(), 4, 1);
  ASSERT_TRUE(grey.ok()) << grey.status();
  EXPECT_EQ(grey->pixels, (std::vector<std::uint8_t>{76, 150, 29, 255}));
  grey = GigeFrameToGrey(kPfncBgr8, rgb.data(), rgb.size(), 4, 1);
  ASSERT_TRUE(grey.ok()) << grey.status();
  EXPECT_EQ(grey->pixels, (std::vector<std::uint8_t>{29, 150, 76, 255}));
}

// A Bayer mosaic of one colour everywhere demosaics to that colour at every pixel, the
// border included: grey = round(0.299 r + 0.587 g + 0.114 b) = round(17.94 + 58.7 + 22.8) = 99.
TEST(GigeFrameToGreyTest, DemosaicsTheFourBayerPatterns) {
  constexpr int kWidth = 6;
  constexpr int kHeight = 4;
  const int r = 60, g = 100, b = 200;
  struct Case {
    std::uint32_t format;
    int cells[4];  // colours of the top-left 2 x 2, row-major
  };
  for (const Case& c : {Case{kPfncBayerRg8, {r, g, g, b}}, Case{kPfncBayerGr8, {g, r, b, g}},
                        Case{kPfncBayerGb8, {g, b, r, g}}, Case{kPfncBayerBg8, {b, g, g, r}}}) {
    std::vector<std::uint8_t> mosaic(kWidth * kHeight);
    for (int y = 0; y < kHeight; ++y) {
      for (int x = 0; x < kWidth; ++x) {
        mosaic[y * kWidth + x] = static_cast<std::uint8_t>(c.cells[2 * (y % 2) + x % 2]);
      }
    }
    auto grey = GigeFrameToGrey(c.format, mosaic.data(), mosaic.size(), kWidth, kHeight);
    ASSERT_TRUE(grey.ok()) << grey.status();
    EXPECT_EQ(grey->pixels, std::vector<std::uint8_t>(kWidth * kHeight, 99))
        << "format 0x" << std::hex << c.format;
  }
  // A grey scene (r = g = b at every pixel, so the mosaic is the scene) with a vertical step
  // between columns 2 and 3: columns whose 3 x 3 neighbourhood lies on one side keep their
  // value exactly, the two beside the step fall in between, rising: no shift of the edge.
  std::vector<std::uint8_t> step(kWidth * kHeight);
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) step[y * kWidth + x] = x < 3 ? 40 : 200;
  }
  auto grey = GigeFrameToGrey(kPfncBayerRg8, step.data(), step.size(), kWidth, kHeight);
  ASSERT_TRUE(grey.ok()) << grey.status();
  for (int y = 0; y < kHeight; ++y) {
    EXPECT_EQ(grey->at(0, y), 40);
    EXPECT_EQ(grey->at(1, y), 40);
    EXPECT_GT(grey->at(2, y), 40);
    EXPECT_LT(grey->at(2, y), grey->at(3, y));
    EXPECT_LT(grey->at(3, y), 200);
    EXPECT_EQ(grey->at(4, y), 200);
    EXPECT_EQ(grey->at(5, y), 200);
  }
}

TEST(GigeFrameToGreyTest, RefusesBadFrames) {
  const std::vector<std::uint8_t> bytes(16, 0);
  // Mono10p (0x010A0046), a packed format, is not converted.
  auto grey = GigeFrameToGrey(0x010A0046, bytes.data(), bytes.size(), 4, 4);
  EXPECT_EQ(grey.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(grey.status().message().find("0x10a0046"), std::string::npos) << grey.status();
  grey = GigeFrameToGrey(kPfncBayerRg8, bytes.data(), bytes.size(), 1, 4);
  EXPECT_EQ(grey.status().message(), "Bayer frame of 1 x 4: needs at least 2 x 2 pixels");
  grey = GigeFrameToGrey(kPfncMono8, bytes.data(), bytes.size(), 5, 4);
  EXPECT_EQ(grey.status().message(), "frame of 5 x 4 needs 20 bytes, got 16");
  grey = GigeFrameToGrey(kPfncMono8, bytes.data(), bytes.size(), kMaxImageSide + 1, 1);
  EXPECT_EQ(grey.status().code(), absl::StatusCode::kInvalidArgument);
  grey = GigeFrameToGrey(kPfncMono8, bytes.data(), bytes.size(), 0, 4);
  EXPECT_EQ(grey.status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace linecal

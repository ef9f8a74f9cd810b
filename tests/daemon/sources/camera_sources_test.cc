// The camera sources end to end: an Aravis source against Aravis's fake GigE camera on
// 127.0.0.1 (resource lock gige_loopback), writing PNG frames into a capture directory.
#include "daemon/sources/camera_sources.h"

#include <atomic>
#include <chrono>
#include <filesystem>
#include <thread>
#include <vector>

#include "daemon/simstation/fake_gige_camera.h"
#include "gtest/gtest.h"
#include "station/io/image_io.h"
#include "tests/daemon/random_image.h"

namespace linecal {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;
using std::chrono::steady_clock;

SensorModel Camera(const std::string& name) {
  SensorModel sensor;
  sensor.name = name;
  sensor.kind = SensorKind::kCamera;
  return sensor;
}

double Seconds(steady_clock::duration d) { return std::chrono::duration<double>(d).count(); }

class CameraSourcesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::path(::testing::TempDir()) /
           ("camera_sources_" +
            std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  AcquireRequest Request(int frames, steady_clock::duration timeout) const {
    AcquireRequest request;
    request.capture_dir = dir_.string();
    request.sensor_dir = "front_camera";
    request.frames = frames;
    request.deadline = steady_clock::now() + timeout;
    return request;
  }

  std::filesystem::path dir_;
};

TEST_F(CameraSourcesTest, AravisSourceWritesTheServedFramesAsPng) {
  const Image8 served = RandomImage(640, 480, 11);
  auto fake = FakeGigeCamera::Start("127.0.0.1", "SRC01", served);
  ASSERT_TRUE(fake.ok()) << fake.status();
  AravisCameraSourceConfig config;
  config.device_id = (*fake)->device_id();
  std::unique_ptr<SensorSource> source = MakeAravisCameraSource(config);
  EXPECT_EQ(source->Describe(), "aravis Aravis-Fake-SRC01");

  AcquireRequest request = Request(3, seconds(10));
  std::vector<std::string> progress;
  request.progress = [&](const std::string& detail) { progress.push_back(detail); };
  const std::int64_t before_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                     std::chrono::system_clock::now().time_since_epoch())
                                     .count();
  absl::StatusOr<CaptureSensor> sensor = source->Acquire(Camera("front_camera"), request);
  ASSERT_TRUE(sensor.ok()) << sensor.status();
  EXPECT_EQ(sensor->name, "front_camera");
  EXPECT_EQ(sensor->kind, SensorKind::kCamera);
  EXPECT_FALSE(sensor->packets.has_value());
  ASSERT_EQ(sensor->frames.size(), 3u);
  EXPECT_EQ(progress, (std::vector<std::string>{"frame 1/3", "frame 2/3", "frame 3/3"}));
  std::int64_t last_ns = before_ns;
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(sensor->frames[k].path, "front_camera/frame_" + std::to_string(k) + ".png");
    // Frames of a 25 frames/s camera: later than the call, each after the one before.
    EXPECT_GT(sensor->frames[k].t_ns, last_ns);
    last_ns = sensor->frames[k].t_ns;
    absl::StatusOr<Image8> png = ReadImage8((dir_ / sensor->frames[k].path).string());
    ASSERT_TRUE(png.ok()) << png.status();
    EXPECT_EQ(png->width, 640);
    EXPECT_EQ(png->height, 480);
    EXPECT_TRUE(png->pixels == served.pixels) << "frame " << k;
  }
}

TEST_F(CameraSourcesTest, AbsentCameraIsUnavailable) {
  AravisCameraSourceConfig config;
  config.device_id = "Aravis-Fake-NOBODY";
  absl::StatusOr<CaptureSensor> sensor =
      MakeAravisCameraSource(config)->Acquire(Camera("front_camera"), Request(1, seconds(10)));
  EXPECT_EQ(sensor.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(sensor.status().message(), "camera 'Aravis-Fake-NOBODY' not found");
}

TEST_F(CameraSourcesTest, NonCameraSensorIsInvalidArgument) {
  SensorModel lidar = Camera("roof_lidar");
  lidar.kind = SensorKind::kLidar;
  AravisCameraSourceConfig aravis;
  aravis.device_id = "Aravis-Fake-UNUSED";
  absl::StatusOr<CaptureSensor> sensor =
      MakeAravisCameraSource(aravis)->Acquire(lidar, Request(1, seconds(10)));
  EXPECT_EQ(sensor.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(sensor.status().message(),
            "sensor 'roof_lidar' is a lidar; aravis Aravis-Fake-UNUSED serves cameras only");
  sensor = MakeV4l2CameraSource(V4l2CameraSourceConfig{})->Acquire(lidar, Request(1, seconds(10)));
  EXPECT_EQ(sensor.status().code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(CameraSourcesTest, CancelEndsTheAcquisitionWithinHalfASecond) {
  auto fake = FakeGigeCamera::Start("127.0.0.1", "CANCEL", RandomImage(64, 48, 1));
  ASSERT_TRUE(fake.ok()) << fake.status();
  AravisCameraSourceConfig config;
  config.device_id = (*fake)->device_id();
  std::unique_ptr<SensorSource> source = MakeAravisCameraSource(config);
  std::atomic<bool> cancel{false};
  AcquireRequest request = Request(100000, seconds(30));
  request.cancel = &cancel;
  std::atomic<int> frames{0};
  request.progress = [&](const std::string&) { ++frames; };
  steady_clock::time_point cancelled_at;
  std::atomic<bool> returned{false};  // the canceller must not outwait a failed acquisition
  std::thread canceller([&] {
    while (frames.load() < 2 && !returned) std::this_thread::sleep_for(milliseconds(5));
    cancelled_at = steady_clock::now();
    cancel = true;
  });
  absl::StatusOr<CaptureSensor> sensor = source->Acquire(Camera("front_camera"), request);
  const auto returned_at = steady_clock::now();
  returned = true;
  canceller.join();
  EXPECT_EQ(sensor.status().code(), absl::StatusCode::kCancelled);
  EXPECT_LT(Seconds(returned_at - cancelled_at), 0.5);
}

TEST_F(CameraSourcesTest, DeadlineEndsTheAcquisition) {
  auto fake = FakeGigeCamera::Start("127.0.0.1", "DEADLINE", RandomImage(64, 48, 1));
  ASSERT_TRUE(fake.ok()) << fake.status();
  AravisCameraSourceConfig config;
  config.device_id = (*fake)->device_id();
  std::unique_ptr<SensorSource> source = MakeAravisCameraSource(config);
  // More frames than 25 frames/s deliver in 1.5 s.
  AcquireRequest request = Request(1000, milliseconds(1500));
  absl::StatusOr<CaptureSensor> sensor = source->Acquire(Camera("front_camera"), request);
  const double late_s = Seconds(steady_clock::now() - request.deadline);
  EXPECT_EQ(sensor.status().code(), absl::StatusCode::kDeadlineExceeded);
  EXPECT_NE(sensor.status().message().find("deadline passed"), std::string::npos)
      << sensor.status();
  EXPECT_GE(late_s, 0.0);
  EXPECT_LT(late_s, 0.2);  // one 50 ms poll interval, with margin for a loaded machine
}

TEST_F(CameraSourcesTest, CameraVanishingMidAcquisitionEndsItByTheDeadline) {
  auto fake = FakeGigeCamera::Start("127.0.0.1", "VANISH2", RandomImage(64, 48, 1));
  ASSERT_TRUE(fake.ok()) << fake.status();
  AravisCameraSourceConfig config;
  config.device_id = (*fake)->device_id();
  std::unique_ptr<SensorSource> source = MakeAravisCameraSource(config);
  AcquireRequest request = Request(1000, seconds(2));
  std::atomic<int> frames{0};
  request.progress = [&](const std::string&) { ++frames; };
  std::thread killer([&] {
    while (frames.load() < 3) std::this_thread::sleep_for(milliseconds(5));
    fake->reset();
  });
  absl::StatusOr<CaptureSensor> sensor = source->Acquire(Camera("front_camera"), request);
  const double late_s = Seconds(steady_clock::now() - request.deadline);
  killer.join();
  EXPECT_EQ(sensor.status().code(), absl::StatusCode::kDeadlineExceeded);
  EXPECT_LT(late_s, 1.0);
  // The source's destructor waits for the vanished camera's release.
  const auto t0 = steady_clock::now();
  source.reset();
  std::printf("source returned %.3f s after its deadline; release took %.3f s more\n", late_s,
              Seconds(steady_clock::now() - t0));
}

TEST(CameraSourceConfigTest, ValidateNamesTheField) {
  AravisCameraSourceConfig aravis;
  EXPECT_EQ(aravis.Validate().message(), "device_id: empty");
  aravis.device_id = "Basler-1";
  EXPECT_TRUE(aravis.Validate().ok());
  aravis.frame_retries = -1;
  EXPECT_EQ(aravis.Validate().message(), "frame_retries: must be >= 0, got -1");
  aravis.frame_retries = 0;
  aravis.frame_timeout = milliseconds(0);
  EXPECT_EQ(aravis.Validate().message(), "frame_timeout: must be > 0 ms, got 0");
  aravis.frame_timeout = milliseconds(10);
  aravis.exposure_us = -5;
  EXPECT_EQ(aravis.Validate().code(), absl::StatusCode::kInvalidArgument);

  V4l2CameraSourceConfig v4l2;
  EXPECT_TRUE(v4l2.Validate().ok());
  v4l2.pixel_format = "MJPG";
  EXPECT_EQ(v4l2.Validate().message(), "pixel_format: pixel format 'MJPG': must be GREY or YUYV");
  v4l2.pixel_format = "YUYV";
  v4l2.width = 640;
  EXPECT_EQ(v4l2.Validate().code(), absl::StatusCode::kInvalidArgument);
  v4l2.height = 480;
  EXPECT_TRUE(v4l2.Validate().ok());
}

TEST_F(CameraSourcesTest, V4l2SourceOnANonV4l2DeviceIsUnavailable) {
  V4l2CameraSourceConfig config;
  config.device = "/dev/null";
  std::unique_ptr<SensorSource> source = MakeV4l2CameraSource(config);
  EXPECT_EQ(source->Describe(), "v4l2 /dev/null");
  absl::StatusOr<CaptureSensor> sensor =
      source->Acquire(Camera("front_camera"), Request(1, seconds(5)));
  EXPECT_EQ(sensor.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(sensor.status().message(), "/dev/null: not a V4L2 device");
}

}  // namespace
}  // namespace linecal

// Several GigE cameras acquired at once, as a cycle does: five of Aravis's fake cameras on
// 127.0.0.1-5 (the reference car's sizes, each serving its own random image), each opened and
// grabbed on its own thread, many rounds. Every frame must be its own camera's image, pixel
// for pixel (docs/sensors.md, "Several cameras at once"). Needs the loopback aliases
// 127.0.0.2-5: added here when missing and the process may (root), removed again at the end;
// skipped otherwise. ctest serialises it with the other fake-camera tests (gige_loopback).
#include <arpa/inet.h>
#include <ifaddrs.h>
#include <netinet/in.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "daemon/drivers/aravis_camera.h"
#include "daemon/simstation/fake_gige_camera.h"
#include "gtest/gtest.h"
#include "tests/daemon/random_image.h"

namespace linecal {
namespace {

using std::chrono::steady_clock;

constexpr int kCameras = 5;
// Rounds of open, grab, close on all cameras at once; each round is a cycle's acquisition.
constexpr int kRounds = 25;
constexpr int kFramesPerRound = 2;

std::string AddressOf(int camera) { return "127.0.0." + std::to_string(camera + 1); }

bool HasLocalAddress(const std::string& address) {
  ifaddrs* list = nullptr;
  if (getifaddrs(&list) != 0) return false;
  bool found = false;
  for (ifaddrs* i = list; i != nullptr && !found; i = i->ifa_next) {
    if (i->ifa_addr == nullptr || i->ifa_addr->sa_family != AF_INET) continue;
    char text[INET_ADDRSTRLEN] = "";
    const auto* in = reinterpret_cast<const sockaddr_in*>(i->ifa_addr);
    found = inet_ntop(AF_INET, &in->sin_addr, text, sizeof text) != nullptr && address == text;
  }
  freeifaddrs(list);
  return found;
}

class AravisConcurrentTest : public testing::Test {
 protected:
  static void SetUpTestSuite() {
    for (int k = 1; k < kCameras; ++k) {
      const std::string address = AddressOf(k);
      if (HasLocalAddress(address)) continue;
      const std::string add = "ip addr add " + address + "/8 dev lo 2>/dev/null";
      if (std::system(add.c_str()) == 0 && HasLocalAddress(address)) added_.push_back(address);
    }
  }
  static void TearDownTestSuite() {
    for (const std::string& address : added_) {
      const std::string del = "ip addr del " + address + "/8 dev lo 2>/dev/null";
      if (std::system(del.c_str()) != 0) {
        std::fprintf(stderr, "could not remove %s from lo\n", address.c_str());
      }
    }
    added_.clear();
  }
  void SetUp() override {
    for (int k = 1; k < kCameras; ++k) {
      if (!HasLocalAddress(AddressOf(k))) {
        GTEST_SKIP() << "needs the loopback aliases 127.0.0.2-5 (ip addr add ... dev lo, root)";
      }
    }
  }

  static std::vector<std::string> added_;
};

std::vector<std::string> AravisConcurrentTest::added_;

// What one camera's thread saw in a round.
struct RoundResult {
  std::string error;     // the first failed Open or Grab, empty if none
  int wrong_frames = 0;  // complete frames that were not this camera's image
  int incomplete = 0;    // incomplete frames dropped and grabbed again
};

RoundResult AcquireOnce(const FakeGigeCamera& fake, const Image8& served) {
  RoundResult result;
  AravisCameraOptions options;
  options.device_id = fake.device_id();
  // As linecal serve-sensors configures its fake cameras' sources: the first frame after the
  // start of a stream arrives incomplete on loopback (docs/sensors.md).
  options.frame_retries = 10;
  absl::StatusOr<std::unique_ptr<AravisCamera>> camera = AravisCamera::Open(options);
  if (!camera.ok()) {
    result.error = camera.status().ToString();
    return result;
  }
  for (int k = 0; k < kFramesPerRound; ++k) {
    absl::StatusOr<CameraFrame> frame =
        (*camera)->Grab(steady_clock::now() + std::chrono::seconds(5), nullptr);
    if (!frame.ok()) {
      result.error = frame.status().ToString();
      break;
    }
    if (frame->image.width != served.width || frame->image.height != served.height ||
        frame->image.pixels != served.pixels) {
      ++result.wrong_frames;
    }
  }
  result.incomplete = (*camera)->incomplete_frames();
  return result;
}

TEST_F(AravisConcurrentTest, CamerasAcquiredAtOnceEachGetTheirOwnFrames) {
  std::vector<Image8> served;
  std::vector<std::unique_ptr<FakeGigeCamera>> fakes;
  for (int k = 0; k < kCameras; ++k) {
    // The reference car: a 1920 x 1080 front camera and four 1280 x 960 surround cameras; a
    // random image per camera, so a frame holding any packet of another camera differs.
    served.push_back(k == 0 ? RandomImage(1920, 1080, 100 + k) : RandomImage(1280, 960, 100 + k));
    absl::StatusOr<std::unique_ptr<FakeGigeCamera>> fake = FakeGigeCamera::Start(
        AddressOf(k), "CONC" + std::to_string(k + 1), served.back(), 0.0, 10.0);
    ASSERT_TRUE(fake.ok()) << fake.status();
    fakes.push_back(*std::move(fake));
  }
  int incomplete = 0;
  double slowest_round_s = 0;
  for (int round = 0; round < kRounds; ++round) {
    std::vector<RoundResult> results(kCameras);
    std::vector<std::thread> threads;
    const auto t0 = steady_clock::now();
    for (int k = 0; k < kCameras; ++k) {
      threads.emplace_back([&, k] { results[k] = AcquireOnce(*fakes[k], served[k]); });
    }
    for (std::thread& t : threads) t.join();
    slowest_round_s =
        std::max(slowest_round_s, std::chrono::duration<double>(steady_clock::now() - t0).count());
    for (int k = 0; k < kCameras; ++k) {
      EXPECT_EQ(results[k].error, "") << "round " << round << ", camera " << AddressOf(k);
      EXPECT_EQ(results[k].wrong_frames, 0) << "round " << round << ", camera " << AddressOf(k);
      incomplete += results[k].incomplete;
    }
  }
  // For docs/sensors.md: what the retries absorbed, and how long a round took at most.
  std::printf(
      "%d rounds x %d cameras x %d frames: %d incomplete frames retried; slowest round "
      "%.3f s\n",
      kRounds, kCameras, kFramesPerRound, incomplete, slowest_round_s);
}

}  // namespace
}  // namespace linecal

// The boards of a camera frame as a cycle detects them (DetectCameraFrame), against the
// simulator's exact feature positions.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "station/capture/capture.h"
#include "station/io/image_io.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/pipeline/capture_calibration.h"
#include "station/sim/simulator.h"
#include "tests/support/scoped_path.h"

namespace linecal {
namespace {

// The mean offset along u of the front camera's `front_vertical` L-corners from the truth, over
// one capture of `seed` (noise 2 grey levels, blur 0.5 px, as issue 20's captures); adds the
// corners counted to `corners`.
double FrontVerticalLCornerOffsetU(std::uint64_t seed, int* corners) {
  const auto station =
      ReadStationLayout(std::string(LINECAL_SOURCE_DIR) + "/deploy/stations/reference.json");
  const auto car = ReadCarModel(std::string(LINECAL_SOURCE_DIR) + "/deploy/cars/reference.json");
  EXPECT_TRUE(station.ok() && car.ok());
  testing_support::ScopedPath dir("detect_camera_frame_" + std::to_string(seed));
  SimulatorOptions o;
  o.sensors = {"front_camera"};
  o.camera.noise_sigma = 2;
  o.camera.blur_sigma_px = 0.5;
  const absl::StatusOr<SimulationSummary> sim =
      SimulateCapture(*station, *car, o, seed, dir.string());
  EXPECT_TRUE(sim.ok()) << sim.status();
  const absl::StatusOr<Capture> capture = ReadCapture(dir.string());
  EXPECT_TRUE(capture.ok()) << capture.status();
  if (!sim.ok() || !capture.ok()) return NAN;
  const SensorModel& sensor = *capture->car.FindSensor("front_camera");
  const absl::StatusOr<Image8> image =
      ReadImage8(capture->PathOf(capture->manifest.sensors[0].frames[0]));
  EXPECT_TRUE(image.ok());
  if (!image.ok()) return NAN;
  std::vector<BoardDetectionSummary> summaries(sensor.targets.size());
  const Board& board = capture->station.FindBoard("front_vertical")->board;
  double sum = 0;
  int n = 0;
  for (const BoardObservation& o : DetectCameraFrame(*capture, sensor, image->view(), &summaries)) {
    if (o.board_id != "front_vertical") continue;
    for (const DetectedFeature& f : o.features) {
      if (board.features()[f.id].kind != FeatureKind::kLCorner) continue;
      for (const auto& t : sim->ground_truth["sensors"][0]["frames"][0]["features"]) {
        if (t["board"] == "front_vertical" && t["id"] == f.id) {
          sum += f.uv_px.x() - t["u"].get<double>();
          ++n;
        }
      }
    }
  }
  *corners += n;
  return n > 0 ? sum / n : NAN;
}

// The front camera's vertical board (issue 20): its L-corners are fits of the squares' edge
// lines, and in the raw image of the front camera's lens (k1 −0.12) they came out 0.006 px left
// of the truth on average on every capture, a fixed pattern that moved x by half its σ on every
// car (docs/solvers.md, "Where the front camera's tails ... come from"). Found in the board's
// perspective view, as a fisheye camera's boards are, they sit on the truth. A capture's mean
// scatters by about 0.012 px (its corners share the board's error), so 30 captures (34 L-corners
// each) measure it to about 0.002 px: −0.0017 px from the views, −0.0077 px in the raw image
// (the test fails), the bound between them.
TEST(DetectCameraFrame, FrontVerticalLCornersSitOnTheTruth) {
  double sum = 0;
  int corners = 0;
  for (std::uint64_t seed = 1; seed <= 30; ++seed) {
    const double mean = FrontVerticalLCornerOffsetU(seed, &corners);
    std::printf("seed %d: mean u offset %.4f px\n", static_cast<int>(seed), mean);
    sum += mean;
  }
  EXPECT_EQ(corners, 30 * 34);
  std::printf("mean over seeds %.4f\n", sum / 30);
  EXPECT_LT(std::abs(sum / 30), 0.0045);
}

}  // namespace
}  // namespace linecal

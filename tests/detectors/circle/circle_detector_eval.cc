// Circle board detector evaluation over a grid of renders (acceptance.md's detector test
// set at 1280 x 720): distance 1.3 / 2.5 / 4.2 m (board 70% of the image width down to
// circles 12.5 px across), roll -30 / 0 / 30, seven yaw-pitch pairs up to 50 degrees, each
// rendered clean (noise 0, blur 0.5), at noise 4 + blur 1.0, and with the hardest effects
// (noise 6, blur 1.5, a 4:1 gradient, gamma 0.6 or 1.6, JPEG 80, clutter). Prints the
// detection rate, the feature RMS error per set and every miss. Built with the tests, run
// by hand: build-dir/bin/circle_detector_eval
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <vector>

#include "detectors/circle/circle_detector.h"
#include "tests/detectors/circle/circle_scene.h"

namespace linecal {
namespace {

using circle_scene::Pose;

struct EffectSet {
  const char* name;
  double noise;
  double blur;
  bool hard;
};

struct Tally {
  int frames = 0;
  int found = 0;
  int wrong = 0;  // found, but a feature off by more than a pitch: a wrong identification
  std::vector<double> rms_px;
};

int Run() {
  const std::array<EffectSet, 3> sets = {EffectSet{"clean (noise 0, blur 0.5)", 0.0, 0.5, false},
                                         EffectSet{"noise 4, blur 1.0", 4.0, 1.0, false},
                                         EffectSet{"noise 6, blur 1.5, hard", 6.0, 1.5, true}};
  const std::array<std::array<double, 2>, 7> yaw_pitch = {
      {{0, 0}, {50, 0}, {-50, 0}, {0, 50}, {0, -50}, {35, 35}, {-35, -35}}};
  std::array<Tally, 3> tally;
  std::uint64_t seed = 1;
  for (const double distance : {1.3, 2.5, 4.2}) {
    for (const double roll : {-30.0, 0.0, 30.0}) {
      for (const auto& [yaw, pitch] : yaw_pitch) {
        for (std::size_t s = 0; s < sets.size(); ++s) {
          const Pose pose{distance,
                          yaw,
                          pitch,
                          roll,
                          0.05 * static_cast<double>(seed % 5) - 0.1,
                          0.03 * static_cast<double>(seed % 3) - 0.03};
          CameraRenderOptions o = circle_scene::Effects(sets[s].noise, sets[s].blur);
          if (sets[s].hard) {
            o.illumination_gradient_ratio = 4.0;
            o.illumination_gradient_direction_deg = 37.0 * static_cast<double>(seed);
            o.gamma = seed % 2 == 0 ? 0.6 : 1.6;
            o.jpeg_quality = 80;
            o.clutter = true;
          }
          const absl::StatusOr<CameraFrame> frame = circle_scene::RenderScene(
              circle_scene::OneBoard(BoardType::kCircle, pose), o, seed++);
          if (!frame.ok()) {
            std::fprintf(stderr, "render: %s\n", frame.status().ToString().c_str());
            return 2;
          }
          if (frame->features.size() != 30) continue;  // not wholly in view
          const Detection d = DetectCircleBoard(frame->image8.view(), circle_scene::CircleBoard());
          Tally& t = tally[s];
          ++t.frames;
          if (!d.found) {
            std::printf("miss: %s, distance %.1f roll %.0f yaw %.0f pitch %.0f: %s\n", sets[s].name,
                        distance, roll, yaw, pitch, DetectReasonName(d.reason));
            continue;
          }
          ++t.found;
          double sum2 = 0.0;
          double worst = 0.0;
          for (int id = 0; id < 30; ++id) {
            const double e = (d.features[id].uv_px - frame->features[id].uv_px).norm();
            sum2 += e * e;
            worst = std::max(worst, e);
          }
          // Neighbouring circles are at least 2.8 radii (12 px at the smallest) apart.
          if (worst > 5.0) ++t.wrong;
          t.rms_px.push_back(std::sqrt(sum2 / 30.0));
          // Frames far over the noisy bar (0.12 px) are worth a look.
          if (t.rms_px.back() > 0.25) {
            std::printf(
                "outlier: %s, distance %.1f roll %.0f yaw %.0f pitch %.0f: RMS %.3f px, "
                "worst %.3f px\n",
                sets[s].name, distance, roll, yaw, pitch, t.rms_px.back(), worst);
          }
        }
      }
    }
  }
  std::printf("\n| set | frames | found | rate | wrong ids | median RMS px | max RMS px |\n");
  std::printf("| --- | --- | --- | --- | --- | --- | --- |\n");
  for (std::size_t s = 0; s < sets.size(); ++s) {
    Tally& t = tally[s];
    std::sort(t.rms_px.begin(), t.rms_px.end());
    const double median = t.rms_px.empty() ? 0.0 : t.rms_px[t.rms_px.size() / 2];
    const double max = t.rms_px.empty() ? 0.0 : t.rms_px.back();
    std::printf("| %s | %d | %d | %.1f%% | %d | %.4f | %.4f |\n", sets[s].name, t.frames, t.found,
                100.0 * t.found / std::max(1, t.frames), t.wrong, median, max);
  }
  return 0;
}

}  // namespace
}  // namespace linecal

int main() { return linecal::Run(); }

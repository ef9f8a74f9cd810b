#include "station/sim/radar_sim.h"

#include <cmath>
#include <numbers>
#include <random>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
// Cycle times: ARS408-21 cluster list about every 72 ms, ESR scans every 50 ms (data sheets).
constexpr std::chrono::milliseconds kArs408CycleTime{72};
constexpr std::chrono::milliseconds kEsrCycleTime{50};
// Clutter is weak: floor returns, stands and people sit at -10..5 dBm², below a reflector's
// 10..30 dBm².
constexpr double kClutterRcsMinDbsm = -10.0;
constexpr double kClutterRcsMaxDbsm = 5.0;
// A multipath ghost arrives 10-20 dB below the reflector it mirrors.
constexpr double kGhostLossMinDb = 10.0;
constexpr double kGhostLossMaxDb = 20.0;
// About a third of the clutter moves (people, the next car on the line) at up to 3 m/s.
constexpr double kMovingClutterShare = 0.3;
constexpr double kMaxClutterSpeedMps = 3.0;
// The ESR reports at most 64 tracks; ARS408 clusters carry an 8-bit id.
constexpr size_t kEsrMaxTracks = 64;
constexpr size_t kArs408MaxClusters = 250;

absl::Status CheckRange(const char* field, double v, double lo, double hi) {
  if (!(v >= lo && v <= hi)) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, " = ", v, ": must be in [", lo, ", ", hi, "]"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status RadarSimOptions::Validate() const {
  if (cycles < 1 || cycles > 10000) {
    return absl::InvalidArgumentError(absl::StrCat("cycles = ", cycles, ": must be in [1, 10000]"));
  }
  if (auto s = CheckRange("range_sigma_m", range_sigma_m, 0, 5); !s.ok()) return s;
  if (auto s = CheckRange("azimuth_sigma_deg", azimuth_sigma_deg, 0, 10); !s.ok()) return s;
  if (auto s = CheckRange("rcs_sigma_db", rcs_sigma_db, 0, 20); !s.ok()) return s;
  if (auto s = CheckRange("range_rate_sigma_mps", range_rate_sigma_mps, 0, 5); !s.ok()) return s;
  if (!(detection_probability > 0 && detection_probability <= 1)) {
    return absl::InvalidArgumentError(
        absl::StrCat("detection_probability = ", detection_probability, ": must be in (0, 1]"));
  }
  if (clutter_per_cycle < 0 || clutter_per_cycle > 200) {
    return absl::InvalidArgumentError(
        absl::StrCat("clutter_per_cycle = ", clutter_per_cycle, ": must be in [0, 200]"));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::vector<CanFrame>> SimulateRadar(const std::string& model, int sensor_id,
                                                    const StationLayout& layout,
                                                    const Rigid3d& T_station_radar, CanTime start,
                                                    const std::string& interface,
                                                    const RadarSimOptions& options,
                                                    std::uint64_t seed) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  const std::optional<RadarFieldOfView> fov = RadarFieldOfViewOf(model);
  if (!fov) return absl::InvalidArgumentError(absl::StrCat("unknown radar model '", model, "'"));
  const bool esr = model == "esr";
  const std::vector<RadarTruth> truth = RadarReflectorTruth(layout, T_station_radar, *fov);
  std::vector<double> rcs;
  for (const CornerReflector& r : layout.reflectors) rcs.push_back(r.rcs_dbsm);

  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const RadarConventions conventions;
  std::vector<CanFrame> frames;
  const auto cycle_time =
      esr ? std::chrono::duration_cast<std::chrono::nanoseconds>(kEsrCycleTime)
          : std::chrono::duration_cast<std::chrono::nanoseconds>(kArs408CycleTime);
  for (int c = 0; c < options.cycles; ++c) {
    RadarCycle cycle;
    cycle.time = start + c * cycle_time;
    cycle.sensor_id = esr ? 0 : sensor_id;
    cycle.kind = esr ? RadarDetectionKind::kTrack : RadarDetectionKind::kCluster;
    cycle.counter = static_cast<std::uint32_t>(c);
    std::vector<RadarDetection> dets;
    const auto add = [&](double range, double azimuth, double rate,
                         std::optional<double> rcs_dbsm) {
      RadarDetection d;
      d.kind = cycle.kind;
      d.range_m = range;
      d.azimuth_rad = azimuth;
      d.range_rate_mps = rate;
      if (!esr) d.rcs_dbsm = rcs_dbsm;
      dets.push_back(d);
    };
    for (size_t i = 0; i < truth.size(); ++i) {
      const RadarTruth& t = truth[i];
      if (!t.in_view || uniform(rng) > options.detection_probability) continue;
      // Draws in named steps: the order of a call's arguments is unspecified, and the same
      // seed must give the same log whatever the compiler.
      const double range_noise = options.range_sigma_m * normal(rng);
      const double azimuth_noise = options.azimuth_sigma_deg * kDegToRad * normal(rng);
      const double rate_noise = options.range_rate_sigma_mps * normal(rng);
      const double rcs_noise = options.rcs_sigma_db * normal(rng);
      add(t.range_m + range_noise, t.azimuth_rad + azimuth_noise, rate_noise, rcs[i] + rcs_noise);
      if (options.multipath) {
        const double ghost_range = t.range_m * (1.3 + 0.5 * uniform(rng));
        if (ghost_range <= fov->max_range_m) {
          const double ghost_azimuth_noise = options.azimuth_sigma_deg * kDegToRad * normal(rng);
          const double ghost_rate_noise = options.range_rate_sigma_mps * normal(rng);
          const double ghost_loss_db =
              kGhostLossMinDb + (kGhostLossMaxDb - kGhostLossMinDb) * uniform(rng);
          add(ghost_range, t.azimuth_rad + ghost_azimuth_noise, ghost_rate_noise,
              rcs[i] - ghost_loss_db);
        }
      }
    }
    for (int k = 0; k < options.clutter_per_cycle; ++k) {
      // Clutter spreads over the field of view, from 1 m (closer is the bumper's blind zone)
      // to the station's far end.
      constexpr double kClutterMinRangeM = 1.0;
      constexpr double kClutterMaxRangeM = 30.0;
      const double range =
          kClutterMinRangeM + (kClutterMaxRangeM - kClutterMinRangeM) * uniform(rng);
      const double azimuth = (2 * uniform(rng) - 1) * fov->half_fov_rad;
      const double rate = uniform(rng) < kMovingClutterShare
                              ? (2 * uniform(rng) - 1) * kMaxClutterSpeedMps
                              : options.range_rate_sigma_mps * normal(rng);
      add(range, azimuth, rate,
          kClutterRcsMinDbsm + (kClutterRcsMaxDbsm - kClutterRcsMinDbsm) * uniform(rng));
    }
    // A sensor's list holds at most this many entries; the reflectors come first.
    dets.resize(std::min(dets.size(), esr ? kEsrMaxTracks : kArs408MaxClusters));
    for (size_t i = 0; i < dets.size(); ++i)
      dets[i].id = esr ? static_cast<int>(i) + 1 : static_cast<int>(i);
    cycle.detections = std::move(dets);
    cycle.messages_expected = static_cast<int>(cycle.detections.size());
    absl::StatusOr<std::vector<CanFrame>> encoded =
        esr ? EncodeEsrScan(cycle, interface, conventions)
            : EncodeArs408Cycle(cycle, interface, conventions);
    if (!encoded.ok()) return encoded.status();
    frames.insert(frames.end(), encoded->begin(), encoded->end());
  }
  return frames;
}

}  // namespace linecal

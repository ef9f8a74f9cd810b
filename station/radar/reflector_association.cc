#include "station/radar/reflector_association.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
// 1.4826 x MAD estimates σ for Gaussian data (1 / Φ⁻¹(3/4)).
constexpr double kMadToSigma = 1.4826;
// The nearest a station reflector stands to a radar (docs/station-and-car.md: reflectors at
// 4..15 m); converts a lateral position tolerance or step into an azimuth margin.
constexpr double kNearestReflectorRangeM = 4.0;

double Median(std::vector<double> v) {
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  const double upper = v[mid];
  if (v.size() % 2 == 1) return upper;
  return 0.5 * (upper + *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid)));
}

// Median absolute deviation from `centre`.
double Mad(const std::vector<double>& v, double centre) {
  std::vector<double> d;
  d.reserve(v.size());
  for (double x : v) d.push_back(std::abs(x - centre));
  return Median(std::move(d));
}

// The RMS bias left by rounding to `step` when the value carries Gaussian noise σ, over all
// positions of the true value within a step: step/√12 without noise, falling as
// exp(−2π²σ²/step²) (the first Fourier harmonic of the rounding error) once noise dithers it.
double UnditheredBias(double step, double sigma) {
  if (step <= 0) return 0;
  const double r = sigma / step;
  return step / std::sqrt(12.0) * std::exp(-2 * std::numbers::pi * std::numbers::pi * r * r);
}

double WrapAngle(double a) { return std::remainder(a, 2 * std::numbers::pi); }

struct Candidate {
  double range_m;
  double azimuth_rad;
};

}  // namespace

std::optional<RadarResolution> RadarResolutionOf(const std::string& model) {
  // The factors of the position signals in radar_format.h.
  if (model == "ars408") {
    return RadarResolution{ars408::kClusterDistLong.factor, ars408::kClusterDistLong.offset, 0, 0};
  }
  if (model == "esr") {
    return RadarResolution{0, 0, esr::kTrackRange.factor, esr::kTrackAngle.factor * kDegToRad};
  }
  return std::nullopt;
}

absl::StatusOr<std::vector<ExpectedReflector>> ExpectedReflectors(const SensorModel& sensor,
                                                                  const StationLayout& layout,
                                                                  const Rigid3d& T_station_car) {
  if (sensor.kind != SensorKind::kRadar) {
    return absl::InvalidArgumentError(absl::StrCat("sensor '", sensor.name, "' is a ",
                                                   SensorKindName(sensor.kind), ", not a radar"));
  }
  const std::optional<RadarFieldOfView> fov = RadarFieldOfViewOf(sensor.model);
  if (!fov) {
    return absl::InvalidArgumentError(
        absl::StrCat("sensor '", sensor.name, "': unknown radar model '", sensor.model, "'"));
  }
  const Rigid3d T_station_radar = T_station_car * sensor.T_car_sensor_nominal;
  const Rigid3d T_car_station = T_station_car.Inverse();
  const std::vector<RadarTruth> seen = RadarReflectorTruth(layout, T_station_radar, *fov);
  std::vector<ExpectedReflector> out;
  for (const std::string& id : sensor.targets) {
    const auto it = std::find_if(layout.reflectors.begin(), layout.reflectors.end(),
                                 [&](const CornerReflector& r) { return r.id == id; });
    if (it == layout.reflectors.end()) {
      return absl::NotFoundError(absl::StrCat("sensor '", sensor.name, "': target reflector '", id,
                                              "' is not in station layout '", layout.name, "'"));
    }
    const RadarTruth& t = seen[static_cast<size_t>(it - layout.reflectors.begin())];
    out.push_back({id, T_car_station * it->p_station, t.range_m, t.azimuth_rad, t.in_view});
  }
  return out;
}

absl::Status ReflectorAssociationOptions::Validate() const {
  const auto positive = [](const char* field, double v) -> absl::Status {
    if (std::isfinite(v) && v > 0) return absl::OkStatus();
    return absl::InvalidArgumentError(absl::StrCat(field, " = ", v, ": must be finite and > 0"));
  };
  const auto non_negative = [](const char* field, double v) -> absl::Status {
    if (std::isfinite(v) && v >= 0) return absl::OkStatus();
    return absl::InvalidArgumentError(absl::StrCat(field, " = ", v, ": must be finite and >= 0"));
  };
  if (auto s = positive("azimuth_gate_rad", azimuth_gate_rad); !s.ok()) return s;
  if (azimuth_gate_rad >= std::numbers::pi / 2) {
    return absl::InvalidArgumentError(
        absl::StrCat("azimuth_gate_rad = ", azimuth_gate_rad, ": must be below pi/2"));
  }
  if (auto s = positive("range_gate_m", range_gate_m); !s.ok()) return s;
  if (!std::isfinite(min_rcs_dbsm)) {
    return absl::InvalidArgumentError(
        absl::StrCat("min_rcs_dbsm = ", min_rcs_dbsm, ": must be finite"));
  }
  if (auto s = positive("max_abs_range_rate_mps", max_abs_range_rate_mps); !s.ok()) return s;
  if (min_detections < 2) {
    return absl::InvalidArgumentError(
        absl::StrCat("min_detections = ", min_detections, ": must be >= 2 (a scatter needs two)"));
  }
  if (auto s = non_negative("ambiguity_range_m", ambiguity_range_m); !s.ok()) return s;
  if (auto s = positive("outlier_z", outlier_z); !s.ok()) return s;
  if (auto s = positive("detection_azimuth_sigma_rad", detection_azimuth_sigma_rad); !s.ok()) {
    return s;
  }
  if (auto s = positive("detection_range_sigma_m", detection_range_sigma_m); !s.ok()) return s;
  if (auto s = non_negative("resolution.position_step_m", resolution.position_step_m); !s.ok()) {
    return s;
  }
  if (auto s = non_negative("resolution.range_step_m", resolution.range_step_m); !s.ok()) return s;
  if (auto s = non_negative("resolution.azimuth_step_rad", resolution.azimuth_step_rad); !s.ok()) {
    return s;
  }
  return absl::OkStatus();
}

absl::StatusOr<ReflectorAssociationOptions> ReflectorAssociationOptions::ForSensor(
    const SensorModel& sensor) {
  if (sensor.kind != SensorKind::kRadar) {
    return absl::InvalidArgumentError(absl::StrCat("sensor '", sensor.name, "' is not a radar"));
  }
  const std::optional<RadarResolution> resolution = RadarResolutionOf(sensor.model);
  if (!resolution) {
    return absl::InvalidArgumentError(
        absl::StrCat("sensor '", sensor.name, "': unknown radar model '", sensor.model, "'"));
  }
  ReflectorAssociationOptions o;
  o.resolution = *resolution;
  const double lateral_tolerance_m = sensor.tolerance.xyz_m.head<2>().norm();
  // Twice the yaw tolerance so that out-of-tolerance mountings are measured and judged
  // rather than lost; 3σ of the noise; the position tolerance and half a resolution step as
  // azimuth at the nearest reflector.
  o.azimuth_gate_rad =
      2 * sensor.tolerance.yaw_rad + 3 * o.detection_azimuth_sigma_rad +
      (lateral_tolerance_m + 0.5 * resolution->position_step_m) / kNearestReflectorRangeM +
      resolution->azimuth_step_rad;
  // The range does not depend on the mounting angles: the position tolerance, 3σ of the range
  // noise and one resolution step.
  o.range_gate_m = sensor.tolerance.xyz_m.norm() + 3 * o.detection_range_sigma_m +
                   resolution->position_step_m + resolution->range_step_m;
  return o;
}

const char* ReflectorStatusName(ReflectorStatus status) {
  switch (status) {
    case ReflectorStatus::kFound:
      return "found";
    case ReflectorStatus::kNotInView:
      return "not_in_view";
    case ReflectorStatus::kNoDetections:
      return "no_detections";
    case ReflectorStatus::kTooFewDetections:
      return "too_few_detections";
    case ReflectorStatus::kAmbiguous:
      return "ambiguous";
  }
  return "unknown";
}

ReflectorAssociation AssociateReflectors(std::span<const RadarCycle> cycles,
                                         std::span<const ExpectedReflector> expected,
                                         const ReflectorAssociationOptions& options) {
  ReflectorAssociation out;
  out.cycles = static_cast<int>(cycles.size());
  out.resolution = options.resolution;
  out.detection_azimuth_sigma_rad = options.detection_azimuth_sigma_rad;
  out.detection_range_sigma_m = options.detection_range_sigma_m;
  const auto in_gate = [&](const ExpectedReflector& e, double range_m, double azimuth_rad) {
    return std::abs(range_m - e.range_m) <= options.range_gate_m &&
           std::abs(WrapAngle(azimuth_rad - e.azimuth_rad)) <= options.azimuth_gate_rad;
  };
  for (size_t i = 0; i < expected.size(); ++i) {
    const ExpectedReflector& e = expected[i];
    ReflectorObservation obs;
    obs.reflector_id = e.reflector_id;
    obs.expected_range_m = e.range_m;
    obs.expected_azimuth_rad = e.azimuth_rad;
    if (!e.in_view) {
      obs.status = ReflectorStatus::kNotInView;
      out.reflectors.push_back(obs);
      continue;
    }
    // Gates of two reflectors that overlap cannot tell them apart.
    bool overlaps = false;
    for (size_t j = 0; j < expected.size(); ++j) {
      if (j == i || !expected[j].in_view) continue;
      overlaps |= std::abs(expected[j].range_m - e.range_m) <= 2 * options.range_gate_m &&
                  std::abs(WrapAngle(expected[j].azimuth_rad - e.azimuth_rad)) <=
                      2 * options.azimuth_gate_rad;
    }
    if (overlaps) {
      obs.status = ReflectorStatus::kAmbiguous;
      out.reflectors.push_back(obs);
      continue;
    }

    std::vector<double> ranges, azimuths;
    for (const RadarCycle& cycle : cycles) {
      std::vector<Candidate> candidates;
      for (const RadarDetection& d : cycle.detections) {
        if (!in_gate(e, d.range_m, d.azimuth_rad)) continue;
        if (std::abs(d.range_rate_mps) > options.max_abs_range_rate_mps) continue;
        if (d.rcs_dbsm && *d.rcs_dbsm < options.min_rcs_dbsm) continue;
        candidates.push_back({d.range_m, d.azimuth_rad});
      }
      if (candidates.empty()) continue;
      ++obs.cycles_with_candidates;
      std::sort(candidates.begin(), candidates.end(),
                [](const Candidate& a, const Candidate& b) { return a.range_m < b.range_m; });
      if (candidates.size() > 1 &&
          candidates[1].range_m - candidates[0].range_m < options.ambiguity_range_m) {
        ++obs.ambiguous_cycles;
        continue;
      }
      ranges.push_back(candidates[0].range_m);
      azimuths.push_back(candidates[0].azimuth_rad);
    }
    if (obs.cycles_with_candidates == 0) {
      obs.status = ReflectorStatus::kNoDetections;
      out.reflectors.push_back(obs);
      continue;
    }
    if (2 * obs.ambiguous_cycles >= obs.cycles_with_candidates) {
      obs.status = ReflectorStatus::kAmbiguous;
      out.reflectors.push_back(obs);
      continue;
    }

    // Robust scales, floored by the noise and by the resolution steps (quantised values can
    // make the MAD zero or flip between two levels one step apart).
    const double azimuth_position_step = options.resolution.position_step_m / e.range_m;
    const double azimuth_floor =
        std::max({options.detection_azimuth_sigma_rad, options.resolution.azimuth_step_rad,
                  azimuth_position_step});
    const double range_floor =
        std::max({options.detection_range_sigma_m, options.resolution.range_step_m,
                  options.resolution.position_step_m});
    const double azimuth_median = Median(azimuths);
    const double range_median = Median(ranges);
    const double azimuth_scale =
        std::max(kMadToSigma * Mad(azimuths, azimuth_median), azimuth_floor);
    const double range_scale = std::max(kMadToSigma * Mad(ranges, range_median), range_floor);
    double sum_r = 0, sum_a = 0, sum_rr = 0, sum_aa = 0;
    for (size_t k = 0; k < ranges.size(); ++k) {
      const double da = WrapAngle(azimuths[k] - azimuth_median);
      const double dr = ranges[k] - range_median;
      if (std::abs(da) > options.outlier_z * azimuth_scale ||
          std::abs(dr) > options.outlier_z * range_scale) {
        ++obs.outliers;
        continue;
      }
      ++obs.n_used;
      sum_a += da;
      sum_aa += da * da;
      sum_r += dr;
      sum_rr += dr * dr;
    }
    if (obs.n_used < options.min_detections) {
      obs.status = ReflectorStatus::kTooFewDetections;
      out.reflectors.push_back(obs);
      continue;
    }
    const double n = obs.n_used;
    const double mean_da = sum_a / n;
    const double mean_dr = sum_r / n;
    const double var_a = std::max(0.0, (sum_aa - n * mean_da * mean_da) / (n - 1));
    const double var_r = std::max(0.0, (sum_rr - n * mean_dr * mean_dr) / (n - 1));
    // The scatter cannot be trusted below the sensor's known noise: quantised values may
    // not vary at all.
    const double sigma_a = std::max(std::sqrt(var_a), options.detection_azimuth_sigma_rad);
    const double sigma_r = std::max(std::sqrt(var_r), options.detection_range_sigma_m);
    // Resolution steps the noise does not dither: the ESR's polar steps directly; the ARS408's
    // Cartesian step moves the azimuth by step / range in either axis.
    const double polar_azimuth_bias =
        UnditheredBias(options.resolution.azimuth_step_rad, options.detection_azimuth_sigma_rad);
    const double position_azimuth_bias =
        UnditheredBias(options.resolution.position_step_m,
                       options.detection_azimuth_sigma_rad * e.range_m) /
        e.range_m;
    const double range_bias = std::hypot(
        UnditheredBias(options.resolution.range_step_m, options.detection_range_sigma_m),
        UnditheredBias(options.resolution.position_step_m, options.detection_range_sigma_m));
    obs.status = ReflectorStatus::kFound;
    obs.azimuth_rad = WrapAngle(azimuth_median + mean_da);
    obs.range_m = range_median + mean_dr;
    obs.azimuth_se_without_position_steps_rad =
        std::hypot(sigma_a / std::sqrt(n), polar_azimuth_bias);
    obs.azimuth_se_rad =
        std::hypot(obs.azimuth_se_without_position_steps_rad, position_azimuth_bias);
    obs.range_se_m = std::hypot(sigma_r / std::sqrt(n), range_bias);
    out.reflectors.push_back(obs);
  }
  return out;
}

}  // namespace linecal

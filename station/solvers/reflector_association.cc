#include "station/solvers/reflector_association.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
// 1.4826 x MAD estimates σ for Gaussian data (1 / Φ⁻¹(3/4)).
constexpr double kMadToSigma = 1.4826;
// The range at which ForSensor turns the gate's lateral margin into azimuth_gate_rad; nearer
// reflectors widen their gate by the rest (AzimuthGate).
constexpr double kLateralGateRangeM = 4.0;

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

// W(r) of EstimateDetectionNoise, in steps²: the within-reflector variance of readings rounded
// to whole steps under noise of r steps, averaged over the true value's place in the cell. The
// sum stops once its terms fall below 1e-15 (r ≥ 1e-4: at most ~10⁴ terms).
double WithinVarianceOfRounded(double r) {
  if (r < 1e-4) return 0;
  const double pi2 = std::numbers::pi * std::numbers::pi;
  double mean_rounding_variance = 0;
  for (int k = 1;; ++k) {
    const double term = std::exp(-4 * pi2 * k * k * r * r) / (2 * pi2 * k * k);
    mean_rounding_variance += term;
    if (term < 1e-15) break;
  }
  return r * r + 1.0 / 12 - mean_rounding_variance;
}

// The root in [0, hi] of a function that grows with its argument, by bisection; 0 when it is
// already positive at 0, hi when it is still negative there.
template <typename F>
double IncreasingRoot(F f, double hi) {
  if (f(0.0) >= 0) return 0;
  if (f(hi) <= 0) return hi;
  double lo = 0;
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (f(mid) < 0 ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

// Sample variance of v (n − 1 in the denominator); v has at least two values.
double SampleVariance(std::span<const double> v) {
  double mean = 0;
  for (double x : v) mean += x;
  mean /= static_cast<double>(v.size());
  double ss = 0;
  for (double x : v) ss += (x - mean) * (x - mean);
  return ss / static_cast<double>(v.size() - 1);
}

// The noise σ of readings rounded to `step` (none when 0) whose within-reflector variances,
// weighted by their degrees of freedom, pool to `pooled_variance`.
double NoiseOfRoundedReadings(double pooled_variance, double step) {
  if (step <= 0) return std::sqrt(pooled_variance);
  const double v = pooled_variance / (step * step);
  return step *
         IncreasingRoot([&](double r) { return WithinVarianceOfRounded(r) - v; }, std::sqrt(v) + 1);
}

// The largest range noise the grid's estimate may report: beyond it a detection would leave
// the gates.
constexpr double kMaxRangeSigmaM = 1.0;
// The least noise the grid's likelihood is searched down to: far below what any step resolves.
constexpr double kMinRangeSigmaM = 1e-3;
// Golden-section steps of the search over log σ: they shrink the bracket to 1e-4 of its width.
constexpr int kGoldenSteps = 20;

// One axis (x or y) of one reflector's readings on the grid: how many readings fell in each
// cell, cells counted from the lowest one read, and the reflector's lever from range and
// azimuth noise onto that axis (its noise in steps is hypot(σr·along, σa·across)).
struct GridAxis {
  std::vector<int> counts;
  int n = 0;
  double along = 0;   // |cos| (x) or |sin| (y) of the azimuth: range noise's share, per step
  double across = 0;  // range·|sin| (x) or range·|cos| (y): azimuth noise's share, per step
};

// log ∫ Π_k P_k(v)^{n_k} dv: the likelihood of an axis's cell counts under noise of r steps,
// the true value v (in steps, cell k spanning [k − ½, k + ½]) unknown and taken as uniform
// over the cells (a constant prior density, the same for every r). The integrand is
// log-concave and negligible beyond 6r of the cells read; it is summed on a grid fine enough
// for its narrowest feature (r / √n wide).
double LogLikelihoodOfAxis(const GridAxis& a, double r) {
  const double k_max = static_cast<double>(a.counts.size()) - 1;
  const double lo = -0.5 - 6 * r, hi = k_max + 0.5 + 6 * r;
  const double h = std::clamp(0.25 * r / std::sqrt(static_cast<double>(a.n)), 1e-4, 0.02);
  const int nodes = std::clamp(static_cast<int>((hi - lo) / h), 64, 2000);
  const double dv = (hi - lo) / nodes;
  const double scale = 1 / (r * std::numbers::sqrt2);
  std::vector<double> log_g(static_cast<size_t>(nodes));
  double best = -std::numeric_limits<double>::infinity();
  for (int j = 0; j < nodes; ++j) {
    const double v = lo + (j + 0.5) * dv;
    double g = 0;
    for (size_t k = 0; k < a.counts.size(); ++k) {
      if (a.counts[k] == 0) continue;
      const double kk = static_cast<double>(k);
      // P(cell k | v) = Φ((k + ½ − v) / r) − Φ((k − ½ − v) / r), computed on the side of the
      // cell where it does not cancel.
      const double upper = (kk + 0.5 - v) * scale, lower = (kk - 0.5 - v) * scale;
      const double p = lower > 0 ? 0.5 * (std::erfc(lower) - std::erfc(upper))
                                 : 0.5 * (std::erfc(-upper) - std::erfc(-lower));
      g += a.counts[k] * std::log(std::max(std::abs(p), 1e-300));
    }
    log_g[static_cast<size_t>(j)] = g;
    best = std::max(best, g);
  }
  double sum = 0;
  for (double g : log_g) sum += std::exp(g - best);
  return best + std::log(sum * dv);
}

// The maximum over x in [lo, hi] of a unimodal f, by golden-section search.
template <typename F>
double GoldenMax(F f, double lo, double hi) {
  const double g = 0.5 * (std::sqrt(5.0) - 1);
  double a = lo, b = hi;
  double c = b - g * (b - a), d = a + g * (b - a);
  double fc = f(c), fd = f(d);
  for (int i = 0; i < kGoldenSteps; ++i) {
    if (fc >= fd) {
      b = d, d = c, fd = fc, c = b - g * (b - a), fc = f(c);
    } else {
      a = c, c = d, fc = fd, d = a + g * (b - a), fd = f(d);
    }
  }
  return fc >= fd ? c : d;
}

// The ARS408's grid: readings x = range·cos(azimuth), y = range·sin(azimuth) rounded to `step`.
// Reflector i's noise in x is hypot(σr cᵢ, σa Rᵢ sᵢ), in y hypot(σr sᵢ, σa Rᵢ cᵢ). σr maximises
// the likelihood of every reflector's cell counts in x and y, each reflector's place in its
// cells integrated out (LogLikelihoodOfAxis; x and y taken as independent), by golden section in
// log σr; σa is `azimuth_sigma_rad` (the sensor's nominal): across the line of sight 0.1° is a
// small fraction of a cell, and a free estimate of it scattered by ±70% over captures of 6
// reflectors and came out up to 4x too large. Not the moments of the polar case: with noise well
// below the step the within-reflector variance is decided by where each reflector sits in its
// cell (one astride a cell edge flips half its readings, 0.25 steps², whatever the noise), so
// that a few reflectors gave anything from 0 to 3.5x the noise; the likelihood counts such a
// split as what it is, a reflector near an edge, which any noise explains.
DetectionNoise NoiseOfGrid(std::span<const ReflectorDetections> reflectors, double step,
                           double azimuth_sigma_rad) {
  std::vector<GridAxis> axes;
  DetectionNoise out;
  for (const ReflectorDetections& r : reflectors) {
    const size_t n = r.range_m.size();
    if (n < 2) continue;
    double range = 0, azimuth = 0;
    for (size_t k = 0; k < n; ++k) {
      range += r.range_m[k] / static_cast<double>(n);
      azimuth += r.azimuth_rad[k] / static_cast<double>(n);
    }
    const double c = std::abs(std::cos(azimuth)), s = std::abs(std::sin(azimuth));
    for (const bool along_x : {true, false}) {
      std::vector<long> cells;
      for (size_t k = 0; k < n; ++k) {
        const double v = along_x ? r.range_m[k] * std::cos(r.azimuth_rad[k])
                                 : r.range_m[k] * std::sin(r.azimuth_rad[k]);
        cells.push_back(std::lround(v / step));  // any origin: only differences count
      }
      const long first = *std::min_element(cells.begin(), cells.end());
      const long last = *std::max_element(cells.begin(), cells.end());
      GridAxis a;
      a.counts.assign(static_cast<size_t>(last - first + 1), 0);
      for (long cell : cells) ++a.counts[static_cast<size_t>(cell - first)];
      a.n = static_cast<int>(n);
      a.along = (along_x ? c : s) / step;
      a.across = range * (along_x ? s : c) / step;
      axes.push_back(std::move(a));
    }
    out.dof += static_cast<int>(n - 1);
  }
  if (axes.empty()) return out;
  const auto log_likelihood = [&](double sigma_r, double sigma_a) {
    double sum = 0;
    for (const GridAxis& a : axes) {
      sum += LogLikelihoodOfAxis(a, std::hypot(sigma_r * a.along, sigma_a * a.across));
    }
    return sum;
  };
  out.azimuth_sigma_rad = azimuth_sigma_rad;
  out.range_sigma_m =
      std::exp(GoldenMax([&](double x) { return log_likelihood(std::exp(x), azimuth_sigma_rad); },
                         std::log(kMinRangeSigmaM), std::log(kMaxRangeSigmaM)));
  return out;
}

struct Candidate {
  double range_m;
  double azimuth_rad;
};

// A found reflector's means and standard errors (ReflectorObservation) from its used detections
// and the capture's noise, which floors the scatter (quantised readings of a few cycles may not
// vary at all) and says how far the noise dithers the resolution steps.
void SetMeansAndStandardErrors(const ReflectorDetections& d, const DetectionNoise& noise,
                               const RadarResolution& resolution, ReflectorObservation& obs) {
  const double n = static_cast<double>(d.range_m.size());
  obs.range_m = 0;
  obs.azimuth_rad = 0;
  for (size_t k = 0; k < d.range_m.size(); ++k) {
    obs.range_m += d.range_m[k] / n;
    obs.azimuth_rad += d.azimuth_rad[k] / n;
  }
  const double sigma_a =
      std::max(std::sqrt(SampleVariance(d.azimuth_rad)), noise.azimuth_sigma_rad);
  const double sigma_r = std::max(std::sqrt(SampleVariance(d.range_m)), noise.range_sigma_m);
  obs.azimuth_rad = WrapAngle(obs.azimuth_rad);
  // Resolution steps the noise does not dither: the ESR's polar steps directly; the ARS408's
  // Cartesian step moves the azimuth by step / range in either axis.
  const double polar_azimuth_bias =
      UnditheredBias(resolution.azimuth_step_rad, noise.azimuth_sigma_rad);
  const double position_azimuth_bias =
      UnditheredBias(resolution.position_step_m, noise.azimuth_sigma_rad * obs.range_m) /
      obs.range_m;
  const double range_bias =
      std::hypot(UnditheredBias(resolution.range_step_m, noise.range_sigma_m),
                 UnditheredBias(resolution.position_step_m, noise.range_sigma_m));
  obs.azimuth_se_without_position_steps_rad =
      std::hypot(sigma_a / std::sqrt(n), polar_azimuth_bias);
  obs.azimuth_se_rad = std::hypot(obs.azimuth_se_without_position_steps_rad, position_azimuth_bias);
  obs.range_se_m = std::hypot(sigma_r / std::sqrt(n), range_bias);
}

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

DetectionNoise EstimateDetectionNoise(std::span<const ReflectorDetections> reflectors,
                                      const RadarResolution& resolution,
                                      double grid_azimuth_sigma_rad) {
  if (resolution.position_step_m > 0) {
    return NoiseOfGrid(reflectors, resolution.position_step_m, grid_azimuth_sigma_rad);
  }
  DetectionNoise out;
  double range_ss = 0, azimuth_ss = 0;
  for (const ReflectorDetections& r : reflectors) {
    if (r.range_m.size() < 2) continue;
    const double dof = static_cast<double>(r.range_m.size() - 1);
    range_ss += dof * SampleVariance(r.range_m);
    azimuth_ss += dof * SampleVariance(r.azimuth_rad);
    out.dof += static_cast<int>(dof);
  }
  if (out.dof == 0) return out;
  out.range_sigma_m = NoiseOfRoundedReadings(range_ss / out.dof, resolution.range_step_m);
  out.azimuth_sigma_rad = NoiseOfRoundedReadings(azimuth_ss / out.dof, resolution.azimuth_step_rad);
  return out;
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
  if (auto s = non_negative("azimuth_gate_lateral_m", azimuth_gate_lateral_m); !s.ok()) return s;
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
  o.azimuth_gate_lateral_m = lateral_tolerance_m + 0.5 * resolution->position_step_m;
  o.azimuth_gate_rad = 2 * sensor.tolerance.yaw_rad + 3 * o.detection_azimuth_sigma_rad +
                       o.azimuth_gate_lateral_m / kLateralGateRangeM + resolution->azimuth_step_rad;
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

namespace {

// The half-width of reflector e's azimuth gate: options.azimuth_gate_rad, plus the part of the
// lateral margin's angle that it leaves out for a reflector nearer than kLateralGateRangeM.
double AzimuthGate(const ExpectedReflector& e, const ReflectorAssociationOptions& options) {
  constexpr double kLeastRangeM = 0.1;  // a reflector at the radar itself: a finite gate
  const double inverse_range = 1 / std::max(e.range_m, kLeastRangeM);
  return options.azimuth_gate_rad +
         options.azimuth_gate_lateral_m * std::max(0.0, inverse_range - 1 / kLateralGateRangeM);
}

// True if the gates of in-view reflector i and another in-view one overlap: detections in
// both cannot tell them apart.
bool GatesOverlap(std::span<const ExpectedReflector> expected, size_t i,
                  const ReflectorAssociationOptions& options) {
  const ExpectedReflector& e = expected[i];
  bool overlaps = false;
  for (size_t j = 0; j < expected.size(); ++j) {
    if (j == i || !expected[j].in_view) continue;
    overlaps |= std::abs(expected[j].range_m - e.range_m) <= 2 * options.range_gate_m &&
                std::abs(WrapAngle(expected[j].azimuth_rad - e.azimuth_rad)) <=
                    AzimuthGate(e, options) + AzimuthGate(expected[j], options);
  }
  return overlaps;
}

// True if a detection at range_m, azimuth_rad lies in reflector e's gate.
bool InGate(const ExpectedReflector& e, double range_m, double azimuth_rad,
            const ReflectorAssociationOptions& options) {
  return std::abs(range_m - e.range_m) <= options.range_gate_m &&
         std::abs(WrapAngle(azimuth_rad - e.azimuth_rad)) <= AzimuthGate(e, options);
}

// Per cycle, the nearest candidate in reflector e's gate (passing the range-rate and RCS
// filters), unless a second lies within options.ambiguity_range_m of it; counts the cycles
// with candidates and the ambiguous ones into *obs. Ranges and azimuths in cycle order.
void NearestCandidates(std::span<const RadarCycle> cycles, const ExpectedReflector& e,
                       const ReflectorAssociationOptions& options, std::vector<double>* ranges,
                       std::vector<double>* azimuths, ReflectorObservation* obs) {
  for (const RadarCycle& cycle : cycles) {
    std::vector<Candidate> candidates;
    for (const RadarDetection& d : cycle.detections) {
      if (!InGate(e, d.range_m, d.azimuth_rad, options)) continue;
      if (std::abs(d.range_rate_mps) > options.max_abs_range_rate_mps) continue;
      if (d.rcs_dbsm && *d.rcs_dbsm < options.min_rcs_dbsm) continue;
      candidates.push_back({d.range_m, d.azimuth_rad});
    }
    if (candidates.empty()) continue;
    ++obs->cycles_with_candidates;
    std::sort(candidates.begin(), candidates.end(),
              [](const Candidate& a, const Candidate& b) { return a.range_m < b.range_m; });
    if (candidates.size() > 1 &&
        candidates[1].range_m - candidates[0].range_m < options.ambiguity_range_m) {
      ++obs->ambiguous_cycles;
      continue;
    }
    ranges->push_back(candidates[0].range_m);
    azimuths->push_back(candidates[0].azimuth_rad);
  }
}

// The detections of reflector e within options.outlier_z robust scales of their medians
// (azimuths unwrapped about the median); counts the others into obs->outliers.
ReflectorDetections KeepInliers(const ExpectedReflector& e,
                                const ReflectorAssociationOptions& options,
                                const std::vector<double>& ranges,
                                const std::vector<double>& azimuths, ReflectorObservation* obs) {
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
  const double azimuth_scale = std::max(kMadToSigma * Mad(azimuths, azimuth_median), azimuth_floor);
  const double range_scale = std::max(kMadToSigma * Mad(ranges, range_median), range_floor);
  ReflectorDetections kept;
  for (size_t k = 0; k < ranges.size(); ++k) {
    if (std::abs(WrapAngle(azimuths[k] - azimuth_median)) > options.outlier_z * azimuth_scale ||
        std::abs(ranges[k] - range_median) > options.outlier_z * range_scale) {
      ++obs->outliers;
      continue;
    }
    kept.range_m.push_back(ranges[k]);
    // Unwrapped about the median, so that the mean and scatter never straddle ±π.
    kept.azimuth_rad.push_back(azimuth_median + WrapAngle(azimuths[k] - azimuth_median));
  }
  return kept;
}

// What the cycles show of reflector i, without its means and standard errors (they need the
// noise estimate over all reflectors); *kept: its used detections when found, else empty.
ReflectorObservation ObserveReflector(std::span<const RadarCycle> cycles,
                                      std::span<const ExpectedReflector> expected, size_t i,
                                      const ReflectorAssociationOptions& options,
                                      ReflectorDetections* kept) {
  const ExpectedReflector& e = expected[i];
  ReflectorObservation obs;
  obs.reflector_id = e.reflector_id;
  obs.expected_range_m = e.range_m;
  obs.expected_azimuth_rad = e.azimuth_rad;
  if (!e.in_view) {
    obs.status = ReflectorStatus::kNotInView;
    return obs;
  }
  // Gates of two reflectors that overlap cannot tell them apart.
  if (GatesOverlap(expected, i, options)) {
    obs.status = ReflectorStatus::kAmbiguous;
    return obs;
  }
  std::vector<double> ranges, azimuths;
  NearestCandidates(cycles, e, options, &ranges, &azimuths, &obs);
  if (obs.cycles_with_candidates == 0) {
    obs.status = ReflectorStatus::kNoDetections;
    return obs;
  }
  if (2 * obs.ambiguous_cycles >= obs.cycles_with_candidates) {
    obs.status = ReflectorStatus::kAmbiguous;
    return obs;
  }
  *kept = KeepInliers(e, options, ranges, azimuths, &obs);
  obs.n_used = static_cast<int>(kept->range_m.size());
  if (obs.n_used < options.min_detections) {
    obs.status = ReflectorStatus::kTooFewDetections;
    *kept = {};
  } else {
    obs.status = ReflectorStatus::kFound;
  }
  return obs;
}

}  // namespace

ReflectorAssociation AssociateReflectors(std::span<const RadarCycle> cycles,
                                         std::span<const ExpectedReflector> expected,
                                         const ReflectorAssociationOptions& options) {
  ReflectorAssociation out;
  out.cycles = static_cast<int>(cycles.size());
  out.resolution = options.resolution;
  // The used detections of every reflector (empty unless found), for the noise estimate and
  // the standard errors that need it.
  std::vector<ReflectorDetections> used(expected.size());
  for (size_t i = 0; i < expected.size(); ++i) {
    out.reflectors.push_back(ObserveReflector(cycles, expected, i, options, &used[i]));
  }

  // The azimuth not below the sensor's nominal noise, nor the ESR's range: their moments are
  // rough when the noise is below a step (2 cm under the ESR's 0.1 m: ±25%), and more noise than
  // nominal is what the constant missed. The ARS408's range noise, a likelihood over the grid,
  // is taken as estimated: the grid's dither falls as exp(−2π²r²), so a floor of 5 cm over a
  // true 2 cm read the grid as dithered and cut the grid's part of the σ (coverage 0.91 with
  // the position known to ±1 cm); an estimate that is too low errs towards a larger σ.
  out.noise = EstimateDetectionNoise(used, options.resolution, options.detection_azimuth_sigma_rad);
  if (options.resolution.position_step_m <= 0 || out.noise.dof == 0) {
    out.noise.range_sigma_m = std::max(out.noise.range_sigma_m, options.detection_range_sigma_m);
  }
  out.noise.azimuth_sigma_rad =
      std::max(out.noise.azimuth_sigma_rad, options.detection_azimuth_sigma_rad);
  for (size_t i = 0; i < expected.size(); ++i) {
    if (out.reflectors[i].status == ReflectorStatus::kFound) {
      SetMeansAndStandardErrors(used[i], out.noise, options.resolution, out.reflectors[i]);
    }
  }
  return out;
}

}  // namespace linecal

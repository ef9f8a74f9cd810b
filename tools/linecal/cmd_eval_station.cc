// linecal eval station: the full-physics Monte Carlo evaluation of the whole car
// (docs/acceptance.md, "Uncertainty on the full-physics evaluation"; the table is in
// docs/solvers.md, "The full-physics evaluation").
//
// Per car (seeded: car i draws from its own stream, so the results do not depend on --threads):
// every sensor's mounting angles uniform within ±1.5x each tolerance, its position within
// ±--position-error-m per axis (never beyond the tolerance), a random aligner pose, F frames
// per sensor (camera frames and LiDAR rotations alike, as the daemon's simulated station takes
// them) with F uniform in --frames-min..--frames-max, and a radar range noise uniform in
// --range-noise-min-m..--range-noise-max-m. The station simulator of `linecal sim` renders every
// camera (one scene per capture: the frames of a camera differ only in their image noise),
// scans every LiDAR with a free-running motor and simulates every radar's CAN traffic into a
// temporary capture; the cycle's own pipeline (CalibrateCapture, as `linecal calibrate` and the
// daemon run it: the detectors in the loop) solves it; each estimate is compared with the truth.
// --sensors limits the run to some sensors: each sensor draws from random streams of its own
// (the simulator's per sensor, the truths drawn for every sensor in car model order), so their
// rows are those of the whole car's run, in a fraction of the time.
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <type_traits>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "station/capture/capture.h"
#include "station/pipeline/capture_calibration.h"
#include "station/sim/simulator.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"
#include "tools/linecal/eval_harness.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "eval station";
constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;
// Mounting angle errors within ±this x the tolerance, as the other evaluations draw them: about
// a third of the cars out of tolerance, so the verdicts are tested.
constexpr double kErrorRangeOfTolerance = 1.5;
// The bars of docs/acceptance.md, "Uncertainty on the full-physics evaluation": RMS error / σ
// within 0.8..1.25 (kSigmaRatioLow); coverage, radar yaw p95 and wrong verdicts as
// eval_harness.h has them.
constexpr double kSigmaRatioHighFullPhysics = 1.25;
// The accuracy bars of docs/acceptance.md ("Solvers"), p95 of angles and positions.
struct AccuracyBars {
  double angle_deg, position_m;
};
constexpr AccuracyBars kCameraBars = {0.02, 0.010};
constexpr AccuracyBars kLidar64Bars = {0.05, 0.005};
constexpr AccuracyBars kLidar16Bars = {0.1, 0.010};
// docs/acceptance.md's radar conditions: 50 cycles (the 0.1° azimuth noise is the simulator's
// default).
constexpr int kRadarCycles = 50;

// The flags of this evaluation besides the harness's (--station, --car, --cars, --seed).
struct StationEvalFlags {
  int frames_min = 1, frames_max = 10;
  double range_noise_min_m = 0.02, range_noise_max_m = 0.10;
  double position_error_m = 0.01;
  double noise = 2.0, blur_px = 0.5;
  int threads = 1;
  // Only these sensors of the car model (empty: all). Each sensor draws from its own random
  // streams, so a sensor's rows are those of a run over the whole car.
  std::vector<std::string> sensors;
  // --per-car FILE: one JSON line per car and sensor (WritePerCar); empty: none.
  std::string per_car;
};

// Whether `f` evaluates sensor `name`.
bool Selected(const StationEvalFlags& f, const std::string& name) {
  return f.sensors.empty() ||
         std::find(f.sensors.begin(), f.sensors.end(), name) != f.sensors.end();
}

// Reads one numeric flag into `slot` (its default when absent) and checks it is in [lo, hi];
// the error names the flag and the value.
template <typename T>
absl::Status ReadFlag(const cli::CommandLine& cl, const std::string& name, T lo, T hi, T* slot) {
  T value;
  if constexpr (std::is_integral_v<T>) {
    const absl::StatusOr<int> v = cl.GetInt(name, *slot);
    if (!v.ok()) return v.status();
    value = *v;
  } else {
    const absl::StatusOr<double> v = cl.GetDouble(name, *slot);
    if (!v.ok()) return v.status();
    value = *v;
  }
  if (!(value >= lo && value <= hi)) {
    return absl::InvalidArgumentError(
        absl::StrCat("--", name, ": ", value, ": must be in [", lo, ", ", hi, "]"));
  }
  *slot = value;
  return absl::OkStatus();
}

// All flags of StationEvalFlags, in the order of the usage line; the error names the flag.
absl::StatusOr<StationEvalFlags> ReadStationEvalFlags(const cli::CommandLine& cl) {
  StationEvalFlags f;
  // The bounds are the simulator's (SimulatorOptions::Validate and its nested options).
  for (const absl::Status& s :
       {ReadFlag(cl, "frames-min", 1, 100, &f.frames_min),
        ReadFlag(cl, "frames-max", 1, 100, &f.frames_max),
        ReadFlag(cl, "range-noise-min-m", 0.0, 5.0, &f.range_noise_min_m),
        ReadFlag(cl, "range-noise-max-m", 0.0, 5.0, &f.range_noise_max_m),
        ReadFlag(cl, "position-error-m", 0.0, 0.5, &f.position_error_m),
        ReadFlag(cl, "noise", 0.0, 64.0, &f.noise), ReadFlag(cl, "blur", 0.0, 10.0, &f.blur_px),
        ReadFlag(cl, "threads", 1, 16, &f.threads)}) {
    if (!s.ok()) return s;
  }
  if (f.frames_max < f.frames_min) {
    return absl::InvalidArgumentError(
        absl::StrCat("--frames-max: ", f.frames_max, ": must be >= --frames-min ", f.frames_min));
  }
  if (cl.Has("sensors")) f.sensors = absl::StrSplit(cl.Get("sensors"), ',', absl::SkipEmpty());
  if (cl.Has("per-car")) f.per_car = cl.Get("per-car");
  if (cl.Has("per-car") && f.per_car.empty()) {
    return absl::InvalidArgumentError("--per-car: names no file");
  }
  if (cl.Has("sensors") && f.sensors.empty()) {
    return absl::InvalidArgumentError("--sensors: names no sensor");
  }
  if (f.range_noise_max_m < f.range_noise_min_m) {
    return absl::InvalidArgumentError(absl::StrCat("--range-noise-max-m: ", f.range_noise_max_m,
                                                   ": must be >= --range-noise-min-m ",
                                                   f.range_noise_min_m));
  }
  return f;
}

// The flags: --cars and --seed, this evaluation's own, then --station and --car and their
// targets' check (the cheap checks before the files are read); the error names the flag or file.
absl::Status ReadInputs(const cli::CommandLine& cl, EvalInputs* in, StationEvalFlags* flags) {
  absl::Status status = ReadCarsAndSeed(cl, in);
  if (!status.ok()) return status;
  absl::StatusOr<StationEvalFlags> read = ReadStationEvalFlags(cl);
  if (!read.ok()) return read.status();
  *flags = *read;
  // A path that cannot be written is found now, not after hours of cars.
  if (!flags->per_car.empty() && !std::ofstream(flags->per_car, std::ios::app)) {
    return absl::InvalidArgumentError(absl::StrCat("--per-car: cannot write ", flags->per_car));
  }
  status = ReadStationAndCar(cl, in);
  if (!status.ok()) return status;
  for (const std::string& name : flags->sensors) {
    if (in->car.FindSensor(name) == nullptr) {
      return absl::InvalidArgumentError(
          absl::StrCat("--sensors: car model '", in->car.id, "' has no sensor '", name, "'"));
    }
  }
  return CheckTargetsExist(in->car, in->station);
}

// A sensor's true mounting for this evaluation: angles within ±kErrorRangeOfTolerance x each
// tolerance (a radar's pitch and roll within their tolerance), positions within
// ±min(position_error_m, tolerance) per axis.
TrueMounting DrawMounting(const SensorModel& s, double position_error_m, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::array<double, 6> truth = RandomMounting(s, kErrorRangeOfTolerance, rng).truth;
  const std::array<double, 6> tolerances = MountingTolerances(s);
  for (int i = 3; i < 6; ++i) truth[i] = std::min(position_error_m, tolerances[i]) * unit(rng);
  // A radar measures its yaw alone. Its σ carries pitch and roll as uniform within their
  // tolerances (radar_calibration.cc, PitchRollSigma): an assumption no radar measurement can
  // check, so they are drawn within them, as `eval radar` draws them (the same draws, scaled).
  if (s.kind == SensorKind::kRadar) {
    for (int i : {1, 2}) truth[i] /= kErrorRangeOfTolerance;
  }
  return MountingWithErrors(s, truth);
}

// One car's simulation and calibration: what was drawn and what the pipeline gave, per sensor
// in the car model's order.
struct CarOutcome {
  int frames = 0;
  double range_noise_m = 0;
  std::vector<TrueMounting> truths;
  std::vector<SensorCalibration> calibrations;
};

// A temporary directory, removed with everything in it when this goes out of scope.
class TemporaryDirectory {
 public:
  // Creates "<system temp>/linecal-eval-station-XXXXXX"; path() is empty when it could not.
  TemporaryDirectory() {
    std::string name =
        (std::filesystem::temp_directory_path() / "linecal-eval-station-XXXXXX").string();
    if (mkdtemp(name.data()) != nullptr) path_ = name;
  }
  ~TemporaryDirectory() {
    std::error_code ec;
    if (!path_.empty()) std::filesystem::remove_all(path_, ec);
  }
  TemporaryDirectory(const TemporaryDirectory&) = delete;
  TemporaryDirectory& operator=(const TemporaryDirectory&) = delete;
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// The simulator's options for one car: its frames, range noise, aligner and true mountings;
// `render_threads` for the camera renderer.
SimulatorOptions CarSimulatorOptions(const StationEvalFlags& f, const CarOutcome& car,
                                     const AlignerMeasurement& aligner, const CarModel& model,
                                     int render_threads) {
  SimulatorOptions o;
  o.aligner = aligner;
  o.camera_frames = car.frames;
  o.camera.noise_sigma = f.noise;
  o.camera.blur_sigma_px = f.blur_px;
  o.camera.threads = render_threads;
  o.lidar.rotations = car.frames;
  o.lidar.free_running = true;
  o.lidar_pcap = false;  // the pipeline reads the PCD scans
  o.radar.cycles = kRadarCycles;
  o.radar.range_sigma_m = car.range_noise_m;
  o.sensors = f.sensors;
  for (size_t i = 0; i < model.sensors.size(); ++i) {
    o.true_mountings.emplace(model.sensors[i].name, car.truths[i].T_car_sensor);
  }
  return o;
}

// Car `index`: draws it, simulates it into a temporary capture, reads the capture back and
// runs the cycle's pipeline on it with `threads` threads. Errors: the simulator's, the capture
// reader's or the pipeline's (a sensor that is not solved is an outcome, not an error).
absl::StatusOr<CarOutcome> EvaluateCar(const EvalInputs& in, const StationEvalFlags& f, int index,
                                       int threads) {
  std::mt19937_64 rng(static_cast<std::uint64_t>(in.seed) * 1000003u +
                      static_cast<std::uint64_t>(index));
  CarOutcome car;
  car.frames = std::uniform_int_distribution<int>(f.frames_min, f.frames_max)(rng);
  car.range_noise_m =
      std::uniform_real_distribution<double>(f.range_noise_min_m, f.range_noise_max_m)(rng);
  const AlignerMeasurement aligner = RandomAligner(rng);
  for (const SensorModel& s : in.car.sensors) {
    car.truths.push_back(DrawMounting(s, f.position_error_m, rng));
  }
  const TemporaryDirectory dir;
  if (dir.path().empty()) return absl::InternalError("cannot create a temporary directory");
  const SimulatorOptions options = CarSimulatorOptions(f, car, aligner, in.car, threads);
  const absl::StatusOr<SimulationSummary> sim =
      SimulateCapture(in.station, in.car, options, rng(), dir.path());
  if (!sim.ok()) return sim.status();
  const absl::StatusOr<Capture> capture = ReadCapture(dir.path());
  if (!capture.ok()) return capture.status();
  CaptureCalibrationOptions calibration;
  calibration.threads = threads;
  absl::StatusOr<CycleCalibration> cycle = CalibrateCapture(*capture, calibration);
  if (!cycle.ok()) return cycle.status();
  car.calibrations = std::move(cycle->sensors);
  return car;
}

// Set by SIGINT or SIGTERM: no car starts after it, and the evaluation reports the cars done (a
// long run stopped at a deadline still gives its table).
std::atomic<bool> stop_requested{false};
void RequestStop(int) { stop_requested = true; }

// Runs every car, `threads` at a time, printing "eval station: car k of N" to stderr as each
// ends; the outcomes in car order. Once a stop is requested, the cars done before the first
// one not done (the same cars as a run with that many --cars). Stops at the first error and
// returns it.
absl::StatusOr<std::vector<CarOutcome>> EvaluateCars(const EvalInputs& in,
                                                     const StationEvalFlags& f) {
  std::vector<std::optional<absl::StatusOr<CarOutcome>>> outcomes(in.cars);
  std::atomic<int> next{0}, done{0};
  std::atomic<bool> failed{false};
  std::mutex progress;
  // One car at a time uses both cores for its renders and sensors; parallel cars one each.
  const int inner_threads = f.threads == 1 ? 2 : 1;
  auto work = [&] {
    for (int i = next++; i < in.cars && !failed && !stop_requested; i = next++) {
      outcomes[i] = EvaluateCar(in, f, i, inner_threads);
      failed = failed || !outcomes[i]->ok();
      const std::lock_guard<std::mutex> lock(progress);
      std::fprintf(stderr, "linecal %s: car %d of %d\n", kCommand, ++done, in.cars);
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < std::min(f.threads, in.cars); ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  std::vector<CarOutcome> cars;
  for (std::optional<absl::StatusOr<CarOutcome>>& o : outcomes) {
    if (!o) break;
    if (!o->ok()) return o->status();
    cars.push_back(**std::move(o));
  }
  return cars;
}

// The frames a planned target was looked for in, found whole in, and seen partly in; per car
// that missed it in some frame, the detector's reason in the last of those frames.
struct TargetCount {
  int looked = 0, found = 0, partial = 0;
  std::map<std::string, int> miss_reasons;
};

// One sensor's results over the cars.
struct SensorSamples {
  SensorKind kind = SensorKind::kCamera;
  AccuracyBars bars = kCameraBars;
  int cars = 0;
  std::map<std::string, int> reasons;          // not solved or verdict error: reason
  MountingSamples mounting;                    // cameras and LiDARs: the six components
  std::vector<double> yaw_errors, yaw_sigmas;  // radars: the yaw alone is measured
  int verdicts = 0, verdicts_agree = 0;        // pass or fail, against the truth
  // Wrong verdicts with the truth more than kWrongVerdictEdgeSigmas from the tolerance edge,
  // and the farthest from its edge of any wrong verdict (σ).
  int wrong_off_edge = 0;
  double max_wrong_edge_sigmas = 0;
  // Cameras and LiDARs: per target board (in sensor.targets order); radars: one entry,
  // "reflectors", that counts the planned reflectors and those used in the solve.
  std::vector<std::pair<std::string, TargetCount>> targets;
};

// The accuracy bars of `s`'s kind (and ring count).
AccuracyBars BarsOf(const SensorModel& s) {
  if (s.kind != SensorKind::kLidar) return kCameraBars;
  const absl::StatusOr<LidarBeamTable> beams = LidarBeamTableOf(s);
  return beams.ok() && beams->beams.size() >= 64 ? kLidar64Bars : kLidar16Bars;
}

// Counts the verdict of `c` against `truth`: whether it agrees and, when not, how far (in σ)
// the truth lies from the tolerance edge of the components that decide (those the truth and
// the estimate put on different sides of their edge; all measured ones when none does).
void AddVerdict(const SensorCalibration& c, const TrueMounting& truth, SensorSamples* out) {
  if (c.verdict == Verdict::kError) return;
  const Eigen::Matrix<double, 6, 1> estimate = c.mounting.Deviation();
  bool truly_in = true;
  double edge_deciding = 1e9, edge_any = 1e9;
  for (int i = 0; i < 6; ++i) {
    if (!c.mounting.observed[i] || !(c.mounting.sigma[i] > 0)) continue;
    const double tol = truth.tolerances[i];
    const bool in = std::abs(truth.truth[i]) <= tol;
    truly_in &= in;
    const double edge = std::abs(std::abs(truth.truth[i]) - tol) / c.mounting.sigma[i];
    edge_any = std::min(edge_any, edge);
    if (in != (std::abs(estimate[i]) <= tol)) edge_deciding = std::min(edge_deciding, edge);
  }
  ++out->verdicts;
  if ((c.verdict == Verdict::kPass) == truly_in) {
    ++out->verdicts_agree;
    return;
  }
  const double edge = edge_deciding < 1e9 ? edge_deciding : edge_any;
  out->wrong_off_edge += edge > kWrongVerdictEdgeSigmas;
  out->max_wrong_edge_sigmas = std::max(out->max_wrong_edge_sigmas, edge);
}

// Adds sensor `s`'s outcome of one car (its truth and calibration) to `out`.
void AddSensor(const SensorModel& s, const TrueMounting& truth, const SensorCalibration& c,
               SensorSamples* out) {
  ++out->cars;
  if (out->targets.empty()) {
    if (s.kind == SensorKind::kRadar) out->targets.emplace_back("reflectors", TargetCount{});
    for (const std::string& id : s.targets) {
      if (s.kind != SensorKind::kRadar) out->targets.emplace_back(id, TargetCount{});
    }
  }
  if (s.kind == SensorKind::kRadar) {
    out->targets[0].second.looked += static_cast<int>(s.targets.size());
    out->targets[0].second.found += c.features_used;
  }
  for (size_t b = 0; b < c.boards.size() && b < out->targets.size(); ++b) {
    out->targets[b].second.looked += c.boards[b].frames;
    out->targets[b].second.found += c.boards[b].frames_found;
    out->targets[b].second.partial += c.boards[b].frames_partial;
    if (c.boards[b].frames_found < c.boards[b].frames) {
      ++out->targets[b].second.miss_reasons[c.boards[b].last_reason];
    }
  }
  if (!c.solved) {
    ++out->reasons[c.reason.empty() ? "not_solved" : c.reason];
    return;
  }
  if (c.verdict == Verdict::kError) ++out->reasons[c.reason];
  AddVerdict(c, truth, out);
  if (s.kind == SensorKind::kRadar) {
    out->yaw_errors.push_back(c.mounting.Deviation()[0] - truth.truth[0]);
    out->yaw_sigmas.push_back(c.mounting.sigma[0]);
  } else {
    out->mounting.Add(c.mounting, truth, c.verdict);
  }
}

// One sensor's figures against the bars.
struct SensorFigures {
  int solved = 0;
  double angle_p95 = 0, position_p95 = 0;  // radians, metres (radars: yaw only, no position)
  double ratio_lo = 0, ratio_hi = 0, cover_lo = 0, cover_hi = 0;
  bool all_targets_found = true;
  bool meets_accuracy = false, meets = false;
};

// The figures of `c`, adding its components' columns to `row`.
SensorFigures Figures(const SensorSamples& c, nlohmann::json* row) {
  SensorFigures f;
  if (c.kind == SensorKind::kRadar) {
    const ErrorSigmaStats yaw = SummariseErrors(c.yaw_errors, c.yaw_sigmas);
    f.solved = yaw.n;
    f.angle_p95 = yaw.p95_abs_error;
    f.ratio_lo = f.ratio_hi = yaw.error_over_sigma;
    f.cover_lo = f.cover_hi = yaw.coverage95;
    f.meets_accuracy = f.angle_p95 <= kRadarYawP95BarDeg * kDegToRad;
    (*row)["yaw_p95_abs_error_deg"] = yaw.p95_abs_error * kRadToDeg;
    (*row)["yaw_error_over_sigma"] = yaw.error_over_sigma;
    (*row)["yaw_coverage95"] = yaw.coverage95;
  } else {
    const MountingSummary s = Summarise(c.mounting);
    f.solved = static_cast<int>(c.mounting.errors[0].size());
    f.angle_p95 = MaxAngleP95(s);
    f.position_p95 = MaxPositionP95(s);
    f.ratio_lo = s.ratio_lo;
    f.ratio_hi = s.ratio_hi;
    f.cover_lo = s.cover_lo;
    f.cover_hi = s.cover_hi;
    f.meets_accuracy =
        f.angle_p95 <= c.bars.angle_deg * kDegToRad && f.position_p95 <= c.bars.position_m;
    AddMountingColumns(s, row);
  }
  for (const auto& [id, t] : c.targets) f.all_targets_found &= t.found == t.looked;
  f.meets = f.solved == c.cars && f.solved > 0 && f.ratio_lo >= kSigmaRatioLow &&
            f.ratio_hi <= kSigmaRatioHighFullPhysics && f.cover_lo >= kCoverageLow &&
            f.cover_hi <= kCoverageHigh && c.wrong_off_edge == 0 && f.all_targets_found &&
            (c.kind != SensorKind::kRadar || f.meets_accuracy);
  return f;
}

// One sensor's JSON row and table lines in `report`; returns whether it meets every bar.
bool ReportSensor(const std::string& name, const SensorSamples& c, EvalReport* report) {
  nlohmann::json row = {{"sensor", name}, {"kind", SensorKindName(c.kind)}, {"cars", c.cars}};
  const SensorFigures f = Figures(c, &row);
  const double agreement = c.verdicts ? static_cast<double>(c.verdicts_agree) / c.verdicts : 1.0;
  nlohmann::json targets = nlohmann::json::array();
  for (const auto& [id, t] : c.targets) {
    targets.push_back({{"target", id},
                       {"looked_for", t.looked},
                       {"found", t.found},
                       {"partial", t.partial},
                       {"miss_reasons", t.miss_reasons}});
  }
  row.update({{"solved", f.solved},
              {"angle_p95_abs_error_deg", f.angle_p95 * kRadToDeg},
              {"error_over_sigma_min", f.ratio_lo},
              {"error_over_sigma_max", f.ratio_hi},
              {"coverage95_min", f.cover_lo},
              {"coverage95_max", f.cover_hi},
              {"verdicts", c.verdicts},
              // Verdict error near_tolerance_edge: solved, but within the verdict's 2σ guard
              // band of an edge (mounting.h, DecideTolerance), so neither pass nor fail.
              {"undecided_near_edge",
               c.reasons.contains("near_tolerance_edge") ? c.reasons.at("near_tolerance_edge") : 0},
              {"verdict_agreement", agreement},
              {"wrong_verdicts_beyond_1sigma_of_edge", c.wrong_off_edge},
              {"max_wrong_verdict_edge_distance_sigma", c.max_wrong_edge_sigmas},
              {"targets", std::move(targets)},
              {"all_targets_found", f.all_targets_found},
              {"errors", c.reasons},
              {"meets_accuracy_bars", f.meets_accuracy},
              {"meets_bars", f.meets}});
  if (c.kind != SensorKind::kRadar) row["position_p95_abs_error_mm"] = f.position_p95 * 1e3;
  const std::string position =
      c.kind == SensorKind::kRadar ? "-" : absl::StrFormat("%.2f", f.position_p95 * 1e3);
  report->Table(
      "%-18s %-6s %4d %6d | %8.4f %7s | %4.2f..%-4.2f %4.2f..%-4.2f | %6.1f%% %3d | %s%s\n", name,
      SensorKindName(c.kind), c.cars, f.solved, f.angle_p95 * kRadToDeg, position, f.ratio_lo,
      f.ratio_hi, f.cover_lo, f.cover_hi, agreement * 100, c.wrong_off_edge,
      ReasonsText(c.reasons).empty() ? "-" : ReasonsText(c.reasons),
      f.meets ? "" : "  (misses a bar)");
  for (const char* k : {"yaw", "pitch", "roll", "x", "y", "z"}) {
    const std::string ratio = absl::StrCat(k, "_error_over_sigma");
    if (!row.contains(ratio)) continue;
    report->Table("%-18s   %-5s error/sigma %5.2f coverage %5.3f\n", "", k,
                  row[ratio].get<double>(), row[absl::StrCat(k, "_coverage95")].get<double>());
  }
  for (const auto& [id, t] : c.targets) {
    report->Table("%-18s   target %-24s found %d of %d (partial %d)%s%s\n", "", id, t.found,
                  t.looked, t.partial,
                  t.miss_reasons.empty() ? "" : "; missed: ", ReasonsText(t.miss_reasons));
  }
  report->AddRow(std::move(row));
  return f.meets;
}

// One line of --per-car: car `index`'s sensor `s`, what was drawn and what the pipeline gave.
// truth, estimate (the deviation from nominal), sigma and error_over_sigma in the order yaw,
// pitch, roll (degrees), x, y, z (millimetres); a component the sensor did not measure (a
// radar's all but yaw) or an unsolved sensor's is null.
nlohmann::json PerCarLine(int index, const CarOutcome& o, const SensorModel& s,
                          const TrueMounting& truth, const SensorCalibration& c) {
  nlohmann::json truths = nlohmann::json::array(), estimates = nlohmann::json::array(),
                 sigmas = nlohmann::json::array(), ratios = nlohmann::json::array();
  const Eigen::Matrix<double, 6, 1> estimate = c.mounting.Deviation();
  for (int i = 0; i < 6; ++i) {
    const double unit = i < 3 ? kRadToDeg : 1e3;
    truths.push_back(truth.truth[i] * unit);
    const bool measured = c.solved && c.mounting.observed[i] && c.mounting.sigma[i] > 0;
    estimates.push_back(measured ? nlohmann::json(estimate[i] * unit) : nlohmann::json());
    sigmas.push_back(measured ? nlohmann::json(c.mounting.sigma[i] * unit) : nlohmann::json());
    ratios.push_back(measured ? nlohmann::json((estimate[i] - truth.truth[i]) / c.mounting.sigma[i])
                              : nlohmann::json());
  }
  return {{"car", index},
          {"sensor", s.name},
          {"frames", o.frames},
          {"range_noise_m", o.range_noise_m},
          {"solved", c.solved},
          {"verdict", VerdictName(c.verdict)},
          {"reason", c.reason},
          {"truth", std::move(truths)},
          {"estimate", std::move(estimates)},
          {"sigma", std::move(sigmas)},
          {"error_over_sigma", std::move(ratios)}};
}

// Calls visit(k, i, c) for car k's calibration c of each selected sensor i, in car order and
// then car model order: the one walk of the outcomes that the table and --per-car share.
template <typename Visit>
void ForEachSelectedCalibration(const CarModel& car, const StationEvalFlags& f,
                                const std::vector<CarOutcome>& outcomes, Visit visit) {
  for (size_t k = 0; k < outcomes.size(); ++k) {
    for (size_t i = 0; i < car.sensors.size(); ++i) {
      if (!Selected(f, car.sensors[i].name)) continue;
      for (const SensorCalibration& c : outcomes[k].calibrations) {
        if (c.name == car.sensors[i].name) visit(k, i, c);
      }
    }
  }
}

// Writes --per-car: one JSON object a line per car (in car order) and selected sensor (in car
// model order), for looking into the cars behind a table's figures. Errors: the file's.
absl::Status WritePerCar(const CarModel& car, const StationEvalFlags& f,
                         const std::vector<CarOutcome>& outcomes) {
  std::ofstream out(f.per_car, std::ios::trunc);
  ForEachSelectedCalibration(car, f, outcomes, [&](size_t k, size_t i, const SensorCalibration& c) {
    out << PerCarLine(static_cast<int>(k), outcomes[k], car.sensors[i], outcomes[k].truths[i], c)
               .dump()
        << "\n";
  });
  out.close();
  if (!out) return absl::InternalError(absl::StrCat("--per-car: cannot write ", f.per_car));
  return absl::OkStatus();
}

// The per-sensor samples of all cars, in car order (so they do not depend on --threads).
std::map<std::string, SensorSamples> Collect(const CarModel& car, const StationEvalFlags& f,
                                             const std::vector<CarOutcome>& outcomes) {
  std::map<std::string, SensorSamples> samples;
  for (const SensorModel& s : car.sensors) {
    if (!Selected(f, s.name)) continue;
    samples[s.name].kind = s.kind;
    samples[s.name].bars = BarsOf(s);
  }
  ForEachSelectedCalibration(car, f, outcomes, [&](size_t k, size_t i, const SensorCalibration& c) {
    const SensorModel& s = car.sensors[i];
    AddSensor(s, outcomes[k].truths[i], c, &samples[s.name]);
  });
  return samples;
}

}  // namespace

int RunEvalStation(const Args& args) {
  cli::CommandLine cl(
      "linecal eval station --station FILE --car FILE [--cars N] [--seed S] [--frames-min F] "
      "[--frames-max F] [--range-noise-min-m M] [--range-noise-max-m M] [--position-error-m M] "
      "[--noise G] [--blur P] [--sensors A,B] [--threads T] [--per-car FILE] [--json]",
      "Full-physics Monte Carlo evaluation of the whole car: per car, mounting angles within "
      "1.5x each tolerance, positions within --position-error-m per axis (and the tolerance), a "
      "random aligner pose, F frames per sensor (uniform in --frames-min..--frames-max; camera "
      "frames of one scene and free-running LiDAR rotations) and a radar range noise uniform in "
      "--range-noise-min-m..--range-noise-max-m (0.1 deg azimuth, 50 cycles). The station "
      "simulator of `linecal sim` writes a temporary capture, the pipeline of `linecal "
      "calibrate` (detectors in the loop) solves it, and every sensor's estimate is compared "
      "with the truth. Prints per sensor the cars solved, the p95 angle and position errors, "
      "per component RMS error / RMS sigma and 95% coverage, the verdict agreement, the wrong "
      "verdicts with the truth more than 1 sigma from a tolerance edge and per planned target "
      "the frames it was looked for and found in. Exit 0 when every bar of docs/acceptance.md's "
      "\"Uncertainty on the full-physics evaluation\" holds, 1 otherwise, 2 on bad input.",
      {{"station", "FILE", "station layout (e.g. deploy/stations/reference.json)", true},
       {"car", "FILE", "car model (e.g. deploy/cars/reference.json)", true},
       {"cars", "N", "number of random cars (default 200)"},
       {"seed", "S", "random seed (default 1)"},
       {"frames-min", "F", "fewest frames per sensor (default 1)"},
       {"frames-max", "F", "most frames per sensor (default 10)"},
       {"range-noise-min-m", "M", "least radar range noise 1-sigma, metres (default 0.02)"},
       {"range-noise-max-m", "M", "most radar range noise 1-sigma, metres (default 0.10)"},
       {"position-error-m", "M", "mounting position error bound per axis, metres (default 0.01)"},
       {"noise", "G", "camera image noise, grey levels (default 2)"},
       {"blur", "P", "camera blur, pixels (default 0.5)"},
       {"sensors", "A,B",
        "evaluate only these sensors (default: all); each sensor's figures are those of a run "
        "over the whole car"},
       {"threads", "T", "cars evaluated at once (default 1)"},
       {"per-car", "FILE",
        "also write one JSON line per car and sensor: frames, range noise, verdict, and truth, "
        "estimate, sigma and error/sigma of yaw, pitch, roll (deg), x, y, z (mm)"},
       {"json", "", "print one JSON object"}});
  if (const std::optional<int> exit = cli::ParseOrExit(cl, kCommand, args)) return *exit;
  EvalInputs in;
  StationEvalFlags flags;
  if (absl::Status s = ReadInputs(cl, &in, &flags); !s.ok()) {
    return cli::BadInput(kCommand, std::string(s.message()));
  }
  std::signal(SIGINT, RequestStop);
  std::signal(SIGTERM, RequestStop);
  const absl::StatusOr<std::vector<CarOutcome>> outcomes = EvaluateCars(in, flags);
  if (!outcomes.ok()) {
    std::fprintf(stderr, "linecal %s: %s\n", kCommand,
                 std::string(outcomes.status().message()).c_str());
    return cli::kExitNegative;
  }
  if (outcomes->empty()) {
    std::fprintf(stderr, "linecal %s: stopped before the first car ended\n", kCommand);
    return cli::kExitNegative;
  }
  const std::map<std::string, SensorSamples> samples = Collect(in.car, flags, *outcomes);
  if (!flags.per_car.empty()) {
    if (absl::Status s = WritePerCar(in.car, flags, *outcomes); !s.ok()) {
      std::fprintf(stderr, "linecal %s: %s\n", kCommand, std::string(s.message()).c_str());
      return cli::kExitNegative;
    }
  }

  EvalReport report(cl);
  report.Table("%-18s %-6s %4s %6s | %8s %7s | %10s %10s | %7s %3s | %s\n", "sensor", "kind",
               "cars", "solved", "p95 deg", "p95 mm", "err/sigma", "cover95", "verdict", ">1s",
               "errors");
  bool all_meet = !samples.empty();
  for (const SensorModel& s : in.car.sensors) {
    if (Selected(flags, s.name)) all_meet &= ReportSensor(s.name, samples.at(s.name), &report);
  }
  report.Table(
      "bars: every sensor solved, error/sigma %.2f..%.2f, coverage %.2f..%.2f, radar yaw p95 <= "
      "%.2f deg, no wrong verdict with the truth > %.0f sigma from an edge, every target found "
      "in every frame: %s\n",
      kSigmaRatioLow, kSigmaRatioHighFullPhysics, kCoverageLow, kCoverageHigh, kRadarYawP95BarDeg,
      kWrongVerdictEdgeSigmas, all_meet ? "all met" : "NOT all met");
  if (outcomes->size() < static_cast<size_t>(in.cars)) {
    std::fprintf(stderr, "linecal %s: stopped: %zu of %d cars reported\n", kCommand,
                 outcomes->size(), in.cars);
  }
  return report.Finish({{"cars", outcomes->size()},
                        {"cars_requested", in.cars},
                        {"seed", in.seed},
                        {"frames_min", flags.frames_min},
                        {"frames_max", flags.frames_max},
                        {"range_noise_min_m", flags.range_noise_min_m},
                        {"range_noise_max_m", flags.range_noise_max_m},
                        {"position_error_m", flags.position_error_m},
                        {"camera_noise", flags.noise},
                        {"camera_blur_px", flags.blur_px},
                        {"sensors_selected", flags.sensors},
                        {"lidar_free_running", true},
                        {"radar_cycles", kRadarCycles}},
                       "sensors", all_meet);
}

}  // namespace linecal::tools

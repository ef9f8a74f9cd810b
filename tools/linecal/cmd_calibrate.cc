// linecal calibrate: one cycle's results from a capture, without the daemon
// (station/pipeline/capture_calibration.h does the work; the daemon replays through the same code).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "station/io/image_io.h"
#include "station/pipeline/capture_calibration.h"
#include "station/pipeline/results_json.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/calibration_report.h"
#include "tools/linecal/commands.h"
#include "tools/linecal/input_budget_flags.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "calibrate";
constexpr double kDegPerRad = 180.0 / std::numbers::pi;

void PrintTable(const Capture& capture, const CycleCalibration& cycle) {
  std::printf("VIN %s, car model %s: %s (%.0f ms)\n", capture.manifest.vin.c_str(),
              capture.manifest.car_model.c_str(), VerdictName(cycle.verdict),
              cycle.elapsed_ns * 1e-6);
  std::printf("  %-20s %-7s %-7s %-26s %9s %9s %9s %8s %8s %8s %6s %9s\n", "sensor", "kind",
              "verdict", "reason", "dyaw_deg", "dpitch_deg", "droll_deg", "dx_mm", "dy_mm", "dz_mm",
              "feat", "rms");
  for (const SensorCalibration& s : cycle.sensors) {
    std::string numbers;
    const MountingEstimate& m = s.mounting;
    const double shown[6] = {
        m.angles_deviation.yaw * kDegPerRad,  m.angles_deviation.pitch * kDegPerRad,
        m.angles_deviation.roll * kDegPerRad, m.position_deviation_m.x() * 1e3,
        m.position_deviation_m.y() * 1e3,     m.position_deviation_m.z() * 1e3};
    for (int i = 0; i < 6; ++i) {
      const int width = i < 3 ? 9 : 8;
      // "-": not solved, or a component this sensor cannot observe (kept nominal).
      numbers += s.solved && m.observed[i]
                     ? absl::StrFormat(i < 3 ? " %+*.3f" : " %+*.1f", width, shown[i])
                     : absl::StrFormat(" %*s", width, "-");
    }
    std::printf("  %-20s %-7s %-7s %-26s%s %6d %9.3f\n", s.name.c_str(), SensorKindName(s.kind),
                VerdictName(s.verdict), s.reason.empty() ? "-" : s.reason.c_str(), numbers.c_str(),
                s.features_used, s.residual_rms);
  }
  for (const SensorCalibration& s : cycle.sensors) {
    if (!s.message.empty()) std::printf("  %s\n", s.message.c_str());
  }
  // The seed formulas beside the extrinsic (docs/solvers.md).
  for (const SensorCalibration& s : cycle.sensors) {
    if (s.kind != SensorKind::kCamera || !s.solved) continue;
    std::string line = absl::StrFormat("  %s: board method ", s.name);
    if (s.board_method.valid && s.vanishing_point_px) {
      double worst = 0;
      for (double d : s.ground_disagreement) worst = std::max(worst, d);
      absl::StrAppendFormat(&line,
                            "vanishing point %.3f px from the extrinsic's, ground %.3f%% at 5-50 m",
                            s.vanishing_point_disagreement_px, worst * 100);
    } else {
      absl::StrAppend(&line, s.board_method.valid ? "valid" : s.board_method.reason);
    }
    absl::StrAppend(&line, "; roll from the vertical board ");
    if (s.vertical_roll.valid) {
      absl::StrAppendFormat(&line, "%+.3f deg (pose %+.3f deg)",
                            s.vertical_roll.roll_rad * kDegPerRad,
                            s.mounting.angles.roll * kDegPerRad);
    } else {
      absl::StrAppend(&line, s.vertical_roll.reason);
    }
    std::printf("%s\n", line.c_str());
  }
}

// The options: the capture, the output, and the input budget `capture check` takes too.
std::vector<cli::OptionSpec> CalibrateOptions() {
  std::vector<cli::OptionSpec> options = {
      {"capture", "DIR", "capture directory (docs/capture-format.md)", true},
      {"json", "", "print one JSON object"},
      {"report", "DIR",
       "write DIR/<camera>.png per camera: its first frame with the detected features, the "
       "reprojected boards, the horizon, a ground grid and a legend (created if missing)"}};
  for (cli::OptionSpec& o : InputBudgetOptions()) options.push_back(std::move(o));
  return options;
}

}  // namespace

int RunCalibrate(const Args& args) {
  cli::CommandLine cl(
      "linecal calibrate --capture DIR [--json] [--report DIR] [--max-image-pixels N ...]",
      "Computes a calibration cycle from a capture, as the daemon would: detects every camera's "
      "boards in its frames and solves its mounting in the car frame, calibrates the radars from "
      "their corner reflectors, and judges each sensor against the car model's tolerances. "
      "Prints a table (deviations from nominal; residual RMS in pixels for cameras, degrees for "
      "radars), or with --json the results document of docs/interfaces.md. Exit 0 when every "
      "sensor "
      "passes, 1 when any fails or could not be calibrated, 2 on bad usage or input.",
      CalibrateOptions());
  if (const std::optional<int> exit = cli::ParseOrExit(cl, kCommand, args)) return *exit;
  const absl::StatusOr<InputBudget> budget = InputBudgetFromFlags(cl);
  if (!budget.ok()) return cli::BadInput(kCommand, std::string(budget.status().message()));
  std::string report_dir;
  if (cl.Has("report")) {
    report_dir = cl.Get("report");
    std::error_code ec;
    std::filesystem::create_directories(report_dir, ec);
    if (ec || !std::filesystem::is_directory(report_dir)) {
      return cli::BadInput(
          kCommand, absl::StrCat("--report ", report_dir, ": not a directory that can be created (",
                                 ec ? ec.message() : "a file is in the way", ")"));
    }
  }
  const absl::StatusOr<Capture> capture = ReadCapture(cl.Get("capture"), *budget);
  if (!capture.ok()) return cli::BadInput(kCommand, std::string(capture.status().message()));
  std::fprintf(stderr, "calibrate: %zu sensors of %s\n", capture->manifest.sensors.size(),
               capture->dir.c_str());
  CaptureCalibrationOptions options;
  options.keep_first_frame_features = !report_dir.empty();
  const absl::StatusOr<CycleCalibration> cycle = CalibrateCapture(*capture, options);
  if (!cycle.ok()) return cli::BadInput(kCommand, std::string(cycle.status().message()));
  if (!report_dir.empty()) {
    for (const SensorCalibration& s : cycle->sensors) {
      const SensorModel* sensor = capture->car.FindSensor(s.name);
      const CaptureSensor* recorded = capture->manifest.FindSensor(s.name);
      if (s.kind != SensorKind::kCamera || recorded == nullptr || recorded->frames.empty())
        continue;
      const std::string frame = capture->PathOf(recorded->frames.front());
      const absl::StatusOr<Image8> image = ReadImage8(frame);
      if (!image.ok()) {
        std::fprintf(stderr, "calibrate: no report for %s: %s\n", s.name.c_str(),
                     std::string(image.status().message()).c_str());
        continue;
      }
      const std::string out = (std::filesystem::path(report_dir) / (s.name + ".png")).string();
      if (absl::Status w =
              WritePngRgb(out, DrawCalibrationReport(image->view(), *capture, *sensor, s));
          !w.ok()) {
        return cli::BadInput(kCommand, absl::StrCat("--report ", report_dir, ": ", w.message()));
      }
      std::fprintf(stderr, "calibrate: wrote %s\n", out.c_str());
    }
  }
  if (cl.Has("json")) {
    std::printf("%s\n", CycleCalibrationToJson(*capture, *cycle).dump(2).c_str());
  } else {
    PrintTable(*capture, *cycle);
  }
  return cycle->verdict == Verdict::kPass ? cli::kExitOk : cli::kExitNegative;
}

}  // namespace linecal::tools

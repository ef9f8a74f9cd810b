// linecal radar calibrate: a radar's mounting yaw from the corner reflectors of a capture
// (docs/lidar-radar.md, "Radar calibration").
#include <cstdio>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>

#include "absl/strings/str_cat.h"
#include "station/capture/capture.h"
#include "station/io/candump.h"
#include "station/model/pose_json.h"
#include "station/sensors/radar/radar_decoder.h"
#include "station/solvers/radar_calibration.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "radar calibrate";
constexpr double kDegPerRad = 180.0 / std::numbers::pi;

// printf-formats one number, for table cells that may also be "-".
std::string Format(const char* format, double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, format, v);
  return buffer;
}

nlohmann::json ResultJson(const SensorModel& sensor, const RadarCalibrationRun& run) {
  const RadarCalibrationResult& r = run.result;
  nlohmann::json reflectors = nlohmann::json::array();
  for (const ReflectorObservation& o : run.association.reflectors) {
    nlohmann::json j = {{"id", o.reflector_id},
                        {"status", ReflectorStatusName(o.status)},
                        {"expected_range_m", o.expected_range_m},
                        {"expected_azimuth_deg", o.expected_azimuth_rad * kDegPerRad},
                        {"cycles_with_candidates", o.cycles_with_candidates},
                        {"ambiguous_cycles", o.ambiguous_cycles},
                        {"outliers", o.outliers},
                        {"n_used", o.n_used}};
    if (o.status == ReflectorStatus::kFound) {
      j["range_m"] = o.range_m;
      j["range_se_m"] = o.range_se_m;
      j["azimuth_deg"] = o.azimuth_rad * kDegPerRad;
      j["azimuth_se_deg"] = o.azimuth_se_rad * kDegPerRad;
    }
    for (const RadarReflectorResidual& res : r.residuals) {
      if (res.reflector_id == o.reflector_id) j["residual_deg"] = res.residual_rad * kDegPerRad;
    }
    reflectors.push_back(std::move(j));
  }
  return {{"sensor", sensor.name},
          {"model", sensor.model},
          {"verdict", VerdictName(r.verdict)},
          {"reason", r.reason},
          {"cycles", run.association.cycles},
          {"reflectors_used", r.reflectors_used},
          {"yaw_deg", r.yaw_rad * kDegPerRad},
          {"yaw_sigma_deg", r.yaw_sigma_rad * kDegPerRad},
          {"yaw_ci95_deg", r.yaw_ci95_rad * kDegPerRad},
          {"nominal_yaw_deg", r.nominal_yaw_rad * kDegPerRad},
          {"yaw_deviation_deg", r.yaw_deviation_rad * kDegPerRad},
          {"yaw_tolerance_deg", r.yaw_tolerance_rad * kDegPerRad},
          {"pitch_deg", r.pitch_rad * kDegPerRad},
          {"roll_deg", r.roll_rad * kDegPerRad},
          {"pitch_observable", r.pitch_observable},
          {"position", "nominal"},
          {"chi2", r.chi2},
          {"dof", r.dof},
          {"T_car_sensor", MatrixToJson(r.T_car_radar.Matrix())},
          {"reflectors", std::move(reflectors)}};
}

void PrintTable(const SensorModel& sensor, const RadarCalibrationRun& run) {
  const RadarCalibrationResult& r = run.result;
  std::printf("radar %s (%s): %s%s%s\n", sensor.name.c_str(), sensor.model.c_str(),
              VerdictName(r.verdict), r.reason.empty() ? "" : " ", r.reason.c_str());
  if (r.reflectors_used > 0) {
    std::printf(
        "  yaw %.4f deg (1-sigma %.4f deg, 95%% +-%.4f deg), nominal %.4f deg, deviation %+.4f "
        "deg, tolerance +-%.3f deg\n",
        r.yaw_rad * kDegPerRad, r.yaw_sigma_rad * kDegPerRad, r.yaw_ci95_rad * kDegPerRad,
        r.nominal_yaw_rad * kDegPerRad, r.yaw_deviation_rad * kDegPerRad,
        r.yaw_tolerance_rad * kDegPerRad);
  }
  std::printf(
      "  pitch and roll not observable (no elevation): nominal %.3f / %.3f deg; position nominal\n",
      // + 0.0 prints a -0 as 0.
      r.pitch_rad * kDegPerRad + 0.0, r.roll_rad * kDegPerRad + 0.0);
  std::printf("  %-24s %-18s %5s %9s %13s %13s %12s\n", "reflector", "status", "n", "range_m",
              "azimuth_deg", "expected_deg", "residual_deg");
  for (const ReflectorObservation& o : run.association.reflectors) {
    std::string residual = "-";
    for (const RadarReflectorResidual& res : r.residuals) {
      if (res.reflector_id == o.reflector_id) {
        residual = Format("%+.4f", res.residual_rad * kDegPerRad);
      }
    }
    const bool found = o.status == ReflectorStatus::kFound;
    std::printf("  %-24s %-18s %5d %9s %13s %13.4f %12s\n", o.reflector_id.c_str(),
                ReflectorStatusName(o.status), o.n_used,
                found ? Format("%.3f", o.range_m).c_str() : "-",
                found ? Format("%.4f", o.azimuth_rad * kDegPerRad).c_str() : "-",
                o.expected_azimuth_rad * kDegPerRad, residual.c_str());
  }
}

}  // namespace

int RunRadarCalibrate(const Args& args) {
  cli::CommandLine cl(
      "linecal radar calibrate --capture DIR --sensor NAME [--json]",
      "Calibrates one radar of a capture: decodes its CAN log, associates detections with the "
      "station's corner reflectors (gated around where the nominal mounting expects them), and "
      "solves the mounting yaw from their azimuths. Pitch and roll are not observable (the "
      "radars report no elevation) and the position is taken as nominal. Prints yaw, deviation "
      "from nominal, 1-sigma and the verdict against the car model's yaw tolerance. Exit 0 on "
      "pass, 1 on fail or when it cannot calibrate (reason), 2 on bad usage or input.",
      {{"capture", "DIR", "capture directory", true},
       {"sensor", "NAME", "radar sensor of the car model", true},
       {"json", "", "print one JSON object"}});
  if (const std::optional<int> exit = cli::ParseOrExit(cl, kCommand, args)) return *exit;

  const absl::StatusOr<Capture> capture = ReadCapture(cl.Get("capture"));
  if (!capture.ok()) return cli::BadInput(kCommand, std::string(capture.status().message()));
  const std::string name = cl.Get("sensor");
  const SensorModel* sensor = capture->car.FindSensor(name);
  if (sensor == nullptr) {
    return cli::BadInput(kCommand, absl::StrCat("--sensor: car model '", capture->car.id,
                                                "' has no sensor '", name, "'"));
  }
  if (sensor->kind != SensorKind::kRadar) {
    return cli::BadInput(kCommand, absl::StrCat("--sensor: '", name, "' is a ",
                                                SensorKindName(sensor->kind), ", not a radar"));
  }
  const CaptureSensor* recorded = capture->manifest.FindSensor(name);
  if (recorded == nullptr || !recorded->can_log) {
    return cli::BadInput(kCommand, absl::StrCat(capture->dir, "/", kCaptureManifestFile,
                                                ": no CAN log for sensor '", name, "'"));
  }
  const std::optional<RadarModel> model = ParseRadarModel(sensor->model);
  if (!model) {
    return cli::BadInput(
        kCommand, absl::StrCat("sensor '", name, "': unknown radar model '", sensor->model, "'"));
  }
  const absl::StatusOr<std::vector<CanFrame>> frames =
      ReadCandumpLog(capture->PathOf(*recorded->can_log));
  if (!frames.ok()) return cli::BadInput(kCommand, std::string(frames.status().message()));
  const RadarDecodeResult decoded = DecodeRadarFrames(*frames, *model, RadarConventions{});
  const absl::StatusOr<RadarCalibrationRun> run =
      CalibrateRadar(*sensor, capture->station, capture->manifest.aligner.T_station_car(),
                     decoded.cycles, RadarCalibrationOptions{});
  if (!run.ok()) return cli::BadInput(kCommand, std::string(run.status().message()));

  if (cl.Has("json")) {
    std::printf("%s\n", ResultJson(*sensor, *run).dump(2).c_str());
  } else {
    PrintTable(*sensor, *run);
  }
  return run->result.verdict == Verdict::kPass ? cli::kExitOk : cli::kExitNegative;
}

}  // namespace linecal::tools

// linecal plan / linecal plan check: the board placement planner (station/planner/planner.h,
// docs/planner.md) on the command line, with its JSON and drawings.
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "station/io/json_reader.h"
#include "station/planner/planner.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"
#include "tools/linecal/plan_drawing.h"

namespace linecal::tools {
namespace {

constexpr double kDegPerRad = 180.0 / std::numbers::pi;

nlohmann::json SigmaJson(const SensorAssessment& a) {
  if (!a.sigma_valid) return nullptr;
  const char* names[6] = {"yaw_deg", "pitch_deg", "roll_deg", "x_m", "y_m", "z_m"};
  nlohmann::json j = nlohmann::json::object();
  for (int i = 0; i < 6; ++i) {
    j[names[i]] = a.observed[i] ? nlohmann::json(a.sigma[i] * (i < 3 ? kDegPerRad : 1.0))
                                : nlohmann::json(nullptr);
  }
  return j;
}

nlohmann::json AssessmentJson(const SensorAssessment& a) {
  nlohmann::json targets = nlohmann::json::array();
  for (const TargetAssessment& t : a.targets) {
    nlohmann::json j = {
        {"id", t.target}, {"reasons", t.reasons}, {"detail", t.detail}, {"features", t.features}};
    if (a.kind != SensorKind::kRadar) {
      j["hidden_share"] = t.hidden_share;
      j["hidden_by"] = t.hidden_by.empty() ? nlohmann::json(nullptr) : nlohmann::json(t.hidden_by);
    }
    if (a.kind == SensorKind::kCamera) j["smallest_feature_px"] = t.smallest_feature_px;
    if (a.kind == SensorKind::kLidar) j["fewest_rings_through_a_hole"] = t.fewest_rings;
    targets.push_back(j);
  }
  return {{"name", a.sensor},
          {"kind", SensorKindName(a.kind)},
          {"calibratable", a.calibratable},
          {"reasons", a.reasons},
          {"predicted_sigma", SigmaJson(a)},
          {"uncertainty_ratio",
           a.sigma_valid ? nlohmann::json(a.uncertainty_ratio) : nlohmann::json(nullptr)},
          {"targets", targets}};
}

nlohmann::json RegionJson(const ValidRegion& r) {
  nlohmann::json polygon = nlohmann::json::array();
  for (const Eigen::Vector2d& p : r.polygon) polygon.push_back({p.x(), p.y()});
  return {{"sensor", r.sensor},
          {"target", r.target},
          {"distance_m", {r.distance_min_m, r.distance_max_m}},
          {"lateral_m", {r.lateral_min_m, r.lateral_max_m}},
          {"height_m", {r.height_min_m, r.height_max_m}},
          {"heading_deg", {r.heading_min_deg, r.heading_max_deg}},
          {"polygon_m", polygon}};
}

void PrintAssessments(const std::vector<SensorAssessment>& sensors) {
  std::printf("  %-20s %-7s %-13s %9s %9s %9s %7s %7s %7s  %s\n", "sensor", "kind", "calibratable",
              "s_yaw_deg", "s_pitch", "s_roll", "s_x_mm", "s_y_mm", "s_z_mm", "reasons");
  for (const SensorAssessment& a : sensors) {
    std::string numbers;
    for (int i = 0; i < 6; ++i) {
      numbers += a.sigma_valid && a.observed[i]
                     ? absl::StrFormat(i < 3 ? " %9.4f" : " %7.2f",
                                       a.sigma[i] * (i < 3 ? kDegPerRad : 1e3))
                     : absl::StrFormat(i < 3 ? " %9s" : " %7s", "-");
    }
    std::printf("  %-20s %-7s %-13s%s  %s\n", a.sensor.c_str(), SensorKindName(a.kind),
                a.calibratable ? "yes" : "no", numbers.c_str(),
                a.reasons.empty() ? "-" : absl::StrJoin(a.reasons, ",").c_str());
    for (const TargetAssessment& t : a.targets) {
      // Failed targets, and partly hidden ones (usable: the detectors find them from what shows).
      if (!t.reasons.empty() || !t.hidden_by.empty()) {
        std::printf("      %s: %s%s\n", t.target.c_str(),
                    t.reasons.empty() ? "usable;" : absl::StrJoin(t.reasons, ",").c_str(),
                    t.detail.c_str());
      }
    }
  }
}

bool AllCalibratable(const std::vector<SensorAssessment>& sensors) {
  for (const SensorAssessment& a : sensors) {
    if (!a.calibratable) return false;
  }
  return true;
}

// The options both subcommands share; nullopt after printing the problem.
std::optional<PlannerOptions> ReadOptions(const cli::CommandLine& cl, const std::string& command) {
  PlannerOptions o;
  const absl::StatusOr<double> feature = cl.GetDouble("min-feature-px", o.min_feature_px);
  const absl::StatusOr<double> noise = cl.GetDouble("corner-noise-px", o.corner_noise_px);
  const absl::StatusOr<double> fisheye_noise =
      cl.GetDouble("fisheye-corner-noise-px", o.fisheye_corner_noise_px);
  const absl::StatusOr<int> frames = cl.GetInt("frames", o.camera_frames);
  for (const absl::Status& s :
       {feature.status(), noise.status(), fisheye_noise.status(), frames.status()}) {
    if (!s.ok()) {
      cli::BadInput(command, std::string(s.message()));
      return std::nullopt;
    }
  }
  o.min_feature_px = *feature;
  o.corner_noise_px = *noise;
  o.fisheye_corner_noise_px = *fisheye_noise;
  o.camera_frames = *frames;
  o.regions = !cl.Has("no-regions");
  if (absl::Status s = o.Validate(); !s.ok()) {
    // Name the flag, not the struct field.
    const std::string m(s.message());
    const std::string flag = m.rfind("min_feature_px", 0) == 0    ? "--min-feature-px"
                             : m.rfind("corner_noise_px", 0) == 0 ? "--corner-noise-px"
                             : m.rfind("fisheye_corner_noise_px", 0) == 0
                                 ? "--fisheye-corner-noise-px"
                             : m.rfind("camera_frames", 0) == 0 ? "--frames"
                                                                : "option";
    cli::BadInput(command, absl::StrCat(flag, ": ", m));
    return std::nullopt;
  }
  return o;
}

const std::vector<cli::OptionSpec> kSharedOptions = {
    {"min-feature-px", "PX", "smallest imaged square or marker cell, pixels (default 15)"},
    {"corner-noise-px", "PX", "camera corner noise of the predicted sigma, pixels (default 0.1)"},
    {"fisheye-corner-noise-px", "PX", "the same for fisheye cameras (default: --corner-noise-px)"},
    {"frames", "N", "camera frames the calibration will use (default 1)"},
    {"json", "", "print one JSON object"}};

}  // namespace

int RunPlan(const Args& args) {
  std::vector<cli::OptionSpec> options = {
      {"car", "FILE", "car model (deploy/cars/*.json)", true},
      {"floor", "FILE", "floor limits (e.g. deploy/stations/reference-floor.json)", true},
      {"out", "DIR", "where to write station.json, car.json, plan.json and the drawings", true},
      {"no-regions", "", "skip the valid regions (the slow part)"}};
  options.insert(options.end(), kSharedOptions.begin(), kSharedOptions.end());
  cli::CommandLine cl(
      "linecal plan --car FILE --floor FILE --out DIR [--min-feature-px 15] [--json]",
      "Plans where to put the calibration boards and radar reflectors for a car model in a "
      "station: per "
      "sensor the target of lowest predicted calibration uncertainty that passes every check "
      "(field of view, "
      "feature size, LiDAR rings through every hole, clear lines of sight, keep-out zones, height "
      "limits). "
      "Writes the layout (station.json, the deploy/stations format), the car model with its "
      "sensors' new "
      "targets (car.json), plan.json (predicted sigma, valid regions) and drawings (birdseye and "
      "side_<sensor>, "
      "SVG and PNG) into --out. Exit 0 when every sensor is calibratable, 1 when not, 2 on bad "
      "input.",
      options);
  constexpr char kCommand[] = "plan";
  if (const std::optional<int> exit = cli::ParseOrExit(cl, kCommand, args)) return *exit;
  const std::optional<PlannerOptions> o = ReadOptions(cl, kCommand);
  if (!o) return cli::kExitBadInput;
  const absl::StatusOr<CarModel> car = ReadCarModel(cl.Get("car"));
  if (!car.ok()) return cli::BadInput(kCommand, std::string(car.status().message()));
  const absl::StatusOr<FloorLimits> floor = ReadFloorLimits(cl.Get("floor"));
  if (!floor.ok()) return cli::BadInput(kCommand, std::string(floor.status().message()));
  const absl::StatusOr<StationPlan> plan = PlanLayout(*car, *floor, *o);
  if (!plan.ok()) return cli::BadInput(kCommand, std::string(plan.status().message()));

  const std::filesystem::path out = cl.Get("out");
  std::error_code ec;
  std::filesystem::create_directories(out, ec);
  if (ec) return cli::BadInput(kCommand, absl::StrCat("--out ", out.string(), ": ", ec.message()));
  nlohmann::json sensors = nlohmann::json::array();
  for (const SensorAssessment& a : plan->sensors) sensors.push_back(AssessmentJson(a));
  nlohmann::json regions = nlohmann::json::array();
  for (const ValidRegion& r : plan->regions) regions.push_back(RegionJson(r));
  const nlohmann::json doc = {
      {"format", "linecal.plan"},
      {"version", 1},
      {"car", car->id},
      {"floor", floor->name},
      {"options",
       {{"min_feature_px", o->min_feature_px},
        {"corner_noise_px", o->corner_noise_px},
        {"fisheye_corner_noise_px", o->fisheye_corner_noise_px},
        {"camera_frames", o->camera_frames},
        {"max_sigma_fraction_of_tolerance", o->max_sigma_fraction_of_tolerance}}},
      {"calibratable", AllCalibratable(plan->sensors)},
      {"station", StationLayoutToJson(plan->layout)},
      {"sensors", sensors},
      {"valid_regions", regions}};
  for (const auto& [name, j] :
       {std::pair<std::string, nlohmann::json>{"station.json", StationLayoutToJson(plan->layout)},
        {"car.json", CarModelToJson(plan->car)},
        {"plan.json", doc}}) {
    if (absl::Status s = WriteJsonFile((out / name).string(), j); !s.ok()) {
      return cli::BadInput(kCommand, std::string(s.message()));
    }
  }
  const PlanScene scene{&plan->car, &plan->layout, &*floor, &plan->sensors, &plan->regions};
  if (absl::Status s = WritePlanDrawings(scene, out.string()); !s.ok()) {
    return cli::BadInput(kCommand, std::string(s.message()));
  }
  if (cl.Has("json")) {
    std::printf("%s\n", doc.dump(2).c_str());
  } else {
    std::printf("plan for car %s in %s: %zu boards, %zu reflectors -> %s\n", car->id.c_str(),
                floor->name.c_str(), plan->layout.boards.size(), plan->layout.reflectors.size(),
                out.string().c_str());
    PrintAssessments(plan->sensors);
  }
  return AllCalibratable(plan->sensors) ? cli::kExitOk : cli::kExitNegative;
}

int RunPlanCheck(const Args& args) {
  std::vector<cli::OptionSpec> options = {
      {"station", "FILE", "station layout (deploy/stations/*.json)", true},
      {"car", "FILE", "car model (deploy/cars/*.json)", true},
      {"floor", "FILE", "floor limits: adds the keep-out, usable-area and height checks"},
      {"out", "DIR", "also write the drawings (birdseye, side_<sensor>; SVG and PNG) here"}};
  options.insert(options.end(), kSharedOptions.begin(), kSharedOptions.end());
  cli::CommandLine cl(
      "linecal plan check --station FILE --car FILE [--floor FILE] [--out DIR] [--json]",
      "Says for every sensor of the car whether it can be calibrated with this station layout and, "
      "when not, "
      "why (reason codes of docs/planner.md: board_outside_fov, features_too_small, too_few_rings, "
      "occluded_by_board, in_keep_out, uncertainty_above_tolerance, ...). Exit 0 when every sensor "
      "is "
      "calibratable, 1 when some are not, 2 on bad input.",
      options);
  constexpr char kCommand[] = "plan check";
  if (const std::optional<int> exit = cli::ParseOrExit(cl, kCommand, args)) return *exit;
  const std::optional<PlannerOptions> o = ReadOptions(cl, kCommand);
  if (!o) return cli::kExitBadInput;
  const absl::StatusOr<StationLayout> layout = ReadStationLayout(cl.Get("station"));
  if (!layout.ok()) return cli::BadInput(kCommand, std::string(layout.status().message()));
  const absl::StatusOr<CarModel> car = ReadCarModel(cl.Get("car"));
  if (!car.ok()) return cli::BadInput(kCommand, std::string(car.status().message()));
  std::optional<FloorLimits> floor;
  if (cl.Has("floor")) {
    absl::StatusOr<FloorLimits> f = ReadFloorLimits(cl.Get("floor"));
    if (!f.ok()) return cli::BadInput(kCommand, std::string(f.status().message()));
    floor = *std::move(f);
  }
  const absl::StatusOr<std::vector<SensorAssessment>> sensors =
      AssessLayout(*car, *layout, floor ? &*floor : nullptr, *o);
  if (!sensors.ok()) return cli::BadInput(kCommand, std::string(sensors.status().message()));
  if (cl.Has("out")) {
    const PlanScene scene{&*car, &*layout, floor ? &*floor : nullptr, &*sensors, nullptr};
    if (absl::Status s = WritePlanDrawings(scene, cl.Get("out")); !s.ok()) {
      return cli::BadInput(kCommand, std::string(s.message()));
    }
  }
  if (cl.Has("json")) {
    nlohmann::json list = nlohmann::json::array();
    for (const SensorAssessment& a : *sensors) list.push_back(AssessmentJson(a));
    const nlohmann::json doc = {{"station", layout->name},
                                {"car", car->id},
                                {"calibratable", AllCalibratable(*sensors)},
                                {"sensors", list}};
    std::printf("%s\n", doc.dump(2).c_str());
  } else {
    std::printf("car %s in station %s:\n", car->id.c_str(), layout->name.c_str());
    PrintAssessments(*sensors);
  }
  return AllCalibratable(*sensors) ? cli::kExitOk : cli::kExitNegative;
}

}  // namespace linecal::tools

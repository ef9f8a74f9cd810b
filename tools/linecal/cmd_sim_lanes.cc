// linecal sim lanes: a rendered lane scene for the after-sale tool (docs/simulator.md, "Lane
// scenes"; docs/aftersale.md).
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "station/aftersale/document.h"
#include "station/io/image_io.h"
#include "station/io/json_reader.h"
#include "station/model/pose_json.h"
#include "station/sim/lane_scene.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/car_camera.h"
#include "tools/linecal/commands.h"

namespace linecal::tools {
namespace {

namespace fs = std::filesystem;
constexpr char kCommand[] = "sim lanes";
constexpr double kDeg = std::numbers::pi / 180.0;

nlohmann::json Uv(const Eigen::Vector2d& p) { return {p.x(), p.y()}; }

// The true mounting: `angles` and `xyz` hold the nominal one and are replaced by --ypr-deg
// (degrees) and --xyz-m (metres) when given. The error names the flag and the value.
absl::Status ReadMounting(const cli::CommandLine& cl, YawPitchRoll* angles, Eigen::Vector3d* xyz) {
  if (cl.Has("ypr-deg")) {
    absl::StatusOr<std::vector<double>> v = cli::ParseNumberList(cl.Get("ypr-deg"), "--ypr-deg", 3);
    if (!v.ok()) return v.status();
    *angles = {(*v)[0] * kDeg, (*v)[1] * kDeg, (*v)[2] * kDeg};
  }
  if (cl.Has("xyz-m")) {
    absl::StatusOr<std::vector<double>> v = cli::ParseNumberList(cl.Get("xyz-m"), "--xyz-m", 3);
    if (!v.ok()) return v.status();
    *xyz = Eigen::Vector3d((*v)[0], (*v)[1], (*v)[2]);
  }
  return absl::OkStatus();
}

// The scene's options from the flags, validated, and the seed (--seed, default 1, >= 0) in
// `seed`. The error names the flag and the value.
absl::StatusOr<LaneSceneOptions> ReadSceneOptions(const cli::CommandLine& cl, int* seed) {
  LaneSceneOptions o;
  for (const auto& [flag, slot] :
       {std::pair{"point-noise-px", &o.point_noise_px}, std::pair{"noise", &o.render.noise_sigma},
        std::pair{"blur", &o.render.blur_sigma_px}, std::pair{"lane-width-m", &o.lane_width_m},
        std::pair{"lane-centre-m", &o.lane_centre_y_m},
        std::pair{"roll-line-m", &o.roll_line_distance_m},
        std::pair{"marked-point-m", &o.marked_point_distance_m}}) {
    absl::StatusOr<double> v = cl.GetDouble(flag, *slot);
    if (!v.ok()) return v.status();
    *slot = *v;
  }
  absl::StatusOr<int> seed_flag = cl.GetInt("seed", 1);
  if (!seed_flag.ok()) return seed_flag.status();
  if (*seed_flag < 0)
    return absl::InvalidArgumentError(absl::StrCat("--seed: must be >= 0, got ", *seed_flag));
  *seed = *seed_flag;
  if (cl.Has("points-m")) {
    absl::StatusOr<std::vector<double>> v =
        cli::ParseNumberList(cl.Get("points-m"), "--points-m", 0);
    if (!v.ok()) return v.status();
    o.point_distances_m = *v;
  }
  if (cl.Has("markers-m")) {
    absl::StatusOr<std::vector<double>> v =
        cli::ParseNumberList(cl.Get("markers-m"), "--markers-m", 2);
    if (!v.ok()) return v.status();
    o.marker_distances_m = {(*v)[0], (*v)[1]};
  }
  o.paint_lane_lines = !cl.Has("no-lane-lines");
  if (!o.paint_lane_lines && o.marker_distances_m[0] == 0) {
    return absl::InvalidArgumentError(
        "--no-lane-lines: needs --markers-m (else nothing is painted to calibrate from)");
  }
  if (absl::Status s = o.Validate(); !s.ok()) return s;
  return o;
}

// aftersale.json: the input of `linecal aftersale` for the rendered scene, with the lane
// lines' points (or the markers'), the roll line and the marked point where the scene has them.
nlohmann::json AftersaleInputJson(const SensorModel& sensor, const Eigen::Vector3d& xyz,
                                  const YawPitchRoll& angles, const LaneSceneOptions& o,
                                  const LaneScene& scene, const std::string& image_name) {
  nlohmann::json input =
      AftersaleCameraInput(sensor.name, *sensor.intrinsics, xyz, std::cos(angles.yaw) < 0);
  input["image"] = image_name;
  if (o.paint_lane_lines && o.marker_distances_m[0] == 0) {
    nlohmann::json lanes = nlohmann::json::array();
    for (const auto& lane : scene.lanes_px) {
      nlohmann::json points = nlohmann::json::array();
      for (const Eigen::Vector2d& p : lane) points.push_back(Uv(p));
      lanes.push_back(points);
    }
    input["lanes"] = lanes;
  } else {
    nlohmann::json markers = nlohmann::json::array();
    for (const Eigen::Vector2d& p : scene.markers_px) markers.push_back(Uv(p));
    input["markers"] = markers;
  }
  if (scene.has_roll_line)
    input["roll_line"] = {Uv(scene.roll_line_px[0]), Uv(scene.roll_line_px[1])};
  if (scene.has_marked_point) {
    input["marked_point"] = {{"uv_px", Uv(scene.marked_point_px)},
                             {"measured_distance_m", o.marked_point_distance_m}};
  }
  return input;
}

// Writes the image and the two JSON files into `dir`; prints the writer's error and returns
// false when one cannot be written.
bool WriteSceneFiles(const fs::path& dir, const std::string& image_name, const LaneScene& scene,
                     const nlohmann::json& input, const nlohmann::json& truth) {
  if (absl::Status s = WritePng8((dir / image_name).string(), scene.frame.image8.view()); !s.ok()) {
    std::fprintf(stderr, "linecal sim lanes: %s\n", std::string(s.message()).c_str());
    return false;
  }
  for (const auto& [name, j] :
       {std::pair{"aftersale.json", &input}, std::pair{"ground_truth.json", &truth}}) {
    if (absl::Status s = WriteJsonFile((dir / name).string(), *j); !s.ok()) {
      std::fprintf(stderr, "linecal sim lanes: %s\n", std::string(s.message()).c_str());
      return false;
    }
  }
  return true;
}

}  // namespace

int RunSimLanes(const Args& args) {
  cli::CommandLine cl(
      "linecal sim lanes --car FILE --camera NAME --out DIR [--ypr-deg Y,P,R] [--xyz-m X,Y,Z] "
      "[options]",
      "Renders two lane lines (and a roll line, markers) painted on the ground ahead of one camera "
      "of the car "
      "model at its nominal mounting or the one given, and writes the image <camera>.png, "
      "aftersale.json (the "
      "input of linecal aftersale: the exact image points, plus noise if asked) and "
      "ground_truth.json.",
      {{"car", "FILE", "car model (e.g. deploy/cars/reference.json)", true},
       {"camera", "NAME", "the camera of the car model", true},
       {"out", "DIR", "directory to write", true},
       {"ypr-deg", "Y,P,R", "the true mounting angles, degrees (default the nominal ones)"},
       {"xyz-m", "X,Y,Z", "the true position in the car frame, metres (default the nominal one)"},
       {"seed", "N", "random seed (default 1)"},
       {"point-noise-px", "SIGMA", "Gaussian noise on the listed points, pixels (default 0)"},
       {"noise", "SIGMA", "image noise, grey levels (default 0)"},
       {"blur", "SIGMA", "image blur, pixels (default 0)"},
       {"lane-width-m", "W", "distance between the lane lines' centre lines (default 3.5)"},
       {"lane-centre-m", "Y", "the lane's centre, y in the car frame (default 0)"},
       {"points-m", "D,D[,...]",
        "distances ahead of the camera of the points on each line (default 6,25)"},
       {"roll-line-m", "D", "the roll line's distance ahead of the camera, 0 = none (default 8)"},
       {"markers-m", "NEAR,FAR",
        "four markers at these distances instead of lane points (default none)"},
       {"no-lane-lines", "", "paint no lane lines (with --markers-m)"},
       {"marked-point-m", "D",
        "the marked point's distance, on the lane's centre line, 0 = none (default 15)"},
       {"json", "", "print the summary as JSON"}});
  if (auto code = cli::ParseOrExit(cl, kCommand, args)) return *code;

  absl::StatusOr<SensorModel> camera_sensor = ReadCarCamera(cl.Get("car"), cl.Get("camera"));
  if (!camera_sensor.ok())
    return cli::BadInput(kCommand, std::string(camera_sensor.status().message()));
  const SensorModel* sensor = &*camera_sensor;

  const Eigen::Matrix3d r_base = CameraBaseRotation();
  YawPitchRoll angles = MountingAngles(sensor->T_car_sensor_nominal.RotationMatrix(), r_base);
  Eigen::Vector3d xyz = sensor->T_car_sensor_nominal.translation();
  if (absl::Status s = ReadMounting(cl, &angles, &xyz); !s.ok()) {
    return cli::BadInput(kCommand, std::string(s.message()));
  }
  int seed = 1;
  const absl::StatusOr<LaneSceneOptions> options = ReadSceneOptions(cl, &seed);
  if (!options.ok()) return cli::BadInput(kCommand, std::string(options.status().message()));
  const LaneSceneOptions& o = *options;

  const CameraModel camera = *CameraModel::Create(*sensor->intrinsics);
  const Rigid3d T_car_camera(MountingRotation(angles, r_base), xyz);
  absl::StatusOr<LaneScene> scene =
      RenderLaneScene(camera, T_car_camera, o, static_cast<std::uint64_t>(seed));
  if (!scene.ok()) return cli::BadInput(kCommand, std::string(scene.status().message()));

  const fs::path dir = cl.Get("out");
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec)
    return cli::BadInput(kCommand,
                         absl::StrCat("--out: cannot create ", dir.string(), ": ", ec.message()));
  const std::string image_name = sensor->name + ".png";
  const nlohmann::json input = AftersaleInputJson(*sensor, xyz, angles, o, *scene, image_name);
  const nlohmann::json truth = {
      {"format", "linecal.lane_scene_truth"},
      {"version", 1},
      {"seed", seed},
      {"camera", sensor->name},
      {"ypr_deg", {angles.yaw / kDeg, angles.pitch / kDeg, angles.roll / kDeg}},
      {"xyz_m", {xyz.x(), xyz.y(), xyz.z()}},
      {"T_car_camera", PoseToJson(T_car_camera, r_base)},
      {"vanishing_point_px", Uv(scene->vanishing_point_px)},
      {"point_noise_px", o.point_noise_px}};
  if (!WriteSceneFiles(dir, image_name, *scene, input, truth)) return cli::kExitNegative;
  if (cl.Has("json")) {
    std::printf("%s\n", nlohmann::json{{"image", (dir / image_name).string()},
                                       {"input", (dir / "aftersale.json").string()},
                                       {"ground_truth", (dir / "ground_truth.json").string()},
                                       {"truth", truth}}
                            .dump(2)
                            .c_str());
  } else {
    std::printf(
        "lane scene of %s written to %s (image %s, input aftersale.json, truth "
        "ground_truth.json)\n",
        sensor->name.c_str(), dir.string().c_str(), image_name.c_str());
  }
  return cli::kExitOk;
}

}  // namespace linecal::tools

#include "station/model/car_model.h"

#include <filesystem>
#include <numbers>
#include <set>

#include "absl/strings/str_cat.h"
#include "detectors/core/image_view.h"
#include "station/io/json_reader.h"
#include "station/model/pose_json.h"
#include "station/model/station_layout.h"
#include "station/sensors/lidar/lidar_format.h"

namespace linecal {
namespace {

constexpr const char* kFormat = "linecal.car";
constexpr int kVersion = 1;
constexpr double kDegToRad = std::numbers::pi / 180.0;

absl::StatusOr<CameraIntrinsics> ReadIntrinsics(const JsonField& parent, const std::string& model) {
  absl::StatusOr<JsonField> f = parent.Object("intrinsics");
  if (!f.ok()) return f.status();
  CameraIntrinsics in;
  if (model == "pinhole") {
    in.type = CameraModelType::kPinhole;
    if (auto s = f->AllowOnlyKeys(
            {"width", "height", "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"});
        !s.ok()) {
      return s;
    }
  } else {
    in.type = CameraModelType::kFisheye;
    if (auto s =
            f->AllowOnlyKeys({"width", "height", "fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"});
        !s.ok()) {
      return s;
    }
  }
  for (const auto& [key, slot] : {std::pair{"width", &in.width}, std::pair{"height", &in.height}}) {
    absl::StatusOr<std::int64_t> v = f->Integer(key);
    if (!v.ok()) return v.status();
    if (*v < 1 || *v > kMaxImageSide) {
      return f->Error(key, absl::StrCat("must be within 1..", kMaxImageSide, ", got ", *v));
    }
    *slot = static_cast<int>(*v);
  }
  for (const auto& [key, slot] : {std::pair{"fx", &in.fx}, std::pair{"fy", &in.fy},
                                  std::pair{"cx", &in.cx}, std::pair{"cy", &in.cy}}) {
    absl::StatusOr<double> v = f->Number(key);
    if (!v.ok()) return v.status();
    *slot = *v;
  }
  for (const auto& [key, slot] :
       {std::pair{"k1", &in.k1}, std::pair{"k2", &in.k2}, std::pair{"k3", &in.k3},
        std::pair{"k4", &in.k4}, std::pair{"p1", &in.p1}, std::pair{"p2", &in.p2}}) {
    if (!f->Has(key)) continue;
    absl::StatusOr<double> v = f->Number(key);
    if (!v.ok()) return v.status();
    *slot = *v;
  }
  // CameraIntrinsics::Validate names the field first ("fx = -3: ..."); prefix the path.
  if (absl::Status s = in.Validate(); !s.ok()) return f->Error(std::string(s.message()));
  return in;
}

absl::StatusOr<MountingTolerance> ReadTolerance(const JsonField& parent) {
  absl::StatusOr<JsonField> f = parent.Object("tolerance");
  if (!f.ok()) return f.status();
  if (auto s = f->AllowOnlyKeys({"ypr_deg", "xyz_m"}); !s.ok()) return s;
  absl::StatusOr<std::vector<double>> ypr = f->Numbers("ypr_deg", 3);
  if (!ypr.ok()) return ypr.status();
  absl::StatusOr<std::vector<double>> xyz = f->Numbers("xyz_m", 3);
  if (!xyz.ok()) return xyz.status();
  for (int i = 0; i < 3; ++i) {
    // A tolerance is a half-width: it must be positive, and beyond 45 degrees or 1 m it
    // checks nothing and is surely a unit mistake.
    if ((*ypr)[i] <= 0 || (*ypr)[i] > 45) {
      return f->Error(absl::StrCat("ypr_deg[", i, "]"),
                      absl::StrCat("must be within (0, 45], got ", (*ypr)[i]));
    }
    if ((*xyz)[i] <= 0 || (*xyz)[i] > 1) {
      return f->Error(absl::StrCat("xyz_m[", i, "]"),
                      absl::StrCat("must be within (0, 1], got ", (*xyz)[i]));
    }
  }
  MountingTolerance t;
  t.yaw_rad = (*ypr)[0] * kDegToRad;
  t.pitch_rad = (*ypr)[1] * kDegToRad;
  t.roll_rad = (*ypr)[2] * kDegToRad;
  t.xyz_m = Eigen::Vector3d((*xyz)[0], (*xyz)[1], (*xyz)[2]);
  return t;
}

absl::StatusOr<SensorModel> ReadSensor(const JsonField& f, const std::filesystem::path& base_dir) {
  if (auto s = f.AllowOnlyKeys({"name", "kind", "model", "nominal", "tolerance", "intrinsics",
                                "angles_file", "radar_sensor_id", "targets"});
      !s.ok()) {
    return s;
  }
  SensorModel m;
  absl::StatusOr<std::string> name = f.String("name");
  if (!name.ok()) return name.status();
  if (name->empty()) return f.Error("name", "must not be empty");
  m.name = *name;
  absl::StatusOr<std::string> kind = f.String("kind");
  if (!kind.ok()) return kind.status();
  absl::StatusOr<std::string> model = f.String("model");
  if (!model.ok()) return model.status();
  m.model = *model;
  if (*kind == "camera") {
    m.kind = SensorKind::kCamera;
    if (*model != "pinhole" && *model != "fisheye") {
      return f.Error("model",
                     absl::StrCat("camera model must be pinhole or fisheye, got '", *model, "'"));
    }
    absl::StatusOr<CameraIntrinsics> in = ReadIntrinsics(f, *model);
    if (!in.ok()) return in.status();
    m.intrinsics = *in;
  } else if (*kind == "lidar") {
    m.kind = SensorKind::kLidar;
    if (*model != "vlp16" && *model != "pandar64" && *model != "pandarxt32") {
      return f.Error(
          "model",
          absl::StrCat("lidar model must be vlp16, pandar64 or pandarxt32, got '", *model, "'"));
    }
    absl::StatusOr<std::string> angles = f.StringOr("angles_file", "");
    if (!angles.ok()) return angles.status();
    if (!angles->empty()) {
      const std::filesystem::path p = base_dir / *angles;
      if (!std::filesystem::is_regular_file(p)) {
        return f.Error("angles_file", absl::StrCat("no such file: ", p.string()));
      }
      // Absolute, so that the model means the same file wherever it is written out again.
      m.angles_file = std::filesystem::absolute(p).lexically_normal().string();
    }
  } else if (*kind == "radar") {
    m.kind = SensorKind::kRadar;
    if (*model != "ars408" && *model != "esr") {
      return f.Error("model",
                     absl::StrCat("radar model must be ars408 or esr, got '", *model, "'"));
    }
    absl::StatusOr<std::int64_t> id = f.IntegerOr("radar_sensor_id", 0);
    if (!id.ok()) return id.status();
    // ARS408 sensor ids are 3 bits (CAN id offset n * 0x10).
    if (*id < 0 || *id > 7)
      return f.Error("radar_sensor_id", absl::StrCat("must be within 0..7, got ", *id));
    m.radar_sensor_id = static_cast<int>(*id);
  } else {
    return f.Error("kind", absl::StrCat("must be camera, lidar or radar, got '", *kind, "'"));
  }
  if (m.kind != SensorKind::kCamera && f.Has("intrinsics"))
    return f.Error("intrinsics", "only cameras have intrinsics");
  if (m.kind != SensorKind::kLidar && f.Has("angles_file"))
    return f.Error("angles_file", "only LiDARs have angle files");
  if (m.kind != SensorKind::kRadar && f.Has("radar_sensor_id"))
    return f.Error("radar_sensor_id", "only radars have a sensor id");
  absl::StatusOr<Rigid3d> nominal = ReadPose(f, "nominal", SensorBaseRotation(m.kind));
  if (!nominal.ok()) return nominal.status();
  m.T_car_sensor_nominal = *nominal;
  absl::StatusOr<MountingTolerance> tol = ReadTolerance(f);
  if (!tol.ok()) return tol.status();
  m.tolerance = *tol;
  absl::StatusOr<std::vector<JsonField>> targets = f.Array("targets");
  if (!targets.ok()) return targets.status();
  if (targets->empty()) return f.Error("targets", "a sensor needs at least one target");
  for (const JsonField& t : *targets) {
    absl::StatusOr<std::string> id = t.AsString();
    if (!id.ok()) return id.status();
    m.targets.push_back(*id);
  }
  return m;
}

}  // namespace

const char* SensorKindName(SensorKind kind) {
  switch (kind) {
    case SensorKind::kCamera:
      return "camera";
    case SensorKind::kLidar:
      return "lidar";
    case SensorKind::kRadar:
      return "radar";
  }
  return "unknown";
}

std::optional<SensorKind> ParseSensorKind(std::string_view name) {
  for (SensorKind k : {SensorKind::kCamera, SensorKind::kLidar, SensorKind::kRadar}) {
    if (name == SensorKindName(k)) return k;
  }
  return std::nullopt;
}

Eigen::Matrix3d SensorBaseRotation(SensorKind kind) {
  switch (kind) {
    case SensorKind::kCamera:
      return CameraBaseRotation();
    case SensorKind::kLidar:
      return LidarBaseRotation();
    case SensorKind::kRadar:
      return Eigen::Matrix3d::Identity();
  }
  return Eigen::Matrix3d::Identity();
}

const SensorModel* CarModel::FindSensor(const std::string& name) const {
  for (const SensorModel& s : sensors) {
    if (s.name == name) return &s;
  }
  return nullptr;
}

absl::StatusOr<CarModel> ParseCarModel(const std::string& text, const std::string& source) {
  absl::StatusOr<JsonDocument> doc = JsonDocument::FromText(text, source);
  if (!doc.ok()) return doc.status();
  absl::StatusOr<JsonField> root = doc->Root();
  if (!root.ok()) return root.status();
  if (auto s = root->AllowOnlyKeys({"format", "version", "id", "description", "sensors"}); !s.ok())
    return s;
  absl::StatusOr<std::string> format = root->String("format");
  if (!format.ok()) return format.status();
  if (*format != kFormat)
    return root->Error("format", absl::StrCat("expected '", kFormat, "', got '", *format, "'"));
  absl::StatusOr<std::int64_t> version = root->Integer("version");
  if (!version.ok()) return version.status();
  if (*version != kVersion) {
    return root->Error("version", absl::StrCat("unsupported version ", *version,
                                               " (this build reads ", kVersion, ")"));
  }
  CarModel car;
  absl::StatusOr<std::string> id = root->String("id");
  if (!id.ok()) return id.status();
  car.id = *id;
  absl::StatusOr<std::string> description = root->StringOr("description", "");
  if (!description.ok()) return description.status();
  car.description = *description;
  absl::StatusOr<std::vector<JsonField>> sensors = root->Array("sensors");
  if (!sensors.ok()) return sensors.status();
  const std::filesystem::path base_dir = std::filesystem::path(source).parent_path();
  std::set<std::string> names;
  for (const JsonField& f : *sensors) {
    absl::StatusOr<SensorModel> m = ReadSensor(f, base_dir);
    if (!m.ok()) return m.status();
    if (!names.insert(m->name).second)
      return f.Error("name", absl::StrCat("duplicate sensor name '", m->name, "'"));
    car.sensors.push_back(std::move(*m));
  }
  return car;
}

absl::StatusOr<CarModel> ReadCarModel(const std::string& path) {
  absl::StatusOr<std::string> text = ReadTextFile(path);
  if (!text.ok()) return text.status();
  return ParseCarModel(*text, path);
}

nlohmann::json CarModelToJson(const CarModel& car) {
  nlohmann::json sensors = nlohmann::json::array();
  for (const SensorModel& s : car.sensors) {
    nlohmann::json j = {{"name", s.name}, {"kind", SensorKindName(s.kind)}, {"model", s.model}};
    j["nominal"] = PoseToJson(s.T_car_sensor_nominal, SensorBaseRotation(s.kind));
    const MountingTolerance& t = s.tolerance;
    j["tolerance"] = {
        {"ypr_deg", {t.yaw_rad / kDegToRad, t.pitch_rad / kDegToRad, t.roll_rad / kDegToRad}},
        {"xyz_m", {t.xyz_m.x(), t.xyz_m.y(), t.xyz_m.z()}}};
    if (s.intrinsics) {
      const CameraIntrinsics& in = *s.intrinsics;
      nlohmann::json k = {{"width", in.width}, {"height", in.height}, {"fx", in.fx},
                          {"fy", in.fy},       {"cx", in.cx},         {"cy", in.cy},
                          {"k1", in.k1},       {"k2", in.k2},         {"k3", in.k3}};
      if (in.type == CameraModelType::kPinhole) {
        k["p1"] = in.p1;
        k["p2"] = in.p2;
      } else {
        k["k4"] = in.k4;
      }
      j["intrinsics"] = std::move(k);
    }
    if (!s.angles_file.empty()) j["angles_file"] = s.angles_file;
    if (s.kind == SensorKind::kRadar) j["radar_sensor_id"] = s.radar_sensor_id;
    j["targets"] = s.targets;
    sensors.push_back(std::move(j));
  }
  return {{"format", kFormat},
          {"version", kVersion},
          {"id", car.id},
          {"description", car.description},
          {"sensors", sensors}};
}

absl::StatusOr<LidarBeamTable> LidarBeamTableOf(const SensorModel& sensor) {
  const std::optional<LidarModel> model = LidarModelFromName(sensor.model);
  if (!model)
    return absl::InvalidArgumentError(absl::StrCat("unknown LiDAR model '", sensor.model, "'"));
  return sensor.angles_file.empty() ? DefaultBeamTable(*model)
                                    : ReadAngleCorrectionCsv(*model, sensor.angles_file);
}

absl::Status CheckTargetsExist(const CarModel& car, const StationLayout& layout) {
  for (const SensorModel& s : car.sensors) {
    for (const std::string& t : s.targets) {
      const bool found = s.kind == SensorKind::kRadar ? layout.FindReflector(t) != nullptr
                                                      : layout.FindBoard(t) != nullptr;
      if (!found) {
        return absl::InvalidArgumentError(
            absl::StrCat("station '", layout.name, "' has no ",
                         s.kind == SensorKind::kRadar ? "reflector" : "board", " '", t,
                         "' (sensor '", s.name, "' of car '", car.id, "' targets it)"));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace linecal

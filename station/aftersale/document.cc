#include "station/aftersale/document.h"

#include <cmath>
#include <memory>
#include <numbers>

#include "absl/strings/str_cat.h"
#include "station/model/pose_json.h"

namespace linecal {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

absl::StatusOr<Eigen::Vector2d> PointOf(const JsonField& f) {
  const nlohmann::json& n = f.node();
  if (!n.is_array() || n.size() != 2 || !n[0].is_number() || !n[1].is_number()) {
    return f.Error("must be [u, v], two numbers");
  }
  return Eigen::Vector2d(n[0].get<double>(), n[1].get<double>());
}

absl::StatusOr<std::vector<Eigen::Vector2d>> PointsAt(const JsonField& parent,
                                                      const std::string& key) {
  absl::StatusOr<std::vector<JsonField>> items = parent.Array(key);
  if (!items.ok()) return items.status();
  std::vector<Eigen::Vector2d> out;
  for (const JsonField& item : *items) {
    absl::StatusOr<Eigen::Vector2d> p = PointOf(item);
    if (!p.ok()) return p.status();
    out.push_back(*p);
  }
  return out;
}

absl::Status ReadIntrinsics(const JsonField& k, AftersaleRequest* r) {
  if (absl::Status s = k.AllowOnlyKeys({"model", "fx", "fy", "cx", "cy", "distortion"}); !s.ok())
    return s;
  absl::StatusOr<std::string> model = k.StringOr("model", "pinhole");
  if (!model.ok()) return model.status();
  if (*model != "pinhole" && *model != "fisheye") {
    return k.Error("model", absl::StrCat("must be pinhole or fisheye, got '", *model, "'"));
  }
  r->model = *model == "fisheye" ? CameraModelType::kFisheye : CameraModelType::kPinhole;
  for (const auto& [key, slot] : {std::pair{"fx", &r->fx}, std::pair{"fy", &r->fy},
                                  std::pair{"cx", &r->cx}, std::pair{"cy", &r->cy}}) {
    if (!k.Has(key)) continue;
    absl::StatusOr<double> v = k.Number(key);
    if (!v.ok()) return v.status();
    *slot = *v;
  }
  if (k.Has("distortion")) {
    absl::StatusOr<std::vector<double>> d = k.Numbers("distortion");
    if (!d.ok()) return d.status();
    r->distortion = *d;
  }
  return absl::OkStatus();
}

absl::Status ReadLanes(const JsonField& root, AftersaleRequest* r) {
  absl::StatusOr<std::vector<JsonField>> lanes = root.Array("lanes");
  if (!lanes.ok()) return lanes.status();
  const auto source = std::make_shared<const std::string>(root.source());
  r->lanes_px.clear();
  for (const JsonField& lane : *lanes) {
    if (!lane.node().is_array()) return lane.Error("must be an array of [u, v] points");
    std::vector<Eigen::Vector2d> line;
    for (size_t j = 0; j < lane.node().size(); ++j) {
      absl::StatusOr<Eigen::Vector2d> p =
          PointOf(JsonField(&lane.node()[j], source, absl::StrCat(lane.path(), "[", j, "]")));
      if (!p.ok()) return p.status();
      line.push_back(*p);
    }
    r->lanes_px.push_back(line);
  }
  return absl::OkStatus();
}

absl::Status ReadPoints(const JsonField& root, AftersaleRequest* r) {
  // Errors about a list as a whole name it as "<document>: <path>".
  const auto where = [&](const std::string& key) {
    return absl::StrCat(root.source(), ": ", root.ChildPath(key));
  };
  if (root.Has("lanes") && root.Has("markers"))
    return root.Error("give lanes or markers, not both");
  if (root.Has("lanes")) {
    if (absl::Status s = ReadLanes(root, r); !s.ok()) return s;
  }
  if (root.Has("markers")) {
    absl::StatusOr<std::vector<Eigen::Vector2d>> m = PointsAt(root, "markers");
    if (!m.ok()) return m.status();
    absl::StatusOr<std::vector<std::vector<Eigen::Vector2d>>> lanes =
        LanesOfMarkers(*m, where("markers"));
    if (!lanes.ok()) return lanes.status();
    r->lanes_px = *lanes;
  }
  if (root.Has("roll_line")) {
    absl::StatusOr<std::vector<Eigen::Vector2d>> p = PointsAt(root, "roll_line");
    if (!p.ok()) return p.status();
    if (p->size() != 2) {
      return absl::InvalidArgumentError(
          absl::StrCat(where("roll_line"), ": 2 points needed, got ", p->size()));
    }
    r->roll_line_px = std::array<Eigen::Vector2d, 2>{(*p)[0], (*p)[1]};
  }
  if (root.Has("marked_point")) {
    absl::StatusOr<JsonField> m = root.Object("marked_point");
    if (!m.ok()) return m.status();
    if (absl::Status s = m->AllowOnlyKeys({"uv_px", "measured_distance_m"}); !s.ok()) return s;
    absl::StatusOr<std::vector<double>> uv = m->Numbers("uv_px", 2);
    if (!uv.ok()) return uv.status();
    r->marked_point_px = Eigen::Vector2d((*uv)[0], (*uv)[1]);
    if (m->Has("measured_distance_m")) {
      absl::StatusOr<double> d = m->Number("measured_distance_m");
      if (!d.ok()) return d.status();
      r->measured_distance_m = *d;
    }
  }
  return absl::OkStatus();
}

nlohmann::json Rows(const Eigen::Matrix3d& m) {
  nlohmann::json rows = nlohmann::json::array();
  for (int i = 0; i < 3; ++i) rows.push_back({m(i, 0), m(i, 1), m(i, 2)});
  return rows;
}

std::vector<double> DistortionOf(const CameraIntrinsics& k) {
  return k.type == CameraModelType::kPinhole ? std::vector<double>{k.k1, k.k2, k.p1, k.p2, k.k3}
                                             : std::vector<double>{k.k1, k.k2, k.k3, k.k4};
}

// The reference toolbox's matrix object.
nlohmann::json ToolboxMatrix(const std::vector<std::vector<double>>& rows) {
  return {{"cols", rows.empty() ? 0 : rows[0].size()},
          {"continuous", "true"},
          {"data", rows},
          {"rows", rows.size()},
          {"type", 6}};
}

absl::Status SetDistortion(const std::vector<double>& d, CameraIntrinsics* k) {
  if (k->type == CameraModelType::kPinhole) {
    if (!d.empty() && d.size() != 4 && d.size() != 5) {
      return absl::InvalidArgumentError(absl::StrCat(
          "intrinsics.distortion: a pinhole takes k1,k2,p1,p2[,k3], got ", d.size(), " values"));
    }
    if (!d.empty()) {
      k->k1 = d[0];
      k->k2 = d[1];
      k->p1 = d[2];
      k->p2 = d[3];
      k->k3 = d.size() == 5 ? d[4] : 0.0;
    }
    return absl::OkStatus();
  }
  if (!d.empty() && d.size() != 4) {
    return absl::InvalidArgumentError(absl::StrCat(
        "intrinsics.distortion: a fisheye takes k1,k2,k3,k4, got ", d.size(), " values"));
  }
  if (!d.empty()) {
    k->k1 = d[0];
    k->k2 = d[1];
    k->k3 = d[2];
    k->k4 = d[3];
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::vector<std::vector<Eigen::Vector2d>>> LanesOfMarkers(
    const std::vector<Eigen::Vector2d>& m, const std::string& what) {
  if (m.size() != 4) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": 4 markers needed, got ", m.size()));
  }
  return std::vector<std::vector<Eigen::Vector2d>>{{m[0], m[1]}, {m[2], m[3]}};
}

absl::Status ReadAftersaleInput(const JsonField& root, AftersaleRequest* r) {
  if (absl::Status s = root.AllowOnlyKeys({"name", "image", "intrinsics", "camera_height_m",
                                           "longitudinal_offset_m", "lateral_offset_m",
                                           "looking_backward", "lanes", "markers", "roll_line",
                                           "roll_deg", "marked_point", "tolerance_percent"});
      !s.ok()) {
    return s;
  }
  absl::StatusOr<std::string> name = root.StringOr("name", r->name);
  if (!name.ok()) return name.status();
  r->name = *name;
  if (root.Has("image")) {
    absl::StatusOr<std::string> image = root.String("image");
    if (!image.ok()) return image.status();
    r->image = *image;
  }
  if (root.Has("intrinsics")) {
    absl::StatusOr<JsonField> k = root.Object("intrinsics");
    if (!k.ok()) return k.status();
    if (absl::Status s = ReadIntrinsics(*k, r); !s.ok()) return s;
  }
  if (root.Has("camera_height_m")) {
    absl::StatusOr<double> h = root.Number("camera_height_m");
    if (!h.ok()) return h.status();
    r->camera_height_m = *h;
  }
  for (const auto& [key, slot] :
       {std::pair{"longitudinal_offset_m", &r->longitudinal_offset_m},
        std::pair{"lateral_offset_m", &r->lateral_offset_m}, std::pair{"roll_deg", &r->roll_deg},
        std::pair{"tolerance_percent", &r->tolerance_percent}}) {
    absl::StatusOr<double> v = root.NumberOr(key, *slot);
    if (!v.ok()) return v.status();
    *slot = *v;
  }
  absl::StatusOr<bool> backward = root.BoolOr("looking_backward", r->looking_backward);
  if (!backward.ok()) return backward.status();
  r->looking_backward = *backward;
  return ReadPoints(root, r);
}

nlohmann::json AftersaleCameraInput(const std::string& name, const CameraIntrinsics& k,
                                    const Eigen::Vector3d& xyz_m, bool looking_backward) {
  return {{"name", name},
          {"intrinsics",
           {{"model", CameraModelTypeName(k.type)},
            {"fx", k.fx},
            {"fy", k.fy},
            {"cx", k.cx},
            {"cy", k.cy},
            {"distortion", DistortionOf(k)}}},
          {"camera_height_m", xyz_m.z()},
          {"longitudinal_offset_m", xyz_m.x()},
          {"lateral_offset_m", xyz_m.y()},
          {"looking_backward", looking_backward},
          {"tolerance_percent", 1.0}};
}

absl::StatusOr<LaneCalibrationInput> AftersaleSolverInput(const AftersaleRequest& r, int width,
                                                          int height) {
  const auto missing = [](const std::string& field, const std::string& flag) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, ": missing (", flag, " or the input file's ", field, ")"));
  };
  LaneCalibrationInput in;
  CameraIntrinsics& k = in.intrinsics;
  k.type = r.model;
  k.width = width;
  k.height = height;
  if (!r.fx) return missing("intrinsics.fx", "--fx");
  if (!r.fy) return missing("intrinsics.fy", "--fy");
  k.fx = *r.fx;
  k.fy = *r.fy;
  // The image centre: pixel centres are integers, so it is at (w - 1) / 2, (h - 1) / 2.
  k.cx = r.cx.value_or((width - 1) / 2.0);
  k.cy = r.cy.value_or((height - 1) / 2.0);
  if (absl::Status s = SetDistortion(r.distortion, &k); !s.ok()) return s;
  if (!r.camera_height_m) return missing("camera_height_m", "--camera-height-m");
  if (r.lanes_px.empty()) return missing("lanes", "--lane, --markers,");
  if (r.marked_point_px.has_value() != r.measured_distance_m.has_value()) {
    return r.marked_point_px ? missing("marked_point.measured_distance_m", "--measured-distance-m")
                             : missing("marked_point.uv_px", "--marked-point");
  }
  in.camera_height_m = *r.camera_height_m;
  in.longitudinal_offset_m = r.longitudinal_offset_m;
  in.lateral_offset_m = r.lateral_offset_m;
  in.looking_backward = r.looking_backward;
  in.lanes_px = r.lanes_px;
  in.roll_line_px = r.roll_line_px;
  in.assumed_roll_rad = r.roll_deg * kDeg;
  in.tolerance_percent = r.tolerance_percent;
  if (r.marked_point_px) {
    in.marked_point = LaneMarkedPoint{*r.marked_point_px, *r.measured_distance_m};
  }
  return in;
}

Eigen::Matrix3d AftersaleImageToGround(const LaneCalibrationResult& r) {
  const Eigen::Matrix3d h = r.ground_homography.inverse();
  return h / h(2, 2);
}

nlohmann::json AftersaleResultJson(const std::string& name, const LaneCalibrationInput& in,
                                   const LaneCalibrationResult& r) {
  nlohmann::json j;
  j["name"] = name;
  j["image_size"] = {in.intrinsics.width, in.intrinsics.height};
  j["vanishing_point_px"] = {r.vanishing_point_px.x(), r.vanishing_point_px.y()};
  j["vanishing_point_residual_px"] = r.vanishing_point_residual_px;
  j["lane_fit_rms_px"] = r.lane_fit_rms_px;
  j["roll_source"] = r.roll_from_line ? "roll_line" : "assumed";
  j["ypr_deg"] = {r.angles.yaw / kDeg, r.angles.pitch / kDeg, r.angles.roll / kDeg};
  j["T_car_camera"] = PoseToJson(r.T_car_camera, CameraBaseRotation());
  j["ground_homography"] = Rows(r.ground_homography);
  j["h_matrix"] = Rows(AftersaleImageToGround(r));
  nlohmann::json flat = nlohmann::json::array();
  for (const RangingCheck& c : r.flat_formula) {
    flat.push_back({{"distance_m", c.true_distance_m},
                    {"flat_formula_m", std::isfinite(c.measured_distance_m)
                                           ? nlohmann::json(c.measured_distance_m)
                                           : nlohmann::json(nullptr)}});
  }
  j["flat_formula"] = flat;
  if (r.distance_check) {
    const LaneDistanceCheck& c = *r.distance_check;
    j["distance_check"] = {{"measured_distance_m", c.measured_distance_m},
                           {"computed_distance_m", c.computed_distance_m},
                           {"error_percent", c.error_percent},
                           {"tolerance_percent", in.tolerance_percent},
                           {"verdict", c.pass ? "pass" : "fail"}};
  }
  return j;
}

std::vector<std::pair<std::string, nlohmann::json>> AftersaleExportFiles(
    const std::string& name, const LaneCalibrationInput& in, const LaneCalibrationResult& r) {
  const CameraIntrinsics& k = in.intrinsics;
  const Eigen::Matrix3d h = AftersaleImageToGround(r);
  std::vector<std::vector<double>> h_rows;
  for (int i = 0; i < 3; ++i) h_rows.push_back({h(i, 0), h(i, 1), h(i, 2)});
  nlohmann::json calibration = {
      {name + "_calibration",
       {{"device_type", "camera"},
        {"param",
         {{"blinding_area_param",
           {{"blinding_area_distance", 0}, {"blinding_area_pixel_height", k.height}}},
          {"h_matrix", ToolboxMatrix(h_rows)},
          {"vanishing_point",
           {{"vanishing_pt_x", r.vanishing_point_px.x()},
            {"vanishing_pt_y", r.vanishing_point_px.y()}}}}},
        {"param_type", "calibration"},
        {"sensor_name", name + "_calibration"},
        {"target_sensor_name", name + "_calibration"}}}};
  nlohmann::json intrinsic = {
      {name + "_calib",
       {{"device_type", "camera"},
        {"param",
         {{"cam_K", ToolboxMatrix({{k.fx, 0, k.cx}, {0, k.fy, k.cy}, {0, 0, 1}})},
          {"cam_dist", ToolboxMatrix({DistortionOf(k)})},
          {"distortion_model", CameraModelTypeName(k.type)},
          {"img_dist_h", k.height},
          {"img_dist_w", k.width}}},
        {"param_type", "intrinsic"},
        {"sensor_name", name},
        {"target_sensor_name", name}}}};
  const Eigen::Matrix4d t = r.T_car_camera.Matrix();
  std::vector<std::vector<double>> t_rows;
  for (int i = 0; i < 4; ++i) t_rows.push_back({t(i, 0), t(i, 1), t(i, 2), t(i, 3)});
  nlohmann::json extrinsic = {
      {name + "_car_center_calib",
       {{"device_type", "relational"},
        {"param", {{"sensor_calib", ToolboxMatrix(t_rows)}, {"time_lag", 0}}},
        {"param_type", "extrinsic"},
        {"sensor_name", name},
        {"target_sensor_name", "car_center"}}}};
  std::vector<std::pair<std::string, nlohmann::json>> files;
  files.emplace_back(name + "-calibration.json", std::move(calibration));
  files.emplace_back(name + "-intrinsic.json", std::move(intrinsic));
  files.emplace_back(name + "-to-car_center-extrinsic.json", std::move(extrinsic));
  return files;
}

}  // namespace linecal

// linecal aftersale: camera calibration in a workshop from lane lines (docs/aftersale.md).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <filesystem>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "station/io/image_io.h"
#include "station/io/json_reader.h"
#include "station/model/pose_json.h"
#include "station/solvers/lane_calibration.h"
#include "station/solvers/seed_formulas.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"
#include "tools/linecal/detection_overlay.h"

namespace linecal::tools {
namespace {

namespace fs = std::filesystem;
constexpr char kCommand[] = "aftersale";
constexpr double kDeg = std::numbers::pi / 180.0;

// Everything the command needs, from the input file and then the flags (flags win).
struct AftersaleRequest {
  std::string name = "front_camera";
  std::string image;
  CameraModelType model = CameraModelType::kPinhole;
  std::optional<double> fx, fy, cx, cy;
  std::vector<double> distortion;  // pinhole k1 k2 p1 p2 [k3]; fisheye k1 k2 k3 k4
  std::optional<double> camera_height_m;
  double longitudinal_offset_m = 0;
  double lateral_offset_m = 0;
  bool looking_backward = false;
  std::vector<std::vector<Eigen::Vector2d>> lanes_px;
  std::optional<std::array<Eigen::Vector2d, 2>> roll_line_px;
  double roll_deg = 0;
  std::optional<Eigen::Vector2d> marked_point_px;
  std::optional<double> measured_distance_m;
  double tolerance_percent = 1.0;
};

// "u,v,u,v,..." as points; `what` names the flag or field in errors.
absl::StatusOr<std::vector<Eigen::Vector2d>> ParsePoints(const std::string& text, const std::string& what) {
  absl::StatusOr<std::vector<double>> v = cli::ParseNumberList(text, what);
  if (!v.ok()) return v.status();
  if (v->size() % 2 != 0) return absl::InvalidArgumentError(absl::StrCat(what, ": an odd count of numbers (U,V pairs)"));
  std::vector<Eigen::Vector2d> points;
  for (size_t i = 0; i < v->size(); i += 2) points.emplace_back((*v)[i], (*v)[i + 1]);
  return points;
}

absl::StatusOr<Eigen::Vector2d> PointOf(const JsonField& f) {
  if (!f.node().is_array() || f.node().size() != 2 || !f.node()[0].is_number() || !f.node()[1].is_number()) {
    return f.Error("must be [u, v], two numbers");
  }
  return Eigen::Vector2d(f.node()[0].get<double>(), f.node()[1].get<double>());
}

absl::StatusOr<std::vector<Eigen::Vector2d>> PointsAt(const JsonField& parent, const std::string& key) {
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

// Four markers, left near, left far, right near, right far: two lines parallel to the car.
absl::StatusOr<std::vector<std::vector<Eigen::Vector2d>>> LanesOfMarkers(const std::vector<Eigen::Vector2d>& m,
                                                                         const std::string& what) {
  if (m.size() != 4) return absl::InvalidArgumentError(absl::StrCat(what, ": 4 markers needed, got ", m.size()));
  return std::vector<std::vector<Eigen::Vector2d>>{{m[0], m[1]}, {m[2], m[3]}};
}

absl::StatusOr<std::array<Eigen::Vector2d, 2>> TwoPoints(const std::vector<Eigen::Vector2d>& p, const std::string& what) {
  if (p.size() != 2) return absl::InvalidArgumentError(absl::StrCat(what, ": 2 points needed, got ", p.size()));
  return std::array<Eigen::Vector2d, 2>{p[0], p[1]};
}

absl::Status ReadInputFile(const std::string& path, AftersaleRequest* r) {
  absl::StatusOr<JsonDocument> doc = JsonDocument::FromFile(path);
  if (!doc.ok()) return doc.status();
  absl::StatusOr<JsonField> root = doc->Root();
  if (!root.ok()) return root.status();
  if (absl::Status s = root->AllowOnlyKeys({"name", "image", "intrinsics", "camera_height_m", "longitudinal_offset_m",
                                            "lateral_offset_m", "looking_backward", "lanes", "markers", "roll_line",
                                            "roll_deg", "marked_point", "tolerance_percent"});
      !s.ok()) {
    return s;
  }
  absl::StatusOr<std::string> name = root->StringOr("name", r->name);
  if (!name.ok()) return name.status();
  r->name = *name;
  if (root->Has("image")) {
    absl::StatusOr<std::string> image = root->String("image");
    if (!image.ok()) return image.status();
    // Relative to the input file, so that a directory of inputs can move.
    r->image = fs::path(*image).is_absolute() ? *image : (fs::path(path).parent_path() / *image).string();
  }
  if (root->Has("intrinsics")) {
    absl::StatusOr<JsonField> k = root->Object("intrinsics");
    if (!k.ok()) return k.status();
    if (absl::Status s = k->AllowOnlyKeys({"model", "fx", "fy", "cx", "cy", "distortion"}); !s.ok()) return s;
    absl::StatusOr<std::string> model = k->StringOr("model", "pinhole");
    if (!model.ok()) return model.status();
    if (*model != "pinhole" && *model != "fisheye") {
      return k->Error("model", absl::StrCat("must be pinhole or fisheye, got '", *model, "'"));
    }
    r->model = *model == "fisheye" ? CameraModelType::kFisheye : CameraModelType::kPinhole;
    for (const auto& [key, slot] : {std::pair{"fx", &r->fx}, std::pair{"fy", &r->fy}, std::pair{"cx", &r->cx},
                                    std::pair{"cy", &r->cy}}) {
      if (!k->Has(key)) continue;
      absl::StatusOr<double> v = k->Number(key);
      if (!v.ok()) return v.status();
      *slot = *v;
    }
    if (k->Has("distortion")) {
      absl::StatusOr<std::vector<double>> d = k->Numbers("distortion");
      if (!d.ok()) return d.status();
      r->distortion = *d;
    }
  }
  if (root->Has("camera_height_m")) {
    absl::StatusOr<double> h = root->Number("camera_height_m");
    if (!h.ok()) return h.status();
    r->camera_height_m = *h;
  }
  for (const auto& [key, slot] : {std::pair{"longitudinal_offset_m", &r->longitudinal_offset_m},
                                  std::pair{"lateral_offset_m", &r->lateral_offset_m},
                                  std::pair{"roll_deg", &r->roll_deg},
                                  std::pair{"tolerance_percent", &r->tolerance_percent}}) {
    absl::StatusOr<double> v = root->NumberOr(key, *slot);
    if (!v.ok()) return v.status();
    *slot = *v;
  }
  absl::StatusOr<bool> backward = root->BoolOr("looking_backward", false);
  if (!backward.ok()) return backward.status();
  r->looking_backward = *backward;
  if (root->Has("lanes") && root->Has("markers")) return root->Error("give lanes or markers, not both");
  if (root->Has("lanes")) {
    absl::StatusOr<std::vector<JsonField>> lanes = root->Array("lanes");
    if (!lanes.ok()) return lanes.status();
    const auto source = std::make_shared<const std::string>(root->source());
    for (const JsonField& lane : *lanes) {
      if (!lane.node().is_array()) return lane.Error("must be an array of [u, v] points");
      std::vector<Eigen::Vector2d> line;
      for (size_t j = 0; j < lane.node().size(); ++j) {
        absl::StatusOr<Eigen::Vector2d> p = PointOf(JsonField(&lane.node()[j], source, absl::StrCat(lane.path(), "[", j, "]")));
        if (!p.ok()) return p.status();
        line.push_back(*p);
      }
      r->lanes_px.push_back(line);
    }
  }
  if (root->Has("markers")) {
    absl::StatusOr<std::vector<Eigen::Vector2d>> m = PointsAt(*root, "markers");
    if (!m.ok()) return m.status();
    absl::StatusOr<std::vector<std::vector<Eigen::Vector2d>>> lanes = LanesOfMarkers(*m, path + ": markers");
    if (!lanes.ok()) return lanes.status();
    r->lanes_px = *lanes;
  }
  if (root->Has("roll_line")) {
    absl::StatusOr<std::vector<Eigen::Vector2d>> p = PointsAt(*root, "roll_line");
    if (!p.ok()) return p.status();
    absl::StatusOr<std::array<Eigen::Vector2d, 2>> two = TwoPoints(*p, path + ": roll_line");
    if (!two.ok()) return two.status();
    r->roll_line_px = *two;
  }
  if (root->Has("marked_point")) {
    absl::StatusOr<JsonField> m = root->Object("marked_point");
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

absl::Status ReadFlags(const cli::CommandLine& cl, AftersaleRequest* r) {
  if (cl.Has("name")) r->name = cl.Get("name");
  if (cl.Has("image")) r->image = cl.Get("image");
  if (cl.Has("model")) {
    const std::string m = cl.Get("model");
    if (m != "pinhole" && m != "fisheye") return absl::InvalidArgumentError("--model: must be pinhole or fisheye, got '" + m + "'");
    r->model = m == "fisheye" ? CameraModelType::kFisheye : CameraModelType::kPinhole;
  }
  for (const auto& [flag, slot] : {std::pair{"fx", &r->fx}, std::pair{"fy", &r->fy}, std::pair{"cx", &r->cx},
                                   std::pair{"cy", &r->cy}, std::pair{"camera-height-m", &r->camera_height_m},
                                   std::pair{"measured-distance-m", &r->measured_distance_m}}) {
    if (!cl.Has(flag)) continue;
    absl::StatusOr<double> v = cl.GetDouble(flag, 0);
    if (!v.ok()) return v.status();
    *slot = *v;
  }
  for (const auto& [flag, slot] : {std::pair{"longitudinal-offset-m", &r->longitudinal_offset_m},
                                   std::pair{"lateral-offset-m", &r->lateral_offset_m},
                                   std::pair{"roll-deg", &r->roll_deg},
                                   std::pair{"tolerance-percent", &r->tolerance_percent}}) {
    absl::StatusOr<double> v = cl.GetDouble(flag, *slot);
    if (!v.ok()) return v.status();
    *slot = *v;
  }
  if (cl.Has("rear")) r->looking_backward = true;
  if (cl.Has("distortion")) {
    absl::StatusOr<std::vector<double>> d = cli::ParseNumberList(cl.Get("distortion"), "--distortion");
    if (!d.ok()) return d.status();
    r->distortion = *d;
  }
  if (cl.Has("lane") && cl.Has("markers")) return absl::InvalidArgumentError("--lane and --markers: give one of them");
  if (cl.Has("lane")) {
    r->lanes_px.clear();
    for (const std::string& text : cl.GetAll("lane")) {
      absl::StatusOr<std::vector<Eigen::Vector2d>> p = ParsePoints(text, "--lane");
      if (!p.ok()) return p.status();
      r->lanes_px.push_back(*p);
    }
  }
  if (cl.Has("markers")) {
    absl::StatusOr<std::vector<Eigen::Vector2d>> p = ParsePoints(cl.Get("markers"), "--markers");
    if (!p.ok()) return p.status();
    absl::StatusOr<std::vector<std::vector<Eigen::Vector2d>>> lanes = LanesOfMarkers(*p, "--markers");
    if (!lanes.ok()) return lanes.status();
    r->lanes_px = *lanes;
  }
  if (cl.Has("roll-line")) {
    absl::StatusOr<std::vector<Eigen::Vector2d>> p = ParsePoints(cl.Get("roll-line"), "--roll-line");
    if (!p.ok()) return p.status();
    absl::StatusOr<std::array<Eigen::Vector2d, 2>> two = TwoPoints(*p, "--roll-line");
    if (!two.ok()) return two.status();
    r->roll_line_px = *two;
  }
  if (cl.Has("marked-point")) {
    absl::StatusOr<std::vector<Eigen::Vector2d>> p = ParsePoints(cl.Get("marked-point"), "--marked-point");
    if (!p.ok()) return p.status();
    if (p->size() != 1) return absl::InvalidArgumentError("--marked-point: one point U,V needed");
    r->marked_point_px = (*p)[0];
  }
  return absl::OkStatus();
}

// The solver's input: the image size from the image, cx and cy defaulting to its centre.
absl::StatusOr<LaneCalibrationInput> SolverInput(const AftersaleRequest& r, int width, int height) {
  const auto missing = [](const std::string& field, const std::string& flag) {
    return absl::InvalidArgumentError(absl::StrCat(field, ": missing (", flag, " or the input file's ", field, ")"));
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
  const std::vector<double>& d = r.distortion;
  if (r.model == CameraModelType::kPinhole) {
    if (!d.empty() && d.size() != 4 && d.size() != 5) {
      return absl::InvalidArgumentError(
          absl::StrCat("intrinsics.distortion: a pinhole takes k1,k2,p1,p2[,k3], got ", d.size(), " values"));
    }
    if (!d.empty()) {
      k.k1 = d[0];
      k.k2 = d[1];
      k.p1 = d[2];
      k.p2 = d[3];
      k.k3 = d.size() == 5 ? d[4] : 0.0;
    }
  } else {
    if (!d.empty() && d.size() != 4) {
      return absl::InvalidArgumentError(
          absl::StrCat("intrinsics.distortion: a fisheye takes k1,k2,k3,k4, got ", d.size(), " values"));
    }
    if (!d.empty()) {
      k.k1 = d[0];
      k.k2 = d[1];
      k.k3 = d[2];
      k.k4 = d[3];
    }
  }
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
  if (r.marked_point_px) in.marked_point = LaneMarkedPoint{*r.marked_point_px, *r.measured_distance_m};
  return in;
}

nlohmann::json Rows(const Eigen::Matrix3d& m) {
  nlohmann::json rows = nlohmann::json::array();
  for (int i = 0; i < 3; ++i) rows.push_back({m(i, 0), m(i, 1), m(i, 2)});
  return rows;
}

// H_ground_image: the undistorted image to the ground (x, y) in metres, scaled to H(2, 2) = 1,
// the direction the reference toolbox's h_matrix maps.
Eigen::Matrix3d ImageToGround(const LaneCalibrationResult& r) {
  const Eigen::Matrix3d h = r.ground_homography.inverse();
  return h / h(2, 2);
}

// The undistorted pixel q as a distorted one, for drawing on the stored image.
bool Distort(const CameraModel& camera, const Eigen::Vector2d& q, Eigen::Vector2d* uv) {
  const CameraIntrinsics& k = camera.intrinsics();
  return camera.Project(Eigen::Vector3d((q.x() - k.cx) / k.fx, (q.y() - k.cy) / k.fy, 1.0), uv);
}

// A polyline through `points` (distorted pixels), skipping gaps where a point is missing.
void DrawPolyline(RgbImage* img, const std::vector<std::optional<Eigen::Vector2d>>& points, int thickness, const RgbColour& c) {
  for (size_t i = 1; i < points.size(); ++i) {
    if (points[i - 1] && points[i]) DrawSegment(img, *points[i - 1], *points[i], thickness, c);
  }
}

// The ground line from a to b (car frame, z = 0) through the estimated pose and the lens.
std::vector<std::optional<Eigen::Vector2d>> GroundLine(const CameraModel& camera, const Rigid3d& T_camera_car,
                                                       const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  constexpr int kSteps = 200;
  std::vector<std::optional<Eigen::Vector2d>> out;
  for (int i = 0; i <= kSteps; ++i) {
    const Eigen::Vector2d g = a + (b - a) * (static_cast<double>(i) / kSteps);
    Eigen::Vector2d uv;
    const Eigen::Vector3d p = T_camera_car * Eigen::Vector3d(g.x(), g.y(), 0);
    if (p.z() > 0 && camera.Project(p, &uv) && camera.IsInImage(uv)) {
      out.emplace_back(uv);
    } else {
      out.emplace_back(std::nullopt);
    }
  }
  return out;
}

// The image with the ground grid (every 5 m ahead to 50 m, every metre across to ±5 m), the
// horizon, the lane lines through the vanishing point, the roll line and the marked point.
RgbImage DrawOverlay(const Image8& image, const CameraModel& camera, const LaneCalibrationInput& in,
                     const LaneCalibrationResult& r) {
  RgbImage img = GreyToRgb(image.view());
  const Rigid3d T_camera_car = r.T_car_camera.Inverse();
  const Eigen::Vector3d c = r.T_car_camera.translation();
  const double along = in.looking_backward ? -1 : 1;
  const RgbColour grid{0, 200, 255}, lane{0, 230, 0}, vp{255, 40, 40}, horizon{255, 220, 0}, roll{255, 140, 0},
      mark{255, 0, 255};
  for (int d = 5; d <= 50; d += 5) {
    DrawPolyline(&img, GroundLine(camera, T_camera_car, {c.x() + along * d, c.y() - 5}, {c.x() + along * d, c.y() + 5}), 1, grid);
  }
  for (int y = -5; y <= 5; ++y) {
    DrawPolyline(&img, GroundLine(camera, T_camera_car, {c.x() + along * 2, c.y() + y}, {c.x() + along * 50, c.y() + y}), 1, grid);
  }
  // The horizon: the images of ground directions at infinity, from 60 degrees left to right.
  std::vector<std::optional<Eigen::Vector2d>> h;
  const Eigen::Matrix3d R_camera_car = T_camera_car.RotationMatrix();
  for (int a = -60; a <= 60; ++a) {
    const Eigen::Vector3d dir = R_camera_car * Eigen::Vector3d(along * std::cos(a * kDeg), std::sin(a * kDeg), 0);
    Eigen::Vector2d uv;
    h.push_back(dir.z() > 0 && camera.Project(dir, &uv) ? std::optional(uv) : std::nullopt);
  }
  DrawPolyline(&img, h, 1, horizon);
  // Each lane line from its marked points to the vanishing point, straight in the undistorted
  // image and drawn through the lens.
  for (const std::vector<Eigen::Vector2d>& points : in.lanes_px) {
    // From the point farthest from the vanishing point (the nearest on the ground).
    Eigen::Vector2d near_q = r.vanishing_point_px;
    for (const Eigen::Vector2d& uv : points) {
      Eigen::Vector2d q;
      if (UndistortedPixel(camera, uv, &q) && (q - r.vanishing_point_px).norm() > (near_q - r.vanishing_point_px).norm()) {
        near_q = q;
      }
    }
    std::vector<std::optional<Eigen::Vector2d>> line;
    for (int i = 0; i <= 200; ++i) {
      Eigen::Vector2d uv;
      const Eigen::Vector2d q = near_q + (r.vanishing_point_px - near_q) * (i / 200.0);
      line.push_back(Distort(camera, q, &uv) ? std::optional(uv) : std::nullopt);
    }
    DrawPolyline(&img, line, 2, lane);
    for (const Eigen::Vector2d& uv : points) DrawCross(&img, uv, 8, lane);
  }
  if (in.roll_line_px) {
    DrawSegment(&img, (*in.roll_line_px)[0], (*in.roll_line_px)[1], 2, roll);
    for (const Eigen::Vector2d& uv : *in.roll_line_px) DrawCross(&img, uv, 8, roll);
  }
  if (in.marked_point) DrawCross(&img, in.marked_point->uv_px, 12, mark);
  Eigen::Vector2d vp_uv;
  if (Distort(camera, r.vanishing_point_px, &vp_uv)) DrawCross(&img, vp_uv, 14, vp);
  return img;
}

// The ground seen from above through the estimate: forward up, left on the left, 20 px/m,
// 3..43 m ahead of the camera and ±8 m across its footprint; each pixel's ground point taken
// through the ground homography (the estimated pose) and the lens into the image. Grid lines
// every 5 m ahead and every metre across.
RgbImage DrawBirdsEye(const Image8& image, const CameraModel& camera, const LaneCalibrationInput& in,
                      const LaneCalibrationResult& r) {
  constexpr double kPxPerM = 20, kNearM = 3, kFarM = 43, kHalfWidthM = 8;
  const int w = static_cast<int>(2 * kHalfWidthM * kPxPerM), h = static_cast<int>((kFarM - kNearM) * kPxPerM);
  RgbImage img(w, h, {0, 0, 0});
  const Eigen::Vector3d c = r.T_car_camera.translation();
  const Rigid3d T_camera_car = r.T_car_camera.Inverse();
  const double along = in.looking_backward ? -1 : 1;
  const CameraIntrinsics& k = camera.intrinsics();
  for (int row = 0; row < h; ++row) {
    for (int col = 0; col < w; ++col) {
      const double ahead = kFarM - (row + 0.5) / kPxPerM;
      const double left = kHalfWidthM - (col + 0.5) / kPxPerM;
      // For a camera looking backward, its left is the car's right.
      const Eigen::Vector3d g(c.x() + along * ahead, c.y() + along * left, 1.0);
      // The ground point in the undistorted image; it must be in front of the camera, which
      // the homography alone cannot tell (q and -q are the same pixel).
      const Eigen::Vector3d q = r.ground_homography * g;
      if ((T_camera_car * Eigen::Vector3d(g.x(), g.y(), 0)).z() <= 0) continue;
      Eigen::Vector2d uv;
      if (!Distort(camera, q.hnormalized(), &uv) || !camera.IsInImage(uv)) continue;
      // Bilinear sample of the stored image.
      const double x = std::clamp(uv.x(), 0.0, k.width - 1.0), y = std::clamp(uv.y(), 0.0, k.height - 1.0);
      const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
      const int x1 = std::min(x0 + 1, k.width - 1), y1 = std::min(y0 + 1, k.height - 1);
      const double fx = x - x0, fy = y - y0;
      const double v = (1 - fy) * ((1 - fx) * image.at(x0, y0) + fx * image.at(x1, y0)) +
                       fy * ((1 - fx) * image.at(x0, y1) + fx * image.at(x1, y1));
      const auto g8 = static_cast<std::uint8_t>(std::lround(v));
      PutPixel(&img, col, row, {g8, g8, g8});
    }
  }
  const RgbColour grid{0, 200, 255};
  for (double d = 5; d < kFarM; d += 5) {
    const double row = (kFarM - d) * kPxPerM;
    DrawSegment(&img, {0, row}, {w - 1.0, row}, 1, grid);
  }
  for (double y = -kHalfWidthM + 1; y < kHalfWidthM; y += 1) {
    const double col = (kHalfWidthM - y) * kPxPerM;
    DrawSegment(&img, {col, 0}, {col, h - 1.0}, 1, grid);
  }
  return img;
}

nlohmann::json ToolboxMatrix(const std::vector<std::vector<double>>& rows) {
  return {{"cols", rows.empty() ? 0 : rows[0].size()}, {"continuous", "true"}, {"data", rows},
          {"rows", rows.size()}, {"type", 6}};
}

// The reference toolbox's three files (docs/aftersale.md, "Export"), with the real values.
absl::StatusOr<std::vector<std::string>> Export(const std::string& dir, const std::string& name,
                                                const LaneCalibrationInput& in, const LaneCalibrationResult& r) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return absl::InvalidArgumentError(absl::StrCat("--export: cannot create ", dir, ": ", ec.message()));
  const CameraIntrinsics& k = in.intrinsics;
  const Eigen::Matrix3d h = ImageToGround(r);
  std::vector<std::vector<double>> h_rows;
  for (int i = 0; i < 3; ++i) h_rows.push_back({h(i, 0), h(i, 1), h(i, 2)});
  const nlohmann::json calibration = {
      {name + "_calibration",
       {{"device_type", "camera"},
        {"param",
         {{"blinding_area_param", {{"blinding_area_distance", 0}, {"blinding_area_pixel_height", k.height}}},
          {"h_matrix", ToolboxMatrix(h_rows)},
          {"vanishing_point",
           {{"vanishing_pt_x", r.vanishing_point_px.x()}, {"vanishing_pt_y", r.vanishing_point_px.y()}}}}},
        {"param_type", "calibration"},
        {"sensor_name", name + "_calibration"},
        {"target_sensor_name", name + "_calibration"}}}};
  const std::vector<double> dist = k.type == CameraModelType::kPinhole ? std::vector<double>{k.k1, k.k2, k.p1, k.p2, k.k3}
                                                                       : std::vector<double>{k.k1, k.k2, k.k3, k.k4};
  const nlohmann::json intrinsic = {
      {name + "_calib",
       {{"device_type", "camera"},
        {"param",
         {{"cam_K", ToolboxMatrix({{k.fx, 0, k.cx}, {0, k.fy, k.cy}, {0, 0, 1}})},
          {"cam_dist", ToolboxMatrix({dist})},
          {"distortion_model", CameraModelTypeName(k.type)},
          {"img_dist_h", k.height},
          {"img_dist_w", k.width}}},
        {"param_type", "intrinsic"},
        {"sensor_name", name},
        {"target_sensor_name", name}}}};
  const Eigen::Matrix4d t = r.T_car_camera.Matrix();
  std::vector<std::vector<double>> t_rows;
  for (int i = 0; i < 4; ++i) t_rows.push_back({t(i, 0), t(i, 1), t(i, 2), t(i, 3)});
  const nlohmann::json extrinsic = {
      {name + "_car_center_calib",
       {{"device_type", "relational"},
        {"param", {{"sensor_calib", ToolboxMatrix(t_rows)}, {"time_lag", 0}}},
        {"param_type", "extrinsic"},
        {"sensor_name", name},
        {"target_sensor_name", "car_center"}}}};
  std::vector<std::string> written;
  for (const auto& [suffix, j] : {std::pair{"-calibration.json", &calibration}, std::pair{"-intrinsic.json", &intrinsic},
                                  std::pair{"-to-car_center-extrinsic.json", &extrinsic}}) {
    const std::string path = (fs::path(dir) / (name + suffix)).string();
    if (absl::Status s = WriteJsonFile(path, *j); !s.ok()) return s;
    written.push_back(path);
  }
  return written;
}

}  // namespace

int RunAftersale(const Args& args) {
  cli::CommandLine cl(
      "linecal aftersale [--input FILE] [--image FILE --lane U,V,U,V --lane U,V,U,V --camera-height-m H --fx F --fy F] "
      "[options]",
      "Calibrates a camera from points on two lane lines (or four markers parallel to the car) in one of its "
      "images: vanishing point, roll from an optional roll line, pitch and yaw, the ground homography, a bird's-eye "
      "view, and the ranging error at a marked point of measured distance (docs/aftersale.md). Flags override the "
      "input file. Exit 0 done (distance check passed or not asked), 1 the distance check failed, 2 bad input.",
      {{"input", "FILE", "the input as JSON (docs/aftersale.md)"},
       {"image", "FILE", "the camera's image (PNG or JPEG)"},
       {"name", "NAME", "the camera's name in the outputs (default front_camera)"},
       {"lane", "U,V,U,V[,...]", "points on one lane line, distorted pixels; give it for each line", false, true},
       {"markers", "U,V x4", "four markers: left near, left far, right near, right far"},
       {"roll-line", "U,V,U,V", "the two ends of the roll line"},
       {"roll-deg", "R", "the roll assumed without a roll line, degrees (default 0)"},
       {"camera-height-m", "H", "the camera's height above the ground, metres"},
       {"longitudinal-offset-m", "X", "the camera's x in the car frame (forward), metres (default 0)"},
       {"lateral-offset-m", "Y", "the camera's y in the car frame (left), metres (default 0)"},
       {"rear", "", "the camera looks backward"},
       {"fx", "F", "focal length, pixels"},
       {"fy", "F", "focal length, pixels"},
       {"cx", "C", "principal point, pixels (default the image centre)"},
       {"cy", "C", "principal point, pixels (default the image centre)"},
       {"model", "pinhole|fisheye", "lens model (default pinhole)"},
       {"distortion", "K1,K2,P1,P2[,K3]", "distortion (fisheye: K1,K2,K3,K4; default none)"},
       {"marked-point", "U,V", "a marked point on the ground"},
       {"measured-distance-m", "D", "its measured distance ahead of the camera's footprint, metres"},
       {"tolerance-percent", "P", "the distance check's tolerance, percent (default 1)"},
       {"json", "", "print the result as JSON"},
       {"out", "DIR", "write <name>-overlay.png and <name>-birdseye.png here"},
       {"export", "DIR", "write the reference toolbox's three JSON files here"}});
  if (auto code = cli::ParseOrExit(cl, kCommand, args)) return *code;

  AftersaleRequest request;
  if (cl.Has("input")) {
    if (absl::Status s = ReadInputFile(cl.Get("input"), &request); !s.ok()) return cli::BadInput(kCommand, std::string(s.message()));
  }
  if (absl::Status s = ReadFlags(cl, &request); !s.ok()) return cli::BadInput(kCommand, std::string(s.message()));
  if (request.image.empty()) return cli::BadInput(kCommand, "image: missing (--image or the input file's image)");
  absl::StatusOr<Image8> image = ReadImage8(request.image);
  if (!image.ok()) return cli::BadInput(kCommand, absl::StrCat("unreadable image: ", image.status().message()));
  absl::StatusOr<LaneCalibrationInput> in = SolverInput(request, image->width, image->height);
  if (!in.ok()) return cli::BadInput(kCommand, std::string(in.status().message()));
  absl::StatusOr<LaneCalibrationResult> r = CalibrateFromLanes(*in);
  if (!r.ok()) return cli::BadInput(kCommand, std::string(r.status().message()));
  const CameraModel camera = *CameraModel::Create(in->intrinsics);

  nlohmann::json j;
  j["name"] = request.name;
  j["image"] = request.image;
  j["image_size"] = {in->intrinsics.width, in->intrinsics.height};
  j["vanishing_point_px"] = {r->vanishing_point_px.x(), r->vanishing_point_px.y()};
  j["vanishing_point_residual_px"] = r->vanishing_point_residual_px;
  j["lane_fit_rms_px"] = r->lane_fit_rms_px;
  j["roll_source"] = r->roll_from_line ? "roll_line" : "assumed";
  j["ypr_deg"] = {r->angles.yaw / kDeg, r->angles.pitch / kDeg, r->angles.roll / kDeg};
  j["T_car_camera"] = PoseToJson(r->T_car_camera, CameraBaseRotation());
  j["ground_homography"] = Rows(r->ground_homography);
  j["h_matrix"] = Rows(ImageToGround(*r));
  nlohmann::json flat = nlohmann::json::array();
  for (const RangingCheck& c : r->flat_formula) {
    flat.push_back({{"distance_m", c.true_distance_m},
                    {"flat_formula_m", std::isfinite(c.measured_distance_m) ? nlohmann::json(c.measured_distance_m)
                                                                             : nlohmann::json(nullptr)}});
  }
  j["flat_formula"] = flat;
  if (r->distance_check) {
    const LaneDistanceCheck& c = *r->distance_check;
    j["distance_check"] = {{"measured_distance_m", c.measured_distance_m},
                           {"computed_distance_m", c.computed_distance_m},
                           {"error_percent", c.error_percent},
                           {"tolerance_percent", in->tolerance_percent},
                           {"verdict", c.pass ? "pass" : "fail"}};
  }
  if (cl.Has("out")) {
    const fs::path dir = cl.Get("out");
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) return cli::BadInput(kCommand, absl::StrCat("--out: cannot create ", dir.string(), ": ", ec.message()));
    const std::string overlay = (dir / (request.name + "-overlay.png")).string();
    const std::string birdseye = (dir / (request.name + "-birdseye.png")).string();
    for (const auto& [path, picture] : {std::pair{overlay, DrawOverlay(*image, camera, *in, *r)},
                                        std::pair{birdseye, DrawBirdsEye(*image, camera, *in, *r)}}) {
      if (absl::Status s = WritePngRgb(path, picture); !s.ok()) {
        std::fprintf(stderr, "linecal aftersale: %s\n", std::string(s.message()).c_str());
        return cli::kExitNegative;
      }
    }
    j["overlay_png"] = overlay;
    j["birdseye_png"] = birdseye;
  }
  if (cl.Has("export")) {
    absl::StatusOr<std::vector<std::string>> written = Export(cl.Get("export"), request.name, *in, *r);
    if (!written.ok()) return cli::BadInput(kCommand, std::string(written.status().message()));
    j["export"] = *written;
  }
  if (cl.Has("json")) {
    std::printf("%s\n", j.dump(2).c_str());
  } else {
    std::printf("%s: vanishing point (%.2f, %.2f) px, yaw %.3f, pitch %.3f, roll %.3f deg (roll %s)\n",
                request.name.c_str(), r->vanishing_point_px.x(), r->vanishing_point_px.y(), r->angles.yaw / kDeg,
                r->angles.pitch / kDeg, r->angles.roll / kDeg, r->roll_from_line ? "from the roll line" : "assumed");
    if (r->distance_check) {
      const LaneDistanceCheck& c = *r->distance_check;
      std::printf("distance check: %.3f m computed, %.3f m measured, %+.2f%% (tolerance %.2f%%): %s\n",
                  c.computed_distance_m, c.measured_distance_m, c.error_percent, in->tolerance_percent,
                  c.pass ? "pass" : "FAIL");
    }
  }
  return r->distance_check && !r->distance_check->pass ? cli::kExitNegative : cli::kExitOk;
}

}  // namespace linecal::tools

#include "tools/linecal/plan_drawing.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "station/camera/camera_model.h"
#include "station/io/image_io.h"
#include "station/sensors/radar/field_of_view.h"

namespace linecal::tools {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr Rgb kBlack = {0, 0, 0};
constexpr Rgb kGrey = {120, 120, 120};
constexpr Rgb kRed = {200, 30, 30};

// Distinct colours per sensor (colour-blind-friendly palette, Okabe-Ito).
Rgb SensorColour(size_t i) {
  static const Rgb kPalette[] = {{0, 114, 178},  {230, 159, 0}, {0, 158, 115},  {204, 121, 167},
                                 {86, 180, 233}, {213, 94, 0},  {120, 80, 160}, {150, 150, 0},
                                 {0, 90, 90},    {160, 60, 60}};
  return kPalette[i % (sizeof kPalette / sizeof kPalette[0])];
}

std::string Hex(const Rgb& c) { return absl::StrFormat("#%02x%02x%02x", c[0], c[1], c[2]); }

// World (metres, a plane) to drawing pixels: x to the right, y up.
struct View {
  double x0 = 0, y0 = 0, scale = 40;  // world point (x0, y0) at the top-left pixel
  Eigen::Vector2d operator()(const Eigen::Vector2d& w) const {
    return {(w.x() - x0) * scale, (y0 - w.y()) * scale};
  }
};

void AddPolygon(Drawing* d, const View& v, const std::vector<Eigen::Vector2d>& world, Rgb fill,
                double opacity, Rgb stroke, double stroke_px, bool dashed = false) {
  DrawShape s;
  s.kind = world.size() == 2 ? DrawShape::kPolyline : DrawShape::kPolygon;
  for (const Eigen::Vector2d& p : world) s.points_px.push_back(v(p));
  s.fill = fill;
  s.fill_opacity = world.size() == 2 ? 0 : opacity;
  s.stroke = stroke;
  s.stroke_px = stroke_px;
  s.dashed = dashed;
  d->shapes.push_back(s);
}

void AddLine(Drawing* d, const View& v, const Eigen::Vector2d& a, const Eigen::Vector2d& b, Rgb c,
             double w, bool dashed = false) {
  AddPolygon(d, v, {a, b}, c, 0, c, w, dashed);
}

void AddText(Drawing* d, const View& v, const Eigen::Vector2d& at, const std::string& text, Rgb c,
             double font_px = 12) {
  DrawShape s;
  s.kind = DrawShape::kText;
  s.points_px = {v(at)};
  s.text = text;
  s.stroke = c;
  s.font_px = font_px;
  d->shapes.push_back(s);
}

void AddDot(Drawing* d, const View& v, const Eigen::Vector2d& at, double r_px, Rgb c) {
  DrawShape s;
  s.kind = DrawShape::kCircle;
  s.points_px = {v(at)};
  s.radius_px = r_px;
  s.fill = c;
  s.fill_opacity = 1;
  s.stroke = kBlack;
  s.stroke_px = 1;
  d->shapes.push_back(s);
}

// The horizontal (bird's-eye) or vertical (side) half-angles of a sensor's view about its
// heading, radians: cameras from the image edges' rays, radars from the model's FOV.
std::optional<std::pair<double, double>> HorizontalFov(const SensorModel& s) {
  if (s.kind == SensorKind::kRadar) {
    const std::optional<RadarFieldOfView> f = RadarFieldOfViewOf(s.model);
    if (!f) return std::nullopt;
    return std::make_pair(-f->half_fov_rad, f->half_fov_rad);
  }
  if (s.kind != SensorKind::kCamera || !s.intrinsics) return std::nullopt;
  absl::StatusOr<CameraModel> camera = CameraModel::Create(*s.intrinsics);
  if (!camera.ok()) return std::nullopt;
  const Eigen::Matrix3d R = s.T_car_sensor_nominal.RotationMatrix();
  const Eigen::Vector3d axis = R.col(2);
  const double heading = std::atan2(axis.y(), axis.x());
  double lo = 0, hi = 0;
  for (int i = 0; i <= 32; ++i) {
    // Along the image border, where the view is widest in azimuth.
    for (double v : {0.0, 0.5, 1.0}) {
      for (double u : {0.0, 1.0}) {
        const Eigen::Vector2d uv(u * (s.intrinsics->width - 1),
                                 v * (s.intrinsics->height - 1) * i / 32.0);
        Eigen::Vector3d ray;
        if (!camera->Unproject(uv, &ray)) continue;
        const Eigen::Vector3d w = R * ray;
        if (std::hypot(w.x(), w.y()) < 1e-6) continue;
        const double a = std::remainder(std::atan2(w.y(), w.x()) - heading, 2 * kPi);
        lo = std::min(lo, a);
        hi = std::max(hi, a);
      }
    }
  }
  return std::make_pair(lo, hi);
}

double Heading(const SensorModel& s) {
  const Eigen::Matrix3d R = s.T_car_sensor_nominal.RotationMatrix();
  const Eigen::Vector3d f = s.kind == SensorKind::kCamera  ? R.col(2)
                            : s.kind == SensorKind::kLidar ? R.col(1)
                                                           : R.col(0);
  return std::atan2(f.y(), f.x());
}

const SensorAssessment* AssessmentOf(const PlanScene& scene, const std::string& name) {
  if (scene.sensors == nullptr) return nullptr;
  for (const SensorAssessment& a : *scene.sensors) {
    if (a.sensor == name) return &a;
  }
  return nullptr;
}

bool TargetOk(const SensorAssessment* a, const std::string& target) {
  if (a == nullptr) return true;
  for (const TargetAssessment& t : a->targets) {
    if (t.target == target) return t.reasons.empty();
  }
  return false;
}

std::array<Eigen::Vector3d, 4> Corners(const StationBoard& b) {
  const Eigen::Vector2d h = 0.5 * b.board.page_size_m();
  std::array<Eigen::Vector3d, 4> c;
  const Eigen::Vector2d xy[4] = {
      {-h.x(), -h.y()}, {h.x(), -h.y()}, {h.x(), h.y()}, {-h.x(), h.y()}};
  for (int i = 0; i < 4; ++i) c[i] = b.T_station_board * Eigen::Vector3d(xy[i].x(), xy[i].y(), 0);
  return c;
}

std::optional<Eigen::Vector3d> TargetPoint(const StationLayout& layout, const std::string& id) {
  if (const StationBoard* b = layout.FindBoard(id)) return b->T_station_board.translation();
  if (const CornerReflector* r = layout.FindReflector(id)) return r->p_station;
  return std::nullopt;
}

// The layout's boards seen from above: an upright board as a thick line with a tick on its
// print side, a lying one as its footprint, each with its id.
void DrawBoards(const StationLayout& layout, const View& v, Drawing* d) {
  for (const StationBoard& b : layout.boards) {
    const std::array<Eigen::Vector3d, 4> c = Corners(b);
    std::vector<Eigen::Vector2d> fp = {c[0].head<2>(), c[1].head<2>(), c[2].head<2>(),
                                       c[3].head<2>()};
    const bool upright = (fp[0] - fp[3]).norm() < 1e-6;
    if (upright) {
      AddLine(d, v, fp[0], fp[1], kBlack, 5);
      // The print side: a short tick along the board's normal.
      const Eigen::Vector3d n = b.T_station_board.RotationMatrix().col(2);
      const Eigen::Vector2d m = b.T_station_board.translation().head<2>();
      AddLine(d, v, m, m + 0.3 * n.head<2>().normalized(), kBlack, 1.5);
    } else {
      AddPolygon(d, v, fp, {250, 250, 200}, 1, kBlack, 1.5);
    }
    AddText(d, v, b.T_station_board.translation().head<2>() + Eigen::Vector2d(0.1, 0.15), b.id,
            kBlack, 11);
  }
}

}  // namespace

Drawing BirdsEyeView(const PlanScene& scene) {
  const StationLayout& layout = *scene.layout;
  const CarModel& car = *scene.car;
  Eigen::AlignedBox2d box;
  if (scene.floor) {
    for (const Eigen::Vector2d& p : scene.floor->usable_area) box.extend(p);
    for (const FloorWall& w : scene.floor->walls) box.extend(w.from).extend(w.to);
  }
  for (const StationBoard& b : layout.boards) box.extend(b.T_station_board.translation().head<2>());
  for (const CornerReflector& r : layout.reflectors) box.extend(r.p_station.head<2>());
  for (const SensorModel& s : car.sensors)
    box.extend(s.T_car_sensor_nominal.translation().head<2>());
  box.extend(box.min() - Eigen::Vector2d(1, 1)).extend(box.max() + Eigen::Vector2d(1, 1));
  View v;
  v.scale = 50;
  // x forward points right; y left points up on the page.
  v.x0 = box.min().x();
  v.y0 = box.max().y();
  Drawing d;
  d.width_px = static_cast<int>(std::ceil(box.sizes().x() * v.scale));
  d.height_px = static_cast<int>(std::ceil(box.sizes().y() * v.scale)) + 30;
  AddPolygon(&d, v,
             {box.min(), {box.max().x(), box.min().y()}, box.max(), {box.min().x(), box.max().y()}},
             {255, 255, 255}, 1, {255, 255, 255}, 0);
  if (scene.floor) {
    AddPolygon(&d, v, scene.floor->usable_area, {236, 236, 236}, 1, kGrey, 1);
    for (const FloorWall& w : scene.floor->walls) AddLine(&d, v, w.from, w.to, {60, 60, 60}, 5);
    for (const KeepOutZone& z : scene.floor->keep_outs) {
      AddPolygon(&d, v, z.polygon, kRed, 0.18, kRed, 1.5, true);
      AddText(&d, v, z.polygon[0] + Eigen::Vector2d(0.05, 0.08), z.id, kRed, 10);
    }
    if (!scene.floor->car_outline.empty())
      AddPolygon(&d, v, scene.floor->car_outline, {200, 200, 210}, 0.9, kBlack, 2);
  }
  // 1 m grid ticks along the bottom: a scale bar.
  for (double x = std::ceil(box.min().x()); x <= box.max().x(); x += 1) {
    AddLine(&d, v, {x, box.min().y()}, {x, box.min().y() + (std::fmod(x, 5.0) == 0 ? 0.3 : 0.15)},
            kBlack, 1);
    if (std::fmod(x, 5.0) == 0)
      AddText(&d, v, {x + 0.05, box.min().y() + 0.35}, absl::StrFormat("x=%g m", x), kBlack, 10);
  }
  if (scene.regions) {
    // Boards only: the reflectors' regions are wide fans that would hide everything else
    // (plan.json has them).
    for (const ValidRegion& r : *scene.regions) {
      if (layout.FindBoard(r.target) == nullptr) continue;
      size_t k = 0;
      while (k < car.sensors.size() && car.sensors[k].name != r.sensor) ++k;
      if (r.polygon.size() >= 3)
        AddPolygon(&d, v, r.polygon, SensorColour(k), 0.10, SensorColour(k), 1, true);
    }
  }
  for (size_t k = 0; k < car.sensors.size(); ++k) {
    const SensorModel& s = car.sensors[k];
    const Eigen::Vector2d eye = s.T_car_sensor_nominal.translation().head<2>();
    const Rgb c = SensorColour(k);
    const std::optional<std::pair<double, double>> fov = HorizontalFov(s);
    if (fov) {
      const double heading = Heading(s);
      std::vector<Eigen::Vector2d> wedge = {eye};
      // As far as the sensor's farthest target, so that wide lenses do not cover the page.
      double radius = 1.0;
      for (const std::string& t : s.targets) {
        if (const std::optional<Eigen::Vector3d> p = TargetPoint(layout, t)) {
          radius = std::max(radius, (p->head<2>() - eye).norm() + 0.8);
        }
      }
      for (int i = 0; i <= 24; ++i) {
        const double a = heading + fov->first + (fov->second - fov->first) * i / 24.0;
        wedge.push_back(eye + radius * Eigen::Vector2d(std::cos(a), std::sin(a)));
      }
      AddPolygon(&d, v, wedge, c, 0.05, c, 0.5);
    }
    const SensorAssessment* a = AssessmentOf(scene, s.name);
    for (const std::string& t : s.targets) {
      const std::optional<Eigen::Vector3d> p = TargetPoint(layout, t);
      if (p)
        AddLine(&d, v, eye, p->head<2>(), TargetOk(a, t) ? c : kRed, TargetOk(a, t) ? 0.8 : 1.5,
                !TargetOk(a, t));
    }
  }
  DrawBoards(layout, v, &d);
  for (const CornerReflector& r : layout.reflectors) {
    AddDot(&d, v, r.p_station.head<2>(), 4, {255, 220, 0});
    AddText(&d, v, r.p_station.head<2>() + Eigen::Vector2d(0.1, 0.1), r.id, kBlack, 10);
  }
  for (size_t k = 0; k < car.sensors.size(); ++k) {
    const SensorModel& s = car.sensors[k];
    const SensorAssessment* a = AssessmentOf(scene, s.name);
    const Eigen::Vector2d eye = s.T_car_sensor_nominal.translation().head<2>();
    AddDot(&d, v, eye, 4, SensorColour(k));
    const std::string label =
        a == nullptr ? s.name : absl::StrCat(s.name, a->calibratable ? " ok" : " NOT calibratable");
    AddText(&d, v, eye + Eigen::Vector2d(0.08, -0.25 - 0.18 * (k % 3)), label,
            a && !a->calibratable ? kRed : kBlack, 10);
  }
  DrawShape title;
  title.kind = DrawShape::kText;
  title.points_px = {{8, d.height_px - 10.0}};
  title.text = absl::StrCat(
      "bird's-eye view: car '", car.id, "', station '", layout.name,
      "' (x forward to the right, y left up; 1 m ticks; dashed red: keep-out / failing target)");
  title.font_px = 12;
  d.shapes.push_back(title);
  return d;
}

Drawing SideView(const PlanScene& scene, const SensorModel& sensor) {
  const StationLayout& layout = *scene.layout;
  const Eigen::Vector3d eye = sensor.T_car_sensor_nominal.translation();
  const double heading = Heading(sensor);
  const Eigen::Vector2d dir(std::cos(heading), std::sin(heading));
  // Distance along the heading from the sensor, and height.
  const auto along = [&](const Eigen::Vector3d& p) {
    return Eigen::Vector2d((p - eye).head<2>().dot(dir), p.z());
  };
  double far = 6;
  for (const std::string& t : sensor.targets) {
    if (std::optional<Eigen::Vector3d> p = TargetPoint(layout, t))
      far = std::max(far, along(*p).x() + 1.5);
  }
  const double top = (scene.floor ? scene.floor->max_height_m : 3.0) + 0.7;
  View v;
  v.scale = std::min(80.0, 1100.0 / (far + 1));
  v.x0 = -1;
  v.y0 = top;
  Drawing d;
  d.width_px = static_cast<int>(std::ceil((far + 1) * v.scale));
  d.height_px = static_cast<int>(std::ceil((top + 0.5) * v.scale)) + 30;
  AddPolygon(&d, v, {{-1, top}, {far, top}, {far, -0.5}, {-1, -0.5}}, {255, 255, 255}, 1,
             {255, 255, 255}, 0);
  AddPolygon(&d, v, {{-1, 0}, {far, 0}, {far, -0.5}, {-1, -0.5}}, {225, 225, 225}, 1, kGrey, 1);
  if (scene.floor) {
    AddLine(&d, v, {-1, scene.floor->max_height_m}, {far, scene.floor->max_height_m}, kRed, 1,
            true);
    AddText(&d, v, {-0.9, scene.floor->max_height_m + 0.08}, "height limit", kRed, 10);
  }
  for (double x = 0; x <= far; x += 1) AddLine(&d, v, {x, 0}, {x, -0.12}, kBlack, 1);
  const Rgb c = {0, 114, 178};
  const double reach = far;
  // A ray of the sensor at `elevation`, up to `reach` or the floor.
  const auto ray_end = [&](double elevation) {
    const Eigen::Vector2d o(0, eye.z());
    const Eigen::Vector2d dir(std::cos(elevation), std::sin(elevation));
    const double length = dir.y() < 0 ? std::min(reach, eye.z() / -dir.y()) : reach;
    return Eigen::Vector2d(o + length * dir);
  };
  const auto ray = [&](double elevation, Rgb colour, double w) {
    AddLine(&d, v, {0, eye.z()}, ray_end(elevation), colour, w);
  };
  if (sensor.kind == SensorKind::kLidar) {
    const absl::StatusOr<LidarBeamTable> beams = LidarBeamTableOf(sensor);
    if (beams.ok()) {
      for (const LidarBeam& b : beams->beams) ray(b.elevation_rad, {150, 190, 230}, 0.6);
    }
  } else if (sensor.kind == SensorKind::kCamera && sensor.intrinsics) {
    absl::StatusOr<CameraModel> camera = CameraModel::Create(*sensor.intrinsics);
    if (camera.ok()) {
      const Eigen::Matrix3d R = sensor.T_car_sensor_nominal.RotationMatrix();
      std::vector<Eigen::Vector2d> wedge = {{0, eye.z()}};
      for (int i = 0; i <= 24; ++i) {
        Eigen::Vector3d r;
        if (!camera->Unproject({sensor.intrinsics->cx, (sensor.intrinsics->height - 1) * i / 24.0},
                               &r))
          continue;
        const Eigen::Vector3d w = R * r;
        const double e = std::atan2(w.z(), w.head<2>().dot(dir));
        wedge.push_back(ray_end(e));
      }
      AddPolygon(&d, v, wedge, c, 0.10, c, 1);
    }
  } else {
    ray(0, c, 1);
  }
  const SensorAssessment* a = AssessmentOf(scene, sensor.name);
  int label_row = 0;  // symmetric boards overlap in this view: their labels go one under another
  for (const std::string& t : sensor.targets) {
    const bool ok = TargetOk(a, t);
    const double label_dz = -0.18 * label_row++;
    if (const StationBoard* b = layout.FindBoard(t)) {
      const std::array<Eigen::Vector3d, 4> cs = Corners(*b);
      Eigen::AlignedBox2d extent;
      for (const Eigen::Vector3d& p : cs) extent.extend(along(p));
      AddPolygon(&d, v,
                 {extent.min(),
                  {extent.max().x(), extent.min().y()},
                  extent.max(),
                  {extent.min().x(), extent.max().y()}},
                 ok ? Rgb{250, 250, 200} : Rgb{255, 200, 200}, 1, ok ? kBlack : kRed, 2);
      AddText(&d, v, {extent.max().x() + 0.05, extent.max().y() + 0.05 + label_dz}, t,
              ok ? kBlack : kRed, 11);
    } else if (const CornerReflector* r = layout.FindReflector(t)) {
      AddDot(&d, v, along(r->p_station), 4, {255, 220, 0});
      AddText(&d, v, along(r->p_station) + Eigen::Vector2d(0.05, 0.1 + label_dz), t,
              ok ? kBlack : kRed, 10);
    }
  }
  AddDot(&d, v, {0, eye.z()}, 5, c);
  std::string caption = absl::StrCat("side view of ", sensor.name,
                                     " (distance along its heading, height; 1 m ticks)");
  if (a != nullptr) {
    caption += a->calibratable ? ": calibratable" : ": NOT calibratable";
    for (const std::string& r : a->reasons) caption += " " + r;
  }
  // Room for the caption (about 7 px per character at 12 px).
  d.width_px = std::max(d.width_px, static_cast<int>(7 * caption.size()) + 16);
  DrawShape title;
  title.kind = DrawShape::kText;
  title.points_px = {{8, d.height_px - 10.0}};
  title.text = caption;
  title.font_px = 12;
  d.shapes.push_back(title);
  return d;
}

std::string DrawingToSvg(const Drawing& drawing) {
  std::string svg = absl::StrFormat(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%d\" height=\"%d\" viewBox=\"0 0 %d %d\" "
      "font-family=\"sans-serif\">\n",
      drawing.width_px, drawing.height_px, drawing.width_px, drawing.height_px);
  for (const DrawShape& s : drawing.shapes) {
    const std::string dash = s.dashed ? " stroke-dasharray=\"6,4\"" : "";
    const std::string stroke = s.stroke_px > 0
                                   ? absl::StrFormat(" stroke=\"%s\" stroke-width=\"%.2f\"%s",
                                                     Hex(s.stroke), s.stroke_px, dash)
                                   : " stroke=\"none\"";
    const std::string fill =
        s.fill_opacity > 0
            ? absl::StrFormat(" fill=\"%s\" fill-opacity=\"%.2f\"", Hex(s.fill), s.fill_opacity)
            : " fill=\"none\"";
    std::string points;
    for (const Eigen::Vector2d& p : s.points_px)
      points += absl::StrFormat("%.1f,%.1f ", p.x(), p.y());
    switch (s.kind) {
      case DrawShape::kPolygon:
        svg += absl::StrCat("<polygon points=\"", points, "\"", fill, stroke, "/>\n");
        break;
      case DrawShape::kPolyline:
        svg += absl::StrCat("<polyline points=\"", points, "\" fill=\"none\"", stroke, "/>\n");
        break;
      case DrawShape::kCircle:
        svg += absl::StrFormat("<circle cx=\"%.1f\" cy=\"%.1f\" r=\"%.1f\"%s%s/>\n",
                               s.points_px[0].x(), s.points_px[0].y(), s.radius_px, fill, stroke);
        break;
      case DrawShape::kText: {
        std::string text;
        for (char ch : s.text) {
          text += ch == '<'   ? "&lt;"
                  : ch == '>' ? "&gt;"
                  : ch == '&' ? "&amp;"
                              : std::string(1, ch);
        }
        svg += absl::StrFormat(
            "<text x=\"%.1f\" y=\"%.1f\" font-size=\"%.0f\" fill=\"%s\">%s</text>\n",
            s.points_px[0].x(), s.points_px[0].y(), s.font_px, Hex(s.stroke), text);
        break;
      }
    }
  }
  svg += "</svg>\n";
  return svg;
}

namespace {

// OpenCV has no dashes: 6 px on, 4 px off along each segment.
void DashedLine(cv::Mat& image, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                const cv::Scalar& colour, int thickness) {
  const double len = (b - a).norm();
  for (double t = 0; t < len; t += 10) {
    const Eigen::Vector2d p = a + (b - a) * (t / len),
                          q = a + (b - a) * (std::min(t + 6, len) / len);
    cv::line(image, {cvRound(p.x()), cvRound(p.y())}, {cvRound(q.x()), cvRound(q.y())}, colour,
             thickness, cv::LINE_AA);
  }
}

}  // namespace

absl::Status WriteDrawingPng(const Drawing& drawing, const std::string& path) {
  cv::Mat image(drawing.height_px, drawing.width_px, CV_8UC3, cv::Scalar(255, 255, 255));
  const auto colour = [](const Rgb& c) {
    return cv::Scalar(c[0], c[1], c[2]);
  };  // the Mat is RGB here
  for (const DrawShape& s : drawing.shapes) {
    std::vector<cv::Point> pts;
    for (const Eigen::Vector2d& p : s.points_px) pts.emplace_back(cvRound(p.x()), cvRound(p.y()));
    const int thickness = std::max(1, static_cast<int>(std::lround(s.stroke_px)));
    switch (s.kind) {
      case DrawShape::kPolygon: {
        if (s.fill_opacity > 0) {
          cv::Mat layer = image.clone();
          cv::fillPoly(layer, std::vector<std::vector<cv::Point>>{pts}, colour(s.fill),
                       cv::LINE_AA);
          cv::addWeighted(layer, s.fill_opacity, image, 1 - s.fill_opacity, 0, image);
        }
        if (s.stroke_px > 0 && s.dashed) {
          for (size_t i = 0; i < s.points_px.size(); ++i) {
            DashedLine(image, s.points_px[i], s.points_px[(i + 1) % s.points_px.size()],
                       colour(s.stroke), thickness);
          }
        } else if (s.stroke_px > 0) {
          cv::polylines(image, pts, true, colour(s.stroke), thickness, cv::LINE_AA);
        }
        break;
      }
      case DrawShape::kPolyline:
        if (s.dashed) {
          for (size_t i = 0; i + 1 < s.points_px.size(); ++i) {
            DashedLine(image, s.points_px[i], s.points_px[i + 1], colour(s.stroke), thickness);
          }
        } else {
          cv::polylines(image, pts, false, colour(s.stroke), thickness, cv::LINE_AA);
        }
        break;
      case DrawShape::kCircle:
        cv::circle(image, pts[0], cvRound(s.radius_px), colour(s.fill), cv::FILLED, cv::LINE_AA);
        cv::circle(image, pts[0], cvRound(s.radius_px), colour(s.stroke), 1, cv::LINE_AA);
        break;
      case DrawShape::kText:
        cv::putText(image, s.text, pts[0], cv::FONT_HERSHEY_SIMPLEX, s.font_px / 30.0,
                    colour(s.stroke), 1, cv::LINE_AA);
        break;
    }
  }
  RgbImage out(drawing.width_px, drawing.height_px);
  std::copy(image.data, image.data + out.rgb.size(), out.rgb.begin());
  return WritePngRgb(path, out);
}

absl::Status WritePlanDrawings(const PlanScene& scene, const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return absl::InternalError(absl::StrCat(dir, ": cannot create: ", ec.message()));
  const auto write = [&](const Drawing& d, const std::string& stem) -> absl::Status {
    const std::string svg_path = (std::filesystem::path(dir) / (stem + ".svg")).string();
    std::ofstream out(svg_path);
    out << DrawingToSvg(d);
    if (!out) return absl::InternalError(absl::StrCat(svg_path, ": cannot write"));
    return WriteDrawingPng(d, (std::filesystem::path(dir) / (stem + ".png")).string());
  };
  if (absl::Status s = write(BirdsEyeView(scene), "birdseye"); !s.ok()) return s;
  for (const SensorModel& s : scene.car->sensors) {
    if (absl::Status st = write(SideView(scene, s), "side_" + s.name); !st.ok()) return st;
  }
  return absl::OkStatus();
}

}  // namespace linecal::tools

#pragma once
// Drawings of a station plan for `linecal plan` and `linecal plan check`: a bird's-eye view
// (floor, walls, keep-outs, car outline, sensors with their field-of-view wedges, boards,
// reflectors, valid regions, lines of sight) and a side view per sensor (its vertical field
// of view or LiDAR rings, its targets' heights, the height limits). One list of primitives
// is written both as SVG (text) and as PNG (rasterised with OpenCV's drawing functions).

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/planner/floor_limits.h"
#include "station/planner/planner.h"

namespace linecal::tools {

using Rgb = std::array<std::uint8_t, 3>;

struct DrawShape {
  enum Kind { kPolygon, kPolyline, kCircle, kText } kind = kPolygon;
  std::vector<Eigen::Vector2d>
      points_px;  // polygon / polyline vertices; circle centre; text anchor
  Rgb fill = {255, 255, 255};
  double fill_opacity = 0;  // 0: not filled
  Rgb stroke = {0, 0, 0};
  double stroke_px = 1;  // 0: no outline
  bool dashed = false;
  double radius_px = 0;  // circles
  std::string text;      // texts
  double font_px = 12;
};

struct Drawing {
  int width_px = 0;
  int height_px = 0;
  std::vector<DrawShape> shapes;  // painter's order
};

// The inputs of a drawing. `floor` and `regions` may be empty / null.
struct PlanScene {
  const CarModel* car = nullptr;
  const StationLayout* layout = nullptr;
  const FloorLimits* floor = nullptr;
  const std::vector<SensorAssessment>* sensors = nullptr;
  const std::vector<ValidRegion>* regions = nullptr;
};

Drawing BirdsEyeView(const PlanScene& scene);
Drawing SideView(const PlanScene& scene, const SensorModel& sensor);

std::string DrawingToSvg(const Drawing& drawing);
// Errors name the path.
absl::Status WriteDrawingPng(const Drawing& drawing, const std::string& path);

// Writes birdseye.{svg,png} and side_<sensor>.{svg,png} into `dir` (created if missing).
absl::Status WritePlanDrawings(const PlanScene& scene, const std::string& dir);

}  // namespace linecal::tools

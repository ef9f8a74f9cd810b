#include "station/planner/floor_limits.h"

#include <cmath>
#include <set>

#include "absl/strings/str_cat.h"
#include "station/io/json_reader.h"

namespace linecal {
namespace {

absl::StatusOr<FloorPolygon> ReadPolygon(const JsonField& parent, const std::string& key) {
  absl::StatusOr<std::vector<JsonField>> items = parent.Array(key);
  if (!items.ok()) return items.status();
  if (items->size() < 3)
    return parent.Error(key, absl::StrCat("needs at least 3 vertices, got ", items->size()));
  FloorPolygon polygon;
  for (const JsonField& item : *items) {
    if (!item.node().is_array() || item.node().size() != 2 || !item.node()[0].is_number() ||
        !item.node()[1].is_number()) {
      return item.Error("must be [x, y] in metres");
    }
    const Eigen::Vector2d p(item.node()[0].get<double>(), item.node()[1].get<double>());
    if (!p.allFinite()) return item.Error("must be finite");
    polygon.push_back(p);
  }
  return polygon;
}

absl::StatusOr<Eigen::Vector2d> ReadPoint(const JsonField& parent, const std::string& key) {
  absl::StatusOr<std::vector<double>> xy = parent.Numbers(key, 2);
  if (!xy.ok()) return xy.status();
  return Eigen::Vector2d((*xy)[0], (*xy)[1]);
}

double Cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

bool OnSegment(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& p) {
  return std::min(a.x(), b.x()) - 1e-12 <= p.x() && p.x() <= std::max(a.x(), b.x()) + 1e-12 &&
         std::min(a.y(), b.y()) - 1e-12 <= p.y() && p.y() <= std::max(a.y(), b.y()) + 1e-12;
}

}  // namespace

absl::StatusOr<FloorLimits> ParseFloorLimits(const std::string& text, const std::string& source) {
  absl::StatusOr<JsonDocument> doc = JsonDocument::FromText(text, source);
  if (!doc.ok()) return doc.status();
  absl::StatusOr<JsonField> root = doc->Root();
  if (!root.ok()) return root.status();
  if (auto s = root->AllowOnlyKeys({"format", "version", "name", "usable_area_m", "walls",
                                    "height_limits_m", "keep_out", "car_outline_m"});
      !s.ok()) {
    return s;
  }
  absl::StatusOr<std::string> format = root->String("format");
  if (!format.ok()) return format.status();
  if (*format != kFloorLimitsFormat) {
    return root->Error("format",
                       absl::StrCat("expected '", kFloorLimitsFormat, "', got '", *format, "'"));
  }
  absl::StatusOr<std::int64_t> version = root->Integer("version");
  if (!version.ok()) return version.status();
  if (*version != kFloorLimitsVersion) {
    return root->Error("version", absl::StrCat("unsupported version ", *version,
                                               " (this build reads ", kFloorLimitsVersion, ")"));
  }
  FloorLimits f;
  absl::StatusOr<std::string> name = root->String("name");
  if (!name.ok()) return name.status();
  f.name = *name;
  absl::StatusOr<FloorPolygon> usable = ReadPolygon(*root, "usable_area_m");
  if (!usable.ok()) return usable.status();
  f.usable_area = *usable;
  if (root->Has("height_limits_m")) {
    absl::StatusOr<std::vector<double>> h = root->Numbers("height_limits_m", 2);
    if (!h.ok()) return h.status();
    if (!((*h)[0] >= 0 && (*h)[0] < (*h)[1])) {
      return root->Error("height_limits_m", "must be [min, max] with 0 <= min < max");
    }
    f.min_height_m = (*h)[0];
    f.max_height_m = (*h)[1];
  }
  std::set<std::string> ids;
  if (root->Has("walls")) {
    absl::StatusOr<std::vector<JsonField>> walls = root->Array("walls");
    if (!walls.ok()) return walls.status();
    for (const JsonField& w : *walls) {
      if (auto s = w.AllowOnlyKeys({"id", "from_m", "to_m"}); !s.ok()) return s;
      FloorWall wall;
      absl::StatusOr<std::string> id = w.String("id");
      if (!id.ok()) return id.status();
      if (!ids.insert(*id).second) return w.Error("id", absl::StrCat("duplicate id '", *id, "'"));
      wall.id = *id;
      absl::StatusOr<Eigen::Vector2d> from = ReadPoint(w, "from_m");
      if (!from.ok()) return from.status();
      absl::StatusOr<Eigen::Vector2d> to = ReadPoint(w, "to_m");
      if (!to.ok()) return to.status();
      if ((*from - *to).norm() < 1e-6) return w.Error("to_m", "must differ from from_m");
      wall.from = *from;
      wall.to = *to;
      f.walls.push_back(wall);
    }
  }
  if (root->Has("keep_out")) {
    absl::StatusOr<std::vector<JsonField>> zones = root->Array("keep_out");
    if (!zones.ok()) return zones.status();
    for (const JsonField& z : *zones) {
      if (auto s = z.AllowOnlyKeys({"id", "description", "polygon_m"}); !s.ok()) return s;
      KeepOutZone zone;
      absl::StatusOr<std::string> id = z.String("id");
      if (!id.ok()) return id.status();
      if (!ids.insert(*id).second) return z.Error("id", absl::StrCat("duplicate id '", *id, "'"));
      zone.id = *id;
      absl::StatusOr<std::string> description = z.StringOr("description", "");
      if (!description.ok()) return description.status();
      zone.description = *description;
      absl::StatusOr<FloorPolygon> polygon = ReadPolygon(z, "polygon_m");
      if (!polygon.ok()) return polygon.status();
      zone.polygon = *polygon;
      f.keep_outs.push_back(zone);
    }
  }
  if (root->Has("car_outline_m")) {
    absl::StatusOr<FloorPolygon> outline = ReadPolygon(*root, "car_outline_m");
    if (!outline.ok()) return outline.status();
    f.car_outline = *outline;
  }
  return f;
}

absl::StatusOr<FloorLimits> ReadFloorLimits(const std::string& path) {
  absl::StatusOr<std::string> text = ReadTextFile(path);
  if (!text.ok()) return text.status();
  return ParseFloorLimits(*text, path);
}

bool PointInPolygon(const Eigen::Vector2d& p, const FloorPolygon& polygon) {
  bool inside = false;
  for (size_t i = 0, j = polygon.size() - 1; i < polygon.size(); j = i++) {
    const Eigen::Vector2d& a = polygon[i];
    const Eigen::Vector2d& b = polygon[j];
    if ((a.y() > p.y()) != (b.y() > p.y()) &&
        p.x() < (b.x() - a.x()) * (p.y() - a.y()) / (b.y() - a.y()) + a.x()) {
      inside = !inside;
    }
  }
  return inside;
}

bool SegmentsIntersect(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c,
                       const Eigen::Vector2d& d) {
  const double d1 = Cross(b - a, c - a);
  const double d2 = Cross(b - a, d - a);
  const double d3 = Cross(d - c, a - c);
  const double d4 = Cross(d - c, b - c);
  if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0)))
    return true;
  // Touching and collinear cases.
  if (d1 == 0 && OnSegment(a, b, c)) return true;
  if (d2 == 0 && OnSegment(a, b, d)) return true;
  if (d3 == 0 && OnSegment(c, d, a)) return true;
  if (d4 == 0 && OnSegment(c, d, b)) return true;
  return false;
}

bool PolygonsOverlap(const FloorPolygon& a, const FloorPolygon& b) {
  const auto edges = [](const FloorPolygon& p) { return p.size() == 2 ? size_t{1} : p.size(); };
  for (size_t i = 0; i < edges(a); ++i) {
    for (size_t j = 0; j < edges(b); ++j) {
      if (SegmentsIntersect(a[i], a[(i + 1) % a.size()], b[j], b[(j + 1) % b.size()])) return true;
    }
  }
  if (b.size() >= 3 && !a.empty() && PointInPolygon(a[0], b)) return true;
  if (a.size() >= 3 && !b.empty() && PointInPolygon(b[0], a)) return true;
  return false;
}

}  // namespace linecal

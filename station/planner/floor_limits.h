#pragma once
// The floor limits of a station for the board placement planner (docs/planner.md): where
// boards and reflectors may stand. Station frame (docs/conventions.md), metres; polygons lie in
// the floor plane z = 0 and are given as [x, y] vertices in order (either orientation).

#include <Eigen/Core>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace linecal {

inline constexpr char kFloorLimitsFormat[] = "linecal.floor";
inline constexpr int kFloorLimitsVersion = 1;

using FloorPolygon = std::vector<Eigen::Vector2d>;

// An area nothing may stand in: the wheel aligner's heads, the car's path in and out.
struct KeepOutZone {
  std::string id;
  std::string description;
  FloorPolygon polygon;
};

// A wall as a segment of the floor plan: a board or its stand may not cross it.
struct FloorWall {
  std::string id;
  Eigen::Vector2d from = Eigen::Vector2d::Zero();
  Eigen::Vector2d to = Eigen::Vector2d::Zero();
};

struct FloorLimits {
  std::string name;
  FloorPolygon usable_area;  // every board footprint and reflector lies inside it
  std::vector<FloorWall> walls;
  double min_height_m = 0.0;  // lowest point of a board or reflector above the floor
  double max_height_m = 3.0;  // highest point (ceiling, lamps, crane rails)
  std::vector<KeepOutZone> keep_outs;
  // The car's outline on the floor in the station frame, for the drawings only; empty:
  // none drawn.
  FloorPolygon car_outline;
};

// Reads a floor limits file (`linecal.floor`, version 1). Errors (InvalidArgument) name the
// file and the field; polygons need at least 3 vertices and min_height_m < max_height_m.
absl::StatusOr<FloorLimits> ReadFloorLimits(const std::string& path);
absl::StatusOr<FloorLimits> ParseFloorLimits(const std::string& text, const std::string& source);

// Point in a simple polygon (even-odd rule; points on an edge may go either way). O(n).
bool PointInPolygon(const Eigen::Vector2d& p, const FloorPolygon& polygon);
// True when the closed segments ab and cd share a point. O(1).
bool SegmentsIntersect(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c,
                       const Eigen::Vector2d& d);
// True when two simple polygons overlap (an edge crosses, or one holds a vertex of the
// other). A "polygon" of two vertices is a segment. O(n m).
bool PolygonsOverlap(const FloorPolygon& a, const FloorPolygon& b);

}  // namespace linecal

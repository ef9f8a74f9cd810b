#pragma once
// The station layout: what stands around the car, surveyed in the station frame
// (docs/station-and-car.md documents the file).

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "detectors/boards/board.h"
#include "detectors/core/pose.h"

namespace linecal {

struct StationBoard {
  std::string id;  // unique in the layout, e.g. "front_chessboard"
  BoardParams params;
  Board board;              // built from params
  Rigid3d T_station_board;  // board frame (page centre) in the station frame
  // Whether a calibration may use a partial view of this board (the features the detector
  // is certain of, with their ids). Off by default: a board the station planned is expected
  // whole, and a partial view usually means a board knocked, hidden or out of frame, which
  // the operator should hear about. Only boards with ids allow it (BoardAllowsPartial).
  bool allow_partial = false;
};

// Whether a board of this type reports partial views with ids (vertical, ArUco, AprilTag grid,
// round-hole and ChArUco boards): a partial view of a chessboard or circle grid cannot be
// placed on the board, so `allow_partial` is refused for those. O(1).
bool BoardAllowsPartial(BoardType type);

// A trihedral corner reflector for radars: a point target.
struct CornerReflector {
  std::string id;
  Eigen::Vector3d p_station = Eigen::Vector3d::Zero();  // metres, the reflector's apex
  double rcs_dbsm = 20.0;                               // radar cross-section, dBm²
};

// A flat rectangular surface (a wall, a screen) for backgrounds and LiDAR returns.
struct StationSurface {
  std::string id;
  Rigid3d T_station_surface;  // surface frame: the rectangle lies in its x-y plane, centred
  Eigen::Vector2d size_m = Eigen::Vector2d::Zero();  // extent along x and y of that frame
  double reflectivity = 0.5;                         // 0..1: grey level and LiDAR intensity
};

struct StationLayout {
  std::string name;
  std::vector<StationBoard> boards;
  std::vector<CornerReflector> reflectors;
  // The floor is the plane z = 0 of the station frame, always present.
  double floor_reflectivity = 0.3;
  std::vector<StationSurface> surfaces;

  const StationBoard* FindBoard(const std::string& id) const;
  const CornerReflector* FindReflector(const std::string& id) const;
};

// Reads a station layout file. Errors name the file and the field ("boards[1].type: unknown
// board type 'chess'; known: chessboard, ..."). Ids must be unique.
absl::StatusOr<StationLayout> ReadStationLayout(const std::string& path);
// The same from text already in memory; `source` names it in messages.
absl::StatusOr<StationLayout> ParseStationLayout(const std::string& text,
                                                 const std::string& source);
nlohmann::json StationLayoutToJson(const StationLayout& layout);

// A board's parameters as the station file writes them: "scale" and the keys of its type
// (docs/station-and-car.md), e.g. {"scale": 1, "cols": 9, "rows": 6, "square_m": 0.025}.
nlohmann::json BoardParamsToJson(const BoardParams& params);

}  // namespace linecal

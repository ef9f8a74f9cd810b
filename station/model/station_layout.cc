#include "station/model/station_layout.h"

#include <algorithm>
#include <set>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "station/io/json_reader.h"
#include "station/model/pose_json.h"

namespace linecal {
namespace {

constexpr const char* kFormat = "linecal.station";
constexpr int kVersion = 1;

// Out-of-int values fall to the board's validation as a clearly bad value.
int ClampToInt(std::int64_t v) {
  constexpr std::int64_t kClamp = 1 << 20;
  return static_cast<int>(std::clamp<std::int64_t>(v, -kClamp, kClamp));
}

// The AprilGrid's keys (docs/station-and-car.md): tag_cols, tag_rows, tag_spacing, start_id;
// absent ones keep the PDF's grid.
absl::Status ReadAprilGrid(const JsonField& f, BoardParams* params) {
  absl::StatusOr<std::int64_t> cols = f.IntegerOr("tag_cols", params->apriltag_cols);
  if (!cols.ok()) return cols.status();
  absl::StatusOr<std::int64_t> rows = f.IntegerOr("tag_rows", params->apriltag_rows);
  if (!rows.ok()) return rows.status();
  absl::StatusOr<double> spacing = f.NumberOr("tag_spacing", params->apriltag_spacing);
  if (!spacing.ok()) return spacing.status();
  absl::StatusOr<std::int64_t> start = f.IntegerOr("start_id", params->apriltag_start_id);
  if (!start.ok()) return start.status();
  params->apriltag_cols = ClampToInt(*cols);
  params->apriltag_rows = ClampToInt(*rows);
  params->apriltag_spacing = *spacing;
  params->apriltag_start_id = ClampToInt(*start);
  return absl::OkStatus();
}

// The station file's key of the field a BoardParamsError is about.
const char* KeyOfBoardError(BoardParamsError error) {
  switch (error) {
    case BoardParamsError::kOk:
    case BoardParamsError::kBadScale:
      return "scale";
    case BoardParamsError::kBadCols:
      return "cols";
    case BoardParamsError::kBadRows:
      return "rows";
    case BoardParamsError::kBadSquare:
      return "square_m";
    case BoardParamsError::kBadSpacing:
      return "spacing_m";
    case BoardParamsError::kBadDiameter:
      return "diameter_m";
    case BoardParamsError::kBadBorderBits:
      return "border_bits";
    case BoardParamsError::kBadTagGrid:
      return "tag_cols";
    case BoardParamsError::kBadTagSpacing:
      return "tag_spacing";
    case BoardParamsError::kBadStartId:
      return "start_id";
    case BoardParamsError::kBadLayout:
      return "hexagonal";
    case BoardParamsError::kBadGap:
      return "gap_m";
    case BoardParamsError::kBadMarker:
      return "marker_m";
    case BoardParamsError::kBadMarkerCount:
      return "dictionary";
  }
  return "type";
}

absl::StatusOr<StationBoard> ReadBoard(const JsonField& f) {
  if (auto s = f.AllowOnlyKeys({"id",         "type",           "scale",       "cols",
                                "rows",       "square_m",       "spacing_m",   "diameter_m",
                                "asymmetric", "light_circles",  "border_bits", "tag_cols",
                                "tag_rows",   "tag_spacing",    "start_id",    "gap_m",
                                "marker_m",   "legacy_pattern", "dictionary",  "pose",
                                "hexagonal",  "allow_partial"});
      !s.ok()) {
    return s;
  }
  absl::StatusOr<std::string> id = f.String("id");
  if (!id.ok()) return id.status();
  BoardParams params;
  absl::StatusOr<std::string> type = f.String("type");
  if (!type.ok()) return type.status();
  const std::optional<BoardType> board_type = BoardTypeFromName(*type);
  if (!board_type) {
    std::vector<std::string> names;
    for (BoardType t : kAllBoardTypes) names.push_back(BoardTypeName(t));
    return f.Error("type", absl::StrCat("unknown board type '", *type,
                                        "'; known: ", absl::StrJoin(names, ", ")));
  }
  params.type = *board_type;
  absl::StatusOr<double> scale = f.NumberOr("scale", 1.0);
  if (!scale.ok()) return scale.status();
  params.scale = *scale;
  absl::StatusOr<std::int64_t> cols = f.IntegerOr("cols", params.cols);
  if (!cols.ok()) return cols.status();
  absl::StatusOr<std::int64_t> rows = f.IntegerOr("rows", params.rows);
  if (!rows.ok()) return rows.status();
  absl::StatusOr<double> square = f.NumberOr("square_m", params.square_m);
  if (!square.ok()) return square.status();
  absl::StatusOr<double> gap = f.NumberOr("gap_m", params.gap_m);
  if (!gap.ok()) return gap.status();
  absl::StatusOr<double> spacing = f.NumberOr("spacing_m", params.spacing_m);
  if (!spacing.ok()) return spacing.status();
  absl::StatusOr<double> diameter = f.NumberOr("diameter_m", params.diameter_m);
  if (!diameter.ok()) return diameter.status();
  absl::StatusOr<bool> asymmetric = f.BoolOr("asymmetric", params.asymmetric);
  if (!asymmetric.ok()) return asymmetric.status();
  absl::StatusOr<bool> light_circles = f.BoolOr("light_circles", params.light_circles);
  if (!light_circles.ok()) return light_circles.status();
  absl::StatusOr<bool> hexagonal = f.BoolOr("hexagonal", params.hexagonal);
  if (!hexagonal.ok()) return hexagonal.status();
  absl::StatusOr<std::int64_t> border = f.IntegerOr("border_bits", params.apriltag_border_bits);
  if (!border.ok()) return border.status();
  params.cols = ClampToInt(*cols);
  params.rows = ClampToInt(*rows);
  params.square_m = *square;
  params.gap_m = *gap;
  params.spacing_m = *spacing;
  params.diameter_m = *diameter;
  params.asymmetric = *asymmetric;
  params.light_circles = *light_circles;
  params.hexagonal = *hexagonal;
  params.apriltag_border_bits = ClampToInt(*border);
  absl::StatusOr<double> marker = f.NumberOr("marker_m", params.marker_m);
  if (!marker.ok()) return marker.status();
  params.marker_m = *marker;
  absl::StatusOr<bool> legacy = f.BoolOr("legacy_pattern", params.charuco_legacy);
  if (!legacy.ok()) return legacy.status();
  params.charuco_legacy = *legacy;
  absl::StatusOr<std::string> dictionary =
      f.StringOr("dictionary", ArucoDictionaryInfoOf(params.charuco_dictionary).name);
  if (!dictionary.ok()) return dictionary.status();
  const std::optional<ArucoDictionary> known = ArucoDictionaryFromName(*dictionary);
  if (!known) return f.Error("dictionary", "unknown ArUco dictionary '" + *dictionary + "'");
  params.charuco_dictionary = *known;
  if (absl::Status s = ReadAprilGrid(f, &params); !s.ok()) return s;
  BoardParamsError error = BoardParamsError::kOk;
  std::optional<Board> board = Board::Create(params, &error);
  if (!board) return f.Error(KeyOfBoardError(error), BoardParamsErrorName(error));
  absl::StatusOr<Rigid3d> pose = ReadPose(f, "pose", BoardBaseRotation());
  if (!pose.ok()) return pose.status();
  absl::StatusOr<bool> allow_partial = f.BoolOr("allow_partial", false);
  if (!allow_partial.ok()) return allow_partial.status();
  if (*allow_partial && !BoardAllowsPartial(params.type)) {
    return f.Error("allow_partial",
                   absl::StrCat("a '", *type,
                                "' board has no ids, so a partial view of it cannot be placed; "
                                "only vertical, aruco, apriltag, round_hole and charuco boards "
                                "allow partial views"));
  }
  return StationBoard{*id, params, std::move(*board), *pose, *allow_partial};
}

absl::StatusOr<CornerReflector> ReadReflector(const JsonField& f) {
  if (auto s = f.AllowOnlyKeys({"id", "xyz_m", "rcs_dbsm"}); !s.ok()) return s;
  CornerReflector r;
  absl::StatusOr<std::string> id = f.String("id");
  if (!id.ok()) return id.status();
  r.id = *id;
  absl::StatusOr<std::vector<double>> xyz = f.Numbers("xyz_m", 3);
  if (!xyz.ok()) return xyz.status();
  r.p_station = Eigen::Vector3d((*xyz)[0], (*xyz)[1], (*xyz)[2]);
  absl::StatusOr<double> rcs = f.NumberOr("rcs_dbsm", r.rcs_dbsm);
  if (!rcs.ok()) return rcs.status();
  // Physical trihedral reflectors span roughly -10..50 dBm²; beyond that it is a typo.
  if (*rcs < -20 || *rcs > 60)
    return f.Error("rcs_dbsm", absl::StrCat("must be within -20..60, got ", *rcs));
  r.rcs_dbsm = *rcs;
  return r;
}

absl::StatusOr<StationSurface> ReadSurface(const JsonField& f) {
  if (auto s = f.AllowOnlyKeys({"id", "size_m", "reflectivity", "pose"}); !s.ok()) return s;
  StationSurface w;
  absl::StatusOr<std::string> id = f.String("id");
  if (!id.ok()) return id.status();
  w.id = *id;
  absl::StatusOr<std::vector<double>> size = f.Numbers("size_m", 2);
  if (!size.ok()) return size.status();
  if ((*size)[0] <= 0 || (*size)[1] <= 0) return f.Error("size_m", "sizes must be > 0");
  w.size_m = Eigen::Vector2d((*size)[0], (*size)[1]);
  absl::StatusOr<double> refl = f.NumberOr("reflectivity", w.reflectivity);
  if (!refl.ok()) return refl.status();
  if (*refl < 0 || *refl > 1)
    return f.Error("reflectivity", absl::StrCat("must be within 0..1, got ", *refl));
  w.reflectivity = *refl;
  // A surface is placed like a board: at zero angles it faces the car (its z along -x).
  absl::StatusOr<Rigid3d> pose = ReadPose(f, "pose", BoardBaseRotation());
  if (!pose.ok()) return pose.status();
  w.T_station_surface = *pose;
  return w;
}

template <typename T, typename ReadFn>
absl::Status ReadList(const JsonField& root, const char* key, ReadFn read, std::vector<T>* out,
                      std::set<std::string>* ids) {
  if (!root.Has(key)) return absl::OkStatus();
  absl::StatusOr<std::vector<JsonField>> items = root.Array(key);
  if (!items.ok()) return items.status();
  for (const JsonField& item : *items) {
    absl::StatusOr<T> v = read(item);
    if (!v.ok()) return v.status();
    if (!ids->insert(v->id).second)
      return item.Error("id", absl::StrCat("duplicate id '", v->id, "'"));
    out->push_back(std::move(*v));
  }
  return absl::OkStatus();
}

}  // namespace

bool BoardAllowsPartial(BoardType type) {
  switch (type) {
    case BoardType::kVertical:
    case BoardType::kAruco:
    case BoardType::kApriltag:
    case BoardType::kRoundHole:
    case BoardType::kCharuco:
      return true;
    case BoardType::kChessboard:
    case BoardType::kCircle:
    case BoardType::kChecker:
    case BoardType::kCircleGrid:
    case BoardType::kSquareGrid:
      return false;
  }
  return false;
}

const StationBoard* StationLayout::FindBoard(const std::string& id) const {
  for (const StationBoard& b : boards) {
    if (b.id == id) return &b;
  }
  return nullptr;
}

const CornerReflector* StationLayout::FindReflector(const std::string& id) const {
  for (const CornerReflector& r : reflectors) {
    if (r.id == id) return &r;
  }
  return nullptr;
}

absl::StatusOr<StationLayout> ParseStationLayout(const std::string& text,
                                                 const std::string& source) {
  absl::StatusOr<JsonDocument> doc = JsonDocument::FromText(text, source);
  if (!doc.ok()) return doc.status();
  absl::StatusOr<JsonField> root = doc->Root();
  if (!root.ok()) return root.status();
  if (auto s = root->AllowOnlyKeys(
          {"format", "version", "name", "boards", "reflectors", "floor_reflectivity", "surfaces"});
      !s.ok()) {
    return s;
  }
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
  StationLayout layout;
  absl::StatusOr<std::string> name = root->String("name");
  if (!name.ok()) return name.status();
  layout.name = *name;
  absl::StatusOr<double> floor = root->NumberOr("floor_reflectivity", layout.floor_reflectivity);
  if (!floor.ok()) return floor.status();
  if (*floor < 0 || *floor > 1) return root->Error("floor_reflectivity", "must be within 0..1");
  layout.floor_reflectivity = *floor;
  // Boards, reflectors and surfaces share one id space so that a sensor's targets are unambiguous.
  std::set<std::string> ids;
  if (auto s = ReadList(*root, "boards", ReadBoard, &layout.boards, &ids); !s.ok()) return s;
  if (auto s = ReadList(*root, "reflectors", ReadReflector, &layout.reflectors, &ids); !s.ok())
    return s;
  if (auto s = ReadList(*root, "surfaces", ReadSurface, &layout.surfaces, &ids); !s.ok()) return s;
  return layout;
}

absl::StatusOr<StationLayout> ReadStationLayout(const std::string& path) {
  absl::StatusOr<std::string> text = ReadTextFile(path);
  if (!text.ok()) return text.status();
  return ParseStationLayout(*text, path);
}

nlohmann::json BoardParamsToJson(const BoardParams& p) {
  nlohmann::json j = {{"scale", p.scale}};
  if (p.type == BoardType::kChecker) {
    j["cols"] = p.cols;
    j["rows"] = p.rows;
    j["square_m"] = p.square_m;
  }
  if (p.type == BoardType::kCircleGrid) {
    j["cols"] = p.cols;
    j["rows"] = p.rows;
    j["spacing_m"] = p.spacing_m;
    j["diameter_m"] = p.diameter_m;
    j["asymmetric"] = p.asymmetric;
    j["light_circles"] = p.light_circles;
    j["hexagonal"] = p.hexagonal;
  }
  if (p.type == BoardType::kSquareGrid) {
    j["cols"] = p.cols;
    j["rows"] = p.rows;
    j["square_m"] = p.square_m;
    j["gap_m"] = p.gap_m;
  }
  if (p.type == BoardType::kApriltag) {
    j["border_bits"] = p.apriltag_border_bits;
    j["tag_cols"] = p.apriltag_cols;
    j["tag_rows"] = p.apriltag_rows;
    j["tag_spacing"] = p.apriltag_spacing;
    j["start_id"] = p.apriltag_start_id;
  }
  if (p.type == BoardType::kCharuco) {
    j["cols"] = p.cols;
    j["rows"] = p.rows;
    j["square_m"] = p.square_m;
    j["marker_m"] = p.marker_m;
    j["legacy_pattern"] = p.charuco_legacy;
    j["dictionary"] = ArucoDictionaryInfoOf(p.charuco_dictionary).name;
  }
  return j;
}

nlohmann::json StationLayoutToJson(const StationLayout& layout) {
  nlohmann::json boards = nlohmann::json::array();
  for (const StationBoard& b : layout.boards) {
    nlohmann::json j = {{"id", b.id}, {"type", BoardTypeName(b.params.type)}};
    j.update(BoardParamsToJson(b.params));
    j["pose"] = PoseToJson(b.T_station_board, BoardBaseRotation());
    if (b.allow_partial) j["allow_partial"] = true;
    boards.push_back(std::move(j));
  }
  nlohmann::json reflectors = nlohmann::json::array();
  for (const CornerReflector& r : layout.reflectors) {
    reflectors.push_back({{"id", r.id},
                          {"xyz_m", {r.p_station.x(), r.p_station.y(), r.p_station.z()}},
                          {"rcs_dbsm", r.rcs_dbsm}});
  }
  nlohmann::json surfaces = nlohmann::json::array();
  for (const StationSurface& w : layout.surfaces) {
    surfaces.push_back({{"id", w.id},
                        {"size_m", {w.size_m.x(), w.size_m.y()}},
                        {"reflectivity", w.reflectivity},
                        {"pose", PoseToJson(w.T_station_surface, BoardBaseRotation())}});
  }
  return {{"format", kFormat},   {"version", kVersion},
          {"name", layout.name}, {"floor_reflectivity", layout.floor_reflectivity},
          {"boards", boards},    {"reflectors", reflectors},
          {"surfaces", surfaces}};
}

}  // namespace linecal

#include "tools/linecal/board_options.h"

#include <cmath>
#include <string>
#include <vector>

#include "absl/algorithm/container.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "tools/linecal/target_file.h"

namespace linecal::tools {
namespace {

std::string DictionaryNames() {
  std::vector<std::string> names;
  for (const ArucoDictionaryInfo& d : AllArucoDictionaries()) names.emplace_back(d.name);
  return absl::StrJoin(names, ", ");
}

std::string BoardNames() {
  std::vector<std::string> names;
  for (BoardType t : kAllBoardTypes) names.emplace_back(BoardTypeName(t));
  return absl::StrJoin(names, ", ");
}

// The option of the field a BoardParamsError is about.
const char* OptionOf(BoardParamsError e) {
  switch (e) {
    case BoardParamsError::kOk:
    case BoardParamsError::kBadScale:
      return "scale";
    case BoardParamsError::kBadCols:
      return "cols";
    case BoardParamsError::kBadRows:
      return "rows";
    case BoardParamsError::kBadSquare:
      return "square";
    case BoardParamsError::kBadBorderBits:
      return "border-bits";
    case BoardParamsError::kBadSpacing:
      return "spacing";
    case BoardParamsError::kBadDiameter:
      return "diameter";
    case BoardParamsError::kBadTagGrid:
      return "tag-cols";
    case BoardParamsError::kBadTagSpacing:
      return "tag-spacing";
    case BoardParamsError::kBadStartId:
      return "start-id";
    case BoardParamsError::kBadLayout:
      return "hexagonal";
    case BoardParamsError::kBadGap:
      return "gap";
    case BoardParamsError::kBadMarker:
      return "marker";
    case BoardParamsError::kBadMarkerCount:
      return "dictionary";
  }
  return "board";
}

// The fewest columns and rows of p's layout.
int MinSide(const BoardParams& p) { return p.hexagonal ? kMinHexagonalSide : kMinCheckerCorners; }

// --tag-cols, --tag-rows, --tag-spacing, --start-id into *p (their defaults: p's).
absl::Status AprilGridFromCommandLine(const cli::CommandLine& cl, BoardParams* p) {
  absl::StatusOr<int> cols = cl.GetInt("tag-cols", p->apriltag_cols);
  if (!cols.ok()) return cols.status();
  absl::StatusOr<int> rows = cl.GetInt("tag-rows", p->apriltag_rows);
  if (!rows.ok()) return rows.status();
  absl::StatusOr<double> spacing = cl.GetDouble("tag-spacing", p->apriltag_spacing);
  if (!spacing.ok()) return spacing.status();
  absl::StatusOr<int> start = cl.GetInt("start-id", p->apriltag_start_id);
  if (!start.ok()) return start.status();
  p->apriltag_cols = *cols;
  p->apriltag_rows = *rows;
  p->apriltag_spacing = *spacing;
  p->apriltag_start_id = *start;
  return absl::OkStatus();
}

// --target FILE: the file gives the board; only what Kalibr's file cannot say (a circle grid's
// diameter and polarity) may be added.
absl::StatusOr<BoardParams> BoardFromTargetFile(const cli::CommandLine& cl) {
  for (const char* option : {"board", "scale", "cols", "rows", "square", "gap", "spacing",
                             "asymmetric", "tag-cols", "tag-rows", "tag-spacing", "start-id",
                             "hexagonal", "marker", "legacy-pattern", "dictionary"}) {
    if (cl.Has(option)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--", option, " cannot be combined with --target (the file gives the board)"));
    }
  }
  absl::StatusOr<BoardParams> p = ReadKalibrTarget(cl.Get("target", ""));
  if (!p.ok()) return p.status();
  const std::pair<const char*, BoardType> additions[] = {{"diameter", BoardType::kCircleGrid},
                                                         {"light-circles", BoardType::kCircleGrid},
                                                         {"border-bits", BoardType::kApriltag}};
  for (const auto& [option, type] : additions) {
    if (cl.Has(option) && p->type != type) {
      return absl::InvalidArgumentError(
          absl::StrCat("--", option, " applies to a ", BoardTypeName(type), " only; ",
                       cl.Get("target", ""), " describes a ", BoardTypeName(p->type)));
    }
  }
  absl::StatusOr<int> border_bits = cl.GetInt("border-bits", p->apriltag_border_bits);
  if (!border_bits.ok()) return border_bits.status();
  p->apriltag_border_bits = *border_bits;
  absl::StatusOr<double> diameter = cl.GetDouble("diameter", p->diameter_m);
  if (!diameter.ok()) return diameter.status();
  p->diameter_m = *diameter;
  p->light_circles = p->light_circles || cl.Has("light-circles");
  const BoardParamsError e = ValidateBoardParams(*p);
  if (e == BoardParamsError::kOk) return p;
  return absl::InvalidArgumentError(
      absl::StrCat("--", OptionOf(e), ": ", DescribeParamsError(e, *p)));
}

}  // namespace

std::string DescribeParamsError(BoardParamsError e, const BoardParams& p) {
  switch (e) {
    case BoardParamsError::kOk:
      return "valid";
    case BoardParamsError::kBadScale:
      return absl::StrCat(p.scale, " is outside [", kMinBoardScale, ", ", kMaxBoardScale, "]");
    case BoardParamsError::kBadCols:
      return absl::StrCat(p.cols, " is outside [", MinSide(p), ", ", kMaxCheckerCorners, "]");
    case BoardParamsError::kBadRows:
      return absl::StrCat(p.rows, " is outside [", MinSide(p), ", ", kMaxCheckerCorners, "]");
    case BoardParamsError::kBadSquare:
      return absl::StrCat(p.square_m, " m is outside (0, ", kMaxCheckerSquareM, "]");
    case BoardParamsError::kBadBorderBits:
      return absl::StrCat(p.apriltag_border_bits, " is neither 1 nor 2");
    case BoardParamsError::kBadSpacing:
      return absl::StrCat(p.spacing_m, " m is outside (0, ", kMaxCircleSpacingM, "]");
    case BoardParamsError::kBadDiameter:
      return absl::StrCat(p.diameter_m, " m must be > 0 and below the nearest circles' distance (",
                          p.asymmetric ? "spacing * sqrt(2)" : "the spacing", ", ",
                          p.asymmetric ? p.spacing_m * std::sqrt(2.0) : p.spacing_m, " m)");
    case BoardParamsError::kBadTagGrid:
      return absl::StrCat(p.apriltag_cols, " x ", p.apriltag_rows, " tags: each in [1, ",
                          kMaxAprilGridTags, "], two tags at least");
    case BoardParamsError::kBadTagSpacing:
      return absl::StrCat(p.apriltag_spacing, " is outside [", kMinAprilGridSpacing, ", ",
                          kMaxAprilGridSpacing, "]");
    case BoardParamsError::kBadStartId:
      return absl::StrCat(p.apriltag_start_id, ": ids ", p.apriltag_start_id, "..",
                          p.apriltag_start_id + p.apriltag_cols * p.apriltag_rows - 1,
                          " must lie in tag36h11's 0..", kTag36h11Codes - 1);
    case BoardParamsError::kBadLayout:
      return "a grid is hexagonal or asymmetric, not both";
    case BoardParamsError::kBadGap:
      return absl::StrCat(p.gap_m, " m is outside (0, ", kMaxSquareGridGapM, "]");
    case BoardParamsError::kBadMarker:
      return absl::StrCat(p.marker_m, " m must be > 0 and below the square (", p.square_m, " m)");
    case BoardParamsError::kBadMarkerCount:
      return absl::StrCat(ArucoDictionaryInfoOf(p.charuco_dictionary).name, " has ",
                          ArucoDictionaryInfoOf(p.charuco_dictionary).marker_count(), " markers; ",
                          p.cols, " x ", p.rows, " squares hold ", CharucoMarkerCount(p));
  }
  return "invalid";
}

std::vector<cli::OptionSpec> BoardOptionSpecs() {
  return {
      {"board", "NAME", "board type: " + BoardNames() + " (this or --target)"},
      {"target", "FILE", "the board from a Kalibr target YAML file (this or --board)"},
      {"scale", "S", "print scale of the board (default 1: 1 PDF unit = 1 mm)"},
      {"cols", "N",
       "checker: inner corners along x; circle_grid: circles per row; square_grid: squares per "
       "row; charuco: squares along x (default 9)"},
      {"rows", "M",
       "checker: inner corners along y; circle_grid: rows of circles; square_grid: rows of "
       "squares; charuco: squares along y (default 6)"},
      {"square", "METRES",
       "checker, square_grid and charuco: square side in metres (default 0.025)"},
      {"gap", "METRES", "square_grid only: white gap between squares in metres (default 0.025)"},
      {"marker", "METRES",
       "charuco only: marker side in metres, OpenCV's markerLength (default 0.01875)"},
      {"dictionary", "NAME",
       "charuco only: OpenCV's ArUco dictionary of the markers, e.g. DICT_5X5_100 (default "
       "DICT_4X4_50)"},
      {"legacy-pattern", "",
       "charuco only: OpenCV's legacy pattern (boards made before 4.6: with an even row count "
       "the top-left square is white)"},
      {"spacing", "METRES",
       "circle_grid only: centre distance in metres, OpenCV's squareSize (default 0.025)"},
      {"diameter", "METRES", "circle_grid only: circle diameter in metres (default 0.0125)"},
      {"asymmetric", "", "circle_grid only: OpenCV's asymmetric grid (default symmetric)"},
      {"light-circles", "", "circle_grid only: white circles on black (default black on white)"},
      {"border-bits", "B", "apriltag only: black tag border, 2 (Kalibr, default) or 1"},
      {"tag-cols", "N", "apriltag only: tags per row (default 6)"},
      {"tag-rows", "M", "apriltag only: tags per column (default 6)"},
      {"tag-spacing", "R", "apriltag only: gap between tags / tag side (default 0.3)"},
      {"start-id", "K", "apriltag only: tag36h11 id of the bottom-left tag (default 0)"},
      {"hexagonal", "",
       "circle_grid only: BoofCV's hexagonal grid; --cols/--rows are its zig-zag columns and "
       "rows, --spacing the distance of neighbours"},
  };
}

absl::StatusOr<BoardParams> BoardParamsFromCommandLine(const cli::CommandLine& cl) {
  if (cl.Has("target")) return BoardFromTargetFile(cl);
  if (!cl.Has("board")) return absl::InvalidArgumentError("--board or --target is required");
  BoardParams p;
  const std::string name = cl.Get("board", BoardTypeName(p.type));
  const std::optional<BoardType> type = BoardTypeFromName(name);
  if (!type.has_value()) {
    return absl::InvalidArgumentError(
        absl::StrCat("--board: unknown board '", name, "' (one of ", BoardNames(), ")"));
  }
  p.type = *type;
  // Each option and the boards it applies to.
  struct Applies {
    const char* option;
    std::vector<BoardType> types;
  };
  const Applies applies[] = {
      {"cols",
       {BoardType::kChecker, BoardType::kCircleGrid, BoardType::kSquareGrid, BoardType::kCharuco}},
      {"rows",
       {BoardType::kChecker, BoardType::kCircleGrid, BoardType::kSquareGrid, BoardType::kCharuco}},
      {"square", {BoardType::kChecker, BoardType::kSquareGrid, BoardType::kCharuco}},
      {"gap", {BoardType::kSquareGrid}},
      {"marker", {BoardType::kCharuco}},
      {"legacy-pattern", {BoardType::kCharuco}},
      {"dictionary", {BoardType::kCharuco}},
      {"spacing", {BoardType::kCircleGrid}},
      {"diameter", {BoardType::kCircleGrid}},
      {"asymmetric", {BoardType::kCircleGrid}},
      {"light-circles", {BoardType::kCircleGrid}},
      {"border-bits", {BoardType::kApriltag}},
      {"tag-cols", {BoardType::kApriltag}},
      {"tag-rows", {BoardType::kApriltag}},
      {"tag-spacing", {BoardType::kApriltag}},
      {"start-id", {BoardType::kApriltag}},
      {"hexagonal", {BoardType::kCircleGrid}},
  };
  for (const Applies& a : applies) {
    if (!cl.Has(a.option) || absl::c_linear_search(a.types, p.type)) continue;
    std::vector<std::string> names;
    for (BoardType t : a.types) names.emplace_back(BoardTypeName(t));
    return absl::InvalidArgumentError(absl::StrCat(
        "--", a.option, " applies to --board ", absl::StrJoin(names, " or "), " only, not ", name));
  }
  absl::StatusOr<double> scale = cl.GetDouble("scale", p.scale);
  if (!scale.ok()) return scale.status();
  absl::StatusOr<int> cols = cl.GetInt("cols", p.cols);
  if (!cols.ok()) return cols.status();
  absl::StatusOr<int> rows = cl.GetInt("rows", p.rows);
  if (!rows.ok()) return rows.status();
  absl::StatusOr<double> square = cl.GetDouble("square", p.square_m);
  if (!square.ok()) return square.status();
  absl::StatusOr<double> gap = cl.GetDouble("gap", p.gap_m);
  if (!gap.ok()) return gap.status();
  absl::StatusOr<double> spacing = cl.GetDouble("spacing", p.spacing_m);
  if (!spacing.ok()) return spacing.status();
  absl::StatusOr<double> diameter = cl.GetDouble("diameter", p.diameter_m);
  if (!diameter.ok()) return diameter.status();
  absl::StatusOr<int> border_bits = cl.GetInt("border-bits", p.apriltag_border_bits);
  if (!border_bits.ok()) return border_bits.status();
  absl::StatusOr<double> marker = cl.GetDouble("marker", p.marker_m);
  if (!marker.ok()) return marker.status();
  if (absl::Status s = AprilGridFromCommandLine(cl, &p); !s.ok()) return s;
  if (cl.Has("dictionary")) {
    const std::string dictionary = cl.Get("dictionary", "");
    const std::optional<ArucoDictionary> d = ArucoDictionaryFromName(dictionary);
    if (!d.has_value()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--dictionary: unknown dictionary '", dictionary, "' (one of ", DictionaryNames(), ")"));
    }
    p.charuco_dictionary = *d;
  }
  p.scale = *scale;
  p.cols = *cols;
  p.rows = *rows;
  p.square_m = *square;
  p.gap_m = *gap;
  p.spacing_m = *spacing;
  p.diameter_m = *diameter;
  p.asymmetric = cl.Has("asymmetric");
  p.light_circles = cl.Has("light-circles");
  p.hexagonal = cl.Has("hexagonal");
  p.apriltag_border_bits = *border_bits;
  p.marker_m = *marker;
  p.charuco_legacy = cl.Has("legacy-pattern");

  const BoardParamsError e = ValidateBoardParams(p);
  if (e == BoardParamsError::kOk) return p;
  return absl::InvalidArgumentError(
      absl::StrCat("--", OptionOf(e), ": ", DescribeParamsError(e, p)));
}

}  // namespace linecal::tools

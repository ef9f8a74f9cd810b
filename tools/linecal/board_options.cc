#include "tools/linecal/board_options.h"

#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"

namespace linecal::tools {
namespace {

std::string BoardNames() {
  std::vector<std::string> names;
  for (BoardType t : kAllBoardTypes) names.emplace_back(BoardTypeName(t));
  return absl::StrJoin(names, ", ");
}

}  // namespace

std::vector<cli::OptionSpec> BoardOptionSpecs(bool board_required) {
  return {
      {"board", "NAME", "board type: " + BoardNames(), board_required},
      {"scale", "S", "print scale of the board (default 1: 1 PDF unit = 1 mm)"},
      {"cols", "N", "checker only: inner corners along x (default 9)"},
      {"rows", "M", "checker only: inner corners along y (default 6)"},
      {"square", "METRES", "checker only: square side in metres (default 0.025)"},
      {"border-bits", "B", "apriltag only: black tag border, 2 (Kalibr, default) or 1"},
  };
}

absl::StatusOr<BoardParams> BoardParamsFromCommandLine(const cli::CommandLine& cl) {
  BoardParams p;
  const std::string name = cl.Get("board", BoardTypeName(p.type));
  const std::optional<BoardType> type = BoardTypeFromName(name);
  if (!type.has_value()) {
    return absl::InvalidArgumentError(
        absl::StrCat("--board: unknown board '", name, "' (one of ", BoardNames(), ")"));
  }
  p.type = *type;
  if (p.type != BoardType::kChecker) {
    for (const char* option : {"cols", "rows", "square"}) {
      if (cl.Has(option)) {
        return absl::InvalidArgumentError(
            absl::StrCat("--", option, " applies to --board checker only, not ", name));
      }
    }
  }
  if (p.type != BoardType::kApriltag && cl.Has("border-bits")) {
    return absl::InvalidArgumentError(
        absl::StrCat("--border-bits applies to --board apriltag only, not ", name));
  }
  absl::StatusOr<double> scale = cl.GetDouble("scale", p.scale);
  if (!scale.ok()) return scale.status();
  absl::StatusOr<int> cols = cl.GetInt("cols", p.cols);
  if (!cols.ok()) return cols.status();
  absl::StatusOr<int> rows = cl.GetInt("rows", p.rows);
  if (!rows.ok()) return rows.status();
  absl::StatusOr<double> square = cl.GetDouble("square", p.square_m);
  if (!square.ok()) return square.status();
  absl::StatusOr<int> border_bits = cl.GetInt("border-bits", p.apriltag_border_bits);
  if (!border_bits.ok()) return border_bits.status();
  p.scale = *scale;
  p.cols = *cols;
  p.rows = *rows;
  p.square_m = *square;
  p.apriltag_border_bits = *border_bits;

  switch (ValidateBoardParams(p)) {
    case BoardParamsError::kOk:
      return p;
    case BoardParamsError::kBadScale:
      return absl::InvalidArgumentError(absl::StrCat("--scale: ", p.scale, " is outside [",
                                                     kMinBoardScale, ", ", kMaxBoardScale, "]"));
    case BoardParamsError::kBadCols:
      return absl::InvalidArgumentError(absl::StrCat(
          "--cols: ", p.cols, " is outside [", kMinCheckerCorners, ", ", kMaxCheckerCorners, "]"));
    case BoardParamsError::kBadRows:
      return absl::InvalidArgumentError(absl::StrCat(
          "--rows: ", p.rows, " is outside [", kMinCheckerCorners, ", ", kMaxCheckerCorners, "]"));
    case BoardParamsError::kBadSquare:
      return absl::InvalidArgumentError(
          absl::StrCat("--square: ", p.square_m, " m is outside (0, ", kMaxCheckerSquareM, "]"));
    case BoardParamsError::kBadBorderBits:
      return absl::InvalidArgumentError(
          absl::StrCat("--border-bits: ", p.apriltag_border_bits, " is neither 1 nor 2"));
  }
  return absl::InvalidArgumentError("bad board options");
}

}  // namespace linecal::tools

#include "tools/linecal/target_file.h"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>
#include <optional>

#include "absl/strings/str_cat.h"
#include "tools/linecal/board_options.h"

namespace linecal::tools {
namespace {

// linecal's AprilGrid tag at scale 1 (docs/boards.md §5): other tag sizes are scales of it.
constexpr double kAprilGridTagM = 0.088;

// One file's keys, each read with an error that names the file and the key.
class TargetYaml {
 public:
  TargetYaml(std::string path, YAML::Node root) : path_(std::move(path)), root_(root) {}

  absl::Status Error(const std::string& key, const std::string& what) const {
    return absl::InvalidArgumentError(absl::StrCat(path_, ": ", key, ": ", what));
  }

  template <typename T>
  absl::StatusOr<T> Get(const std::string& key, std::optional<T> fallback = std::nullopt) const {
    const YAML::Node node = root_[key];
    if (!node) {
      if (fallback.has_value()) return *fallback;
      return Error(key, "missing");
    }
    try {
      const T value = node.as<T>();
      if constexpr (std::is_floating_point_v<T>) {
        if (!std::isfinite(value)) return Error(key, "not a finite number");
      }
      return value;
    } catch (const YAML::Exception&) {
      return Error(key, absl::StrCat("'", node.Scalar().substr(0, 32), "' is not a ",
                                     std::is_same_v<T, bool> ? "boolean"
                                     : std::is_integral_v<T> ? "whole number"
                                                             : "number"));
    }
  }

 private:
  std::string path_;
  YAML::Node root_;
};

// Reads the sizes every grid has; `cols_key`, `rows_key` are the type's names for them.
absl::Status ReadSize(const TargetYaml& y, const char* cols_key, const char* rows_key,
                      BoardParams* p) {
  absl::StatusOr<int> cols = y.Get<int>(cols_key);
  if (!cols.ok()) return cols.status();
  absl::StatusOr<int> rows = y.Get<int>(rows_key);
  if (!rows.ok()) return rows.status();
  p->cols = *cols;
  p->rows = *rows;
  return absl::OkStatus();
}

absl::StatusOr<BoardParams> Checkerboard(const TargetYaml& y) {
  BoardParams p;
  p.type = BoardType::kChecker;
  if (absl::Status s = ReadSize(y, "targetCols", "targetRows", &p); !s.ok()) return s;
  absl::StatusOr<double> row = y.Get<double>("rowSpacingMeters");
  if (!row.ok()) return row.status();
  absl::StatusOr<double> col = y.Get<double>("colSpacingMeters");
  if (!col.ok()) return col.status();
  // A checker of oblong squares has no use on a station; a typo in one of them is likelier.
  if (std::abs(*row - *col) > 1e-9 * std::max(std::abs(*row), std::abs(*col))) {
    return y.Error("colSpacingMeters", absl::StrCat(*col, " differs from rowSpacingMeters ", *row,
                                                    ": linecal's checker has square "
                                                    "squares"));
  }
  p.square_m = *row;
  return p;
}

absl::StatusOr<BoardParams> CircleGrid(const TargetYaml& y) {
  BoardParams p;
  p.type = BoardType::kCircleGrid;
  if (absl::Status s = ReadSize(y, "targetCols", "targetRows", &p); !s.ok()) return s;
  absl::StatusOr<double> spacing = y.Get<double>("spacingMeters");
  if (!spacing.ok()) return spacing.status();
  absl::StatusOr<bool> asymmetric = y.Get<bool>("asymmetricGrid", false);
  if (!asymmetric.ok()) return asymmetric.status();
  p.spacing_m = *spacing;
  p.diameter_m = 0.5 * *spacing;
  p.asymmetric = *asymmetric;
  return p;
}

absl::StatusOr<BoardParams> AprilGrid(const TargetYaml& y) {
  BoardParams p;
  p.type = BoardType::kApriltag;
  BoardParams size;
  if (absl::Status s = ReadSize(y, "tagCols", "tagRows", &size); !s.ok()) return s;
  absl::StatusOr<double> tag = y.Get<double>("tagSize");
  if (!tag.ok()) return tag.status();
  absl::StatusOr<double> spacing = y.Get<double>("tagSpacing");
  if (!spacing.ok()) return spacing.status();
  // Kalibr numbers the tags from 0; its newer files may say where they start.
  absl::StatusOr<int> start = y.Get<int>("tagStartId", 0);
  if (!start.ok()) return start.status();
  p.apriltag_cols = size.cols;
  p.apriltag_rows = size.rows;
  p.apriltag_spacing = *spacing;
  p.apriltag_start_id = *start;
  p.scale = *tag / kAprilGridTagM;
  return p;
}

// The file's key for a field ValidateBoardParams refused (the scale has its own message).
const char* KeyOf(BoardParamsError e) {
  switch (e) {
    case BoardParamsError::kBadCols:
      return "targetCols";
    case BoardParamsError::kBadRows:
      return "targetRows";
    case BoardParamsError::kBadSquare:
      return "rowSpacingMeters";
    case BoardParamsError::kBadTagGrid:
      return "tagCols";
    case BoardParamsError::kBadTagSpacing:
      return "tagSpacing";
    case BoardParamsError::kBadStartId:
      return "tagStartId";
    default:
      return "spacingMeters";
  }
}

}  // namespace

absl::StatusOr<BoardParams> ReadKalibrTarget(const std::string& path) {
  if (!std::filesystem::is_regular_file(path)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": no such file"));
  }
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::Exception& e) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": not YAML (line ", e.mark.line + 1, ": ", e.msg, ")"));
  }
  if (!root.IsMap()) return absl::InvalidArgumentError(absl::StrCat(path, ": not a YAML map"));
  const TargetYaml y(path, root);
  absl::StatusOr<std::string> type = y.Get<std::string>("target_type");
  if (!type.ok()) return type.status();
  absl::StatusOr<BoardParams> p =
      *type == "checkerboard" ? Checkerboard(y)
      : *type == "circlegrid" ? CircleGrid(y)
      : *type == "aprilgrid"
          ? AprilGrid(y)
          : absl::StatusOr<BoardParams>(y.Error(
                "target_type", absl::StrCat("'", type->substr(0, 32),
                                            "' is not checkerboard, circlegrid or aprilgrid")));
  if (!p.ok()) return p;
  const BoardParamsError e = ValidateBoardParams(*p);
  if (e == BoardParamsError::kOk) return p;
  if (e == BoardParamsError::kBadScale) {
    return y.Error("tagSize", absl::StrCat(p->scale * kAprilGridTagM, " m is outside [",
                                           kMinBoardScale * kAprilGridTagM, ", ",
                                           kMaxBoardScale * kAprilGridTagM, "] m"));
  }
  return y.Error(KeyOf(e), DescribeParamsError(e, *p));
}

}  // namespace linecal::tools

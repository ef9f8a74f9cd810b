// linecal boards: the board types the station knows, with their default parameters, page
// size and features (docs/boards.md, docs/boards.md).
#include <cstdio>
#include <map>
#include <nlohmann/json.hpp>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "detectors/boards/board.h"
#include "station/model/station_layout.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "boards";

const char* Description(BoardType type) {
  switch (type) {
    case BoardType::kChessboard:
      return "wide board, two groups of three squares (yaw, vanishing point)";
    case BoardType::kCircle:
      return "30 circles on black, a black pair on a white bar";
    case BoardType::kVertical:
      return "upright coded column of cells (roll, ground distances)";
    case BoardType::kAruco:
      return "four DICT_4X4_50 markers, ids 4, 11, 12, 19";
    case BoardType::kApriltag:
      return "tag36h11 AprilGrid: 6 x 6 tags, ids 0..35, on A0 (or any Kalibr AprilGrid)";
    case BoardType::kRoundHole:
      return "five through holes (LiDAR) and four ArUco markers";
    case BoardType::kChecker:
      return "generic chessboard, cols x rows inner corners";
    case BoardType::kCircleGrid:
      return "circle grid: OpenCV's symmetric or asymmetric (cols x rows), BoofCV's hexagonal";
    case BoardType::kSquareGrid:
      return "BoofCV square grid, cols x rows black squares apart by white gaps";
    case BoardType::kCharuco:
      return "OpenCV ChArUco, cols x rows squares, DICT_4X4_50 markers in the white ones";
  }
  return "";
}

}  // namespace

int RunBoards(const Args& args) {
  cli::CommandLine cl("linecal boards [--json]",
                      "Lists the calibration boards: name, default parameters, page size and "
                      "feature count (ids and layouts: docs/boards.md).",
                      {{"json", "", "print one JSON object {\"boards\": [...]}"}});
  if (const std::optional<int> exit = cli::ParseOrExit(cl, kCommand, args)) return *exit;

  nlohmann::json boards = nlohmann::json::array();
  std::string text = absl::StrFormat("%-11s %-17s %8s  %-40s %s\n", "board", "page (mm)",
                                     "features", "parameters", "description");
  for (BoardType type : kAllBoardTypes) {
    BoardParams params;
    params.type = type;
    const std::optional<Board> board = Board::Create(params);
    if (!board.has_value()) return cli::BadInput(kCommand, "default parameters are invalid");
    std::map<std::string, int> kinds;
    for (const BoardFeature& f : board->features()) ++kinds[FeatureKindName(f.kind)];
    const nlohmann::json parameters = BoardParamsToJson(params);
    boards.push_back({{"name", board->name()},
                      {"description", Description(type)},
                      {"page_width_m", board->page_size_m().x()},
                      {"page_height_m", board->page_size_m().y()},
                      {"feature_count", board->features().size()},
                      {"feature_kinds", kinds},
                      {"parameters", parameters}});
    std::vector<std::string> kv;
    for (const auto& [key, value] : parameters.items()) kv.push_back(key + "=" + value.dump());
    absl::StrAppend(
        &text,
        absl::StrFormat("%-11s %-17s %8d  %-40s %s\n", board->name(),
                        absl::StrFormat("%.0f x %.0f", 1e3 * board->page_size_m().x(),
                                        1e3 * board->page_size_m().y()),
                        board->features().size(), absl::StrJoin(kv, " "), Description(type)));
  }
  if (cl.Has("json")) {
    std::printf("%s\n", nlohmann::json{{"boards", boards}}.dump().c_str());
  } else {
    std::fputs(text.c_str(), stdout);
  }
  return cli::kExitOk;
}

}  // namespace linecal::tools

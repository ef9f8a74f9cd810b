// linecal pattern: a true-scale printable drawing of a board, as SVG (millimetres) or PNG
// (at a resolution in dots per inch, with the pHYs chunk set).
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "station/io/board_raster.h"
#include "station/io/image_io.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/board_options.h"
#include "tools/linecal/commands.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "pattern";
constexpr double kMetresPerInch = 0.0254;
// 150 dpi keeps the widest default board (the 2.6 m chessboard) under kMaxImageSide pixels
// and is plenty for squares of centimetres.
constexpr double kDefaultDpi = 150.0;
// A 16x16 sub-pixel grid makes every edge pixel's grey level exact to 1/256.
constexpr int kSupersample = 16;

}  // namespace

int RunPattern(const Args& args) {
  std::vector<cli::OptionSpec> options = BoardOptionSpecs();
  options.push_back({"out", "FILE", "output file, .svg (true size in mm) or .png", true});
  options.push_back({"dpi", "N", "PNG only: dots per inch (default 150)"});
  options.push_back({"json", "", "print what was written as one JSON object"});
  cli::CommandLine cl(
      "linecal pattern --board NAME [--scale S] [--cols N --rows M] [--square METRES] "
      "[--gap METRES] [--spacing METRES --diameter METRES] [--asymmetric | --hexagonal] "
      "[--light-circles] [--border-bits 1|2] [--marker METRES] [--legacy-pattern] "
      "[--dictionary NAME] --out FILE.svg|FILE.png [--dpi N] [--json]",
      "Writes a printable drawing of a board at true size: SVG with its size in millimetres, "
      "or PNG at --dpi with the physical resolution recorded in the file. Print at 100% "
      "(no fit to page).",
      std::move(options));
  if (const std::optional<int> exit = cli::ParseOrExit(cl, kCommand, args)) return *exit;

  const absl::StatusOr<BoardParams> params = BoardParamsFromCommandLine(cl);
  if (!params.ok()) return cli::BadInput(kCommand, std::string(params.status().message()));
  const std::optional<Board> board = Board::Create(*params);
  if (!board.has_value()) return cli::BadInput(kCommand, "invalid board parameters");

  const std::string out = cl.Get("out");
  const std::string lower = absl::AsciiStrToLower(out);
  const bool svg = absl::EndsWith(lower, ".svg");
  if (!svg && !absl::EndsWith(lower, ".png")) {
    return cli::BadInput(kCommand, absl::StrCat("--out: '", out, "' must end in .svg or .png"));
  }
  if (svg && cl.Has("dpi")) return cli::BadInput(kCommand, "--dpi applies to .png output only");
  const absl::StatusOr<double> dpi = cl.GetDouble("dpi", kDefaultDpi);
  if (!dpi.ok()) return cli::BadInput(kCommand, std::string(dpi.status().message()));
  if (*dpi <= 0) return cli::BadInput(kCommand, absl::StrCat("--dpi: ", *dpi, " must be > 0"));

  nlohmann::json report = {{"board", board->name()},
                           {"scale", board->params().scale},
                           {"out", out},
                           {"page_width_m", board->page_size_m().x()},
                           {"page_height_m", board->page_size_m().y()}};
  std::string summary;
  if (svg) {
    if (const absl::Status s = WriteBoardSvg(*board, out); !s.ok()) {
      return cli::BadInput(kCommand, std::string(s.message()));
    }
    report["format"] = "svg";
    summary =
        absl::StrCat("wrote ", out, ": ", board->name(), " board, ", 1e3 * board->page_size_m().x(),
                     " x ", 1e3 * board->page_size_m().y(), " mm (SVG)");
  } else {
    const double longest_m = board->page_size_m().maxCoeff();
    if (std::round(longest_m * *dpi / kMetresPerInch) > kMaxImageSide) {
      return cli::BadInput(
          kCommand,
          absl::StrCat("--dpi ", *dpi, ": the ", board->name(), " page (", 1e3 * longest_m,
                       " mm) would be over ", kMaxImageSide, " pixels; use --dpi ",
                       std::floor(kMaxImageSide / longest_m * kMetresPerInch),
                       " or less, or an SVG"));
    }
    BoardRasterOptions raster;
    raster.pixels_per_metre = *dpi / kMetresPerInch;
    raster.supersample = kSupersample;
    const absl::StatusOr<Image8> image = RasterizeBoard(*board, raster);
    if (!image.ok()) {
      return cli::BadInput(kCommand, absl::StrCat("--dpi ", *dpi, ": ", image.status().message()));
    }
    if (const absl::Status s =
            WritePng8(out, image->view(), PngWriteOptions{raster.pixels_per_metre});
        !s.ok()) {
      return cli::BadInput(kCommand, std::string(s.message()));
    }
    report["format"] = "png";
    report["dpi"] = *dpi;
    report["width_px"] = image->width;
    report["height_px"] = image->height;
    summary =
        absl::StrCat("wrote ", out, ": ", board->name(), " board, ", 1e3 * board->page_size_m().x(),
                     " x ", 1e3 * board->page_size_m().y(), " mm, ", image->width, " x ",
                     image->height, " px at ", *dpi, " dpi (PNG)");
  }
  if (cl.Has("json")) {
    std::printf("%s\n", report.dump().c_str());
  } else {
    std::printf("%s\n", summary.c_str());
  }
  return cli::kExitOk;
}

}  // namespace linecal::tools

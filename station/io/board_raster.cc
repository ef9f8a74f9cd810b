#include "station/io/board_raster.h"

#include <cmath>
#include <cstdio>
#include <fstream>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace linecal {
namespace {

// Sub-sampling beyond 16 x 16 changes a grey level by less than one step in 256.
constexpr int kMaxSupersample = 16;

std::uint8_t Grey(Paint paint, const BoardRasterOptions& o) {
  switch (paint) {
    case Paint::kBlack:
      return o.black;
    case Paint::kHole:
      return o.hole;
    case Paint::kWhite:
    case Paint::kOffBoard:  // the last pixel row/column may reach past the page: page colour
      return o.white;
  }
  return o.white;
}

// Millimetres for SVG: 4 decimals (0.1 um, far below any printer) without trailing zeros.
std::string Mm(double mm) {
  std::string s = absl::StrFormat("%.4f", mm);
  while (!s.empty() && s.back() == '0') s.pop_back();
  if (!s.empty() && s.back() == '.') s.pop_back();
  return s == "-0" ? "0" : s;
}

}  // namespace

absl::StatusOr<Image8> RasterizeBoard(const Board& board, const BoardRasterOptions& options) {
  const double ppm = options.pixels_per_metre;
  if (!std::isfinite(ppm) || ppm <= 0) {
    return absl::InvalidArgumentError(absl::StrCat("bad raster resolution: ", ppm, " px/m"));
  }
  if (options.supersample < 1 || options.supersample > kMaxSupersample) {
    return absl::InvalidArgumentError(
        absl::StrCat("bad supersample: ", options.supersample, " (1..", kMaxSupersample, ")"));
  }
  const Eigen::Vector2d page = board.page_size_m();
  const double w_px = std::round(page.x() * ppm), h_px = std::round(page.y() * ppm);
  if (w_px < 1 || h_px < 1 || w_px > kMaxImageSide || h_px > kMaxImageSide) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s board of %.4g x %.4g m at %.6g px/m is %.0f x %.0f pixels; the largest side is %d "
        "(at most %.6g px/m)",
        board.name(), page.x(), page.y(), ppm, w_px, h_px, kMaxImageSide,
        kMaxImageSide / page.maxCoeff()));
  }
  const int width = static_cast<int>(w_px), height = static_cast<int>(h_px);
  const int n = options.supersample;
  const double pixel = 1.0 / ppm;
  Image8 image(width, height);
  for (int v = 0; v < height; ++v) {
    const double y_top = 0.5 * page.y() - v * pixel;
    for (int u = 0; u < width; ++u) {
      const double x_left = -0.5 * page.x() + u * pixel;
      const std::optional<Paint> uniform = board.UniformPaintIn(
          Eigen::Vector2d(x_left, y_top - pixel), Eigen::Vector2d(x_left + pixel, y_top));
      if (uniform.has_value()) {
        image.at(u, v) = Grey(*uniform, options);
        continue;
      }
      int sum = 0;
      for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
          const Eigen::Vector2d p(x_left + (i + 0.5) * pixel / n, y_top - (j + 0.5) * pixel / n);
          sum += Grey(board.PaintAt(p), options);
        }
      }
      image.at(u, v) = static_cast<std::uint8_t>((sum + n * n / 2) / (n * n));
    }
  }
  return image;
}

std::string BoardSvg(const Board& board) {
  const Eigen::Vector2d page_mm = 1e3 * board.page_size_m();
  // Board metres to SVG millimetres: origin at the page's top-left, y down.
  const auto x_mm = [&](double x_board) { return 1e3 * x_board + 0.5 * page_mm.x(); };
  const auto y_mm = [&](double y_board) { return 0.5 * page_mm.y() - 1e3 * y_board; };

  std::string svg = absl::StrCat(
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n",
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"", Mm(page_mm.x()), "mm\" height=\"",
      Mm(page_mm.y()), "mm\" viewBox=\"0 0 ", Mm(page_mm.x()), " ", Mm(page_mm.y()), "\">\n",
      "<!-- linecal board '", board.name(), "', scale ", board.params().scale, ", ",
      board.features().size(),
      " features. Print at 100% (no fit to page). Board frame: origin at the page centre, "
      "x right, y up. -->\n");
  for (const BoardShape& s : board.shapes()) {
    std::string style;
    switch (s.paint) {
      case Paint::kBlack:
        style = "fill=\"#000000\"";
        break;
      case Paint::kHole:
        // Cut along the dashed line; 0.5 mm is visible without moving the edge much.
        style =
            "fill=\"#ffffff\" stroke=\"#808080\" stroke-width=\"0.5\" "
            "stroke-dasharray=\"3 2\"";
        break;
      case Paint::kWhite:
      case Paint::kOffBoard:
        style = "fill=\"#ffffff\"";
        break;
    }
    if (s.geometry == ShapeGeometry::kCircle) {
      absl::StrAppend(&svg, "<circle cx=\"", Mm(x_mm(s.centre_board().x())), "\" cy=\"",
                      Mm(y_mm(s.centre_board().y())), "\" r=\"", Mm(1e3 * s.radius_m()), "\" ",
                      style, "/>\n");
    } else {
      absl::StrAppend(&svg, "<rect x=\"", Mm(x_mm(s.box_board.min().x())), "\" y=\"",
                      Mm(y_mm(s.box_board.max().y())), "\" width=\"",
                      Mm(1e3 * s.box_board.sizes().x()), "\" height=\"",
                      Mm(1e3 * s.box_board.sizes().y()), "\" ", style, "/>\n");
    }
  }
  absl::StrAppend(&svg, "</svg>\n");
  return svg;
}

absl::Status WriteBoardSvg(const Board& board, const std::string& path) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return absl::InvalidArgumentError(absl::StrCat(path, ": cannot create"));
  out << BoardSvg(board);
  out.close();
  if (!out) {
    std::remove(path.c_str());
    return absl::InternalError(absl::StrCat(path, ": write failed"));
  }
  return absl::OkStatus();
}

}  // namespace linecal

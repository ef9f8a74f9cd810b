#pragma once
// Drawing a board face-on: an anti-aliased grey raster (for printable PNG patterns and for
// comparing with the reference PDFs) and a true-scale SVG (for printing).

#include <cstdint>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"

namespace linecal {

struct BoardRasterOptions {
  // Image resolution on the board, pixels per metre (e.g. dpi / 0.0254).
  double pixels_per_metre = 1000.0;
  // Sub-samples per pixel side where a pixel is not of one paint: the grey level is the
  // mean over supersample^2 point samples (area-correct to 1 / supersample^2).
  int supersample = 4;
  // Grey levels per paint. A through hole prints as the page (the PDFs paint holes white).
  std::uint8_t white = 255;
  std::uint8_t black = 0;
  std::uint8_t hole = 255;
};

// The page of `board` seen face-on: x_board to the right, y_board up. The image is
// round(page width * pixels_per_metre) x round(page height * pixels_per_metre) pixels;
// pixel (u, v) covers board x in [-w/2 + u / ppm, -w/2 + (u + 1) / ppm) and y downwards
// from h/2 likewise. Errors: InvalidArgument for a non-positive resolution or supersample
// outside [1, 16], or an image side over kMaxImageSide (the message gives the largest
// resolution that fits). Cost: one Board::UniformPaintIn per pixel, plus supersample^2
// PaintAt calls on the pixels along edges.
absl::StatusOr<Image8> RasterizeBoard(const Board& board, const BoardRasterOptions& options);

// A standalone SVG document of the board at true size: width and height in millimetres, a
// viewBox in millimetres (y down, origin at the page's top-left), one element per shape in
// painter's order. Through holes are drawn white with a dashed grey cutting line. Cost:
// linear in the number of shapes.
std::string BoardSvg(const Board& board);

// Writes BoardSvg(board) to `path`. Errors: the file cannot be written (path in message).
absl::Status WriteBoardSvg(const Board& board, const std::string& path);

}  // namespace linecal

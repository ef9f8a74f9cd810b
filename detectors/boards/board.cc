#include "detectors/boards/board.h"

#include <apriltag/tag36h11.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <string_view>

#include "detectors/boards/aruco_dict_4x4_50.h"

namespace linecal {
namespace {

// Collects a board's shapes and features. Layouts are written in the units of docs/boards.md,
// millimetres, either in PDF coordinates (origin at the page's top-left, y down) or in
// board-frame millimetres (origin at the page centre, y up); both end up in metres, scaled.
class Drawing {
 public:
  Drawing(double page_w_mm, double page_h_mm, double scale)
      : page_w_mm_(page_w_mm), page_h_mm_(page_h_mm), m_per_mm_(scale * 1e-3) {
    // The page itself: every board is printed on white.
    BoardRect(Paint::kWhite, -0.5 * page_w_mm, -0.5 * page_h_mm, 0.5 * page_w_mm, 0.5 * page_h_mm);
  }

  Eigen::Vector2d page_size_m() const {
    return m_per_mm_ * Eigen::Vector2d(page_w_mm_, page_h_mm_);
  }

  // Board-frame millimetres to board-frame metres.
  Eigen::Vector2d Board(double x_mm, double y_mm) const {
    return Eigen::Vector2d(x_mm * m_per_mm_, y_mm * m_per_mm_);
  }
  // PDF millimetres to board-frame metres: x_board = x_pdf - W/2, y_board = H/2 - y_pdf.
  Eigen::Vector2d Pdf(double x_pdf, double y_pdf) const {
    return Board(x_pdf - 0.5 * page_w_mm_, 0.5 * page_h_mm_ - y_pdf);
  }

  void BoardRect(Paint paint, double min_x_mm, double min_y_mm, double max_x_mm, double max_y_mm) {
    shapes_.push_back(
        BoardShape{ShapeGeometry::kRect, paint,
                   Eigen::AlignedBox2d(Board(min_x_mm, min_y_mm), Board(max_x_mm, max_y_mm))});
  }
  // A rectangle given by its top-left corner in PDF coordinates and its size.
  void PdfRect(Paint paint, double x_pdf, double y_pdf, double w_mm, double h_mm) {
    shapes_.push_back(
        BoardShape{ShapeGeometry::kRect, paint,
                   Eigen::AlignedBox2d(Pdf(x_pdf, y_pdf + h_mm), Pdf(x_pdf + w_mm, y_pdf))});
  }
  void BoardCircle(Paint paint, double cx_mm, double cy_mm, double diameter_mm) {
    const double r = 0.5 * diameter_mm;
    shapes_.push_back(
        BoardShape{ShapeGeometry::kCircle, paint,
                   Eigen::AlignedBox2d(Board(cx_mm - r, cy_mm - r), Board(cx_mm + r, cy_mm + r))});
  }
  void PdfCircle(Paint paint, double cx_pdf, double cy_pdf, double diameter_mm) {
    const double r = 0.5 * diameter_mm;
    shapes_.push_back(
        BoardShape{ShapeGeometry::kCircle, paint,
                   Eigen::AlignedBox2d(Pdf(cx_pdf - r, cy_pdf + r), Pdf(cx_pdf + r, cy_pdf - r))});
  }

  // Appends a feature; ids are given in the order of the calls.
  void Feature(FeatureKind kind, const Eigen::Vector2d& p_board, int marker = -1) {
    features_.push_back(BoardFeature{static_cast<int>(features_.size()), p_board, kind, marker});
  }

  std::vector<BoardShape>& shapes() { return shapes_; }
  std::vector<BoardFeature>& features() { return features_; }

 private:
  double page_w_mm_;
  double page_h_mm_;
  double m_per_mm_;
  std::vector<BoardShape> shapes_;
  std::vector<BoardFeature> features_;
};

// ---- 1. Chessboard (chessboard.pdf, 2600 x 500) -------------------------------------------

void DrawChessboard(Drawing& d) {
  constexpr double kSquare = 150.0;
  // Black squares, top-left corners in PDF coordinates (docs/boards.md, checked against the PDF).
  constexpr double kSquares[6][2] = {{100, 100},  {400, 100},  {250, 250},    // left "V"
                                     {2200, 100}, {2050, 250}, {2350, 250}};  // right "Λ"
  for (const auto& s : kSquares) d.PdfRect(Paint::kBlack, s[0], s[1], kSquare, kSquare);
  // The 10 corners of each group, PDF rows top to bottom, left to right in a row; X marks
  // the two vertices where squares touch diagonally.
  struct Corner {
    double x, y;
    bool x_corner;
  };
  // clang-format off
  constexpr Corner kCorners[20] = {
      // left group: ids 0..9
      {100, 100, false}, {250, 100, false}, {400, 100, false}, {550, 100, false},
      {100, 250, false}, {250, 250, true},  {400, 250, true},  {550, 250, false},
      {250, 400, false}, {400, 400, false},
      // right group: ids 10..19
      {2200, 100, false}, {2350, 100, false},
      {2050, 250, false}, {2200, 250, true},  {2350, 250, true},  {2500, 250, false},
      {2050, 400, false}, {2200, 400, false}, {2350, 400, false}, {2500, 400, false}};
  // clang-format on
  for (const Corner& c : kCorners) {
    d.Feature(c.x_corner ? FeatureKind::kXCorner : FeatureKind::kLCorner, d.Pdf(c.x, c.y));
  }
}

// ---- 2. Circle board (circle_board.pdf, 900 x 600) ----------------------------------------

void DrawCircleBoard(Drawing& d) {
  constexpr double kDiameter = 50.0;
  constexpr double kColumns[6] = {100, 300, 400, 500, 600, 800};
  constexpr double kRows[5] = {100, 170, 240, 310, 380};
  // The two black circles on the white bar: row 2, columns 2 and 3 (x 400 and 500).
  const auto is_black = [](int row, int col) { return row == 2 && (col == 2 || col == 3); };

  d.PdfRect(Paint::kBlack, 50, 50, 100, 500);   // left strip
  d.PdfRect(Paint::kBlack, 200, 50, 500, 500);  // centre square
  d.PdfRect(Paint::kBlack, 750, 50, 100, 500);  // right strip
  for (int r = 0; r < 5; ++r) {
    for (int c = 0; c < 6; ++c) {
      if (!is_black(r, c)) d.PdfCircle(Paint::kWhite, kColumns[c], kRows[r], kDiameter);
    }
  }
  d.PdfRect(Paint::kWhite, 350, 205, 200, 70);  // the white bar under the black pair
  d.PdfCircle(Paint::kBlack, 400, 240, kDiameter);
  d.PdfCircle(Paint::kBlack, 500, 240, kDiameter);

  // Features: the 30 centres, row-major from the top row, id = 6 * row + col.
  for (int r = 0; r < 5; ++r) {
    for (int c = 0; c < 6; ++c) d.Feature(FeatureKind::kCircleCentre, d.Pdf(kColumns[c], kRows[r]));
  }
}

// ---- 3. Vertical board (vertical_board.pdf, 300 x 1000) -----------------------------------

void DrawVerticalBoard(Drawing& d) {
  constexpr int kCellRows = 18;
  constexpr int kCellCols = 4;
  constexpr double kCell = 50.0;
  constexpr double kLeft = 50.0;  // PDF x of cell column 0
  constexpr double kTop = 50.0;   // PDF y of cell row 0
  // docs/boards.md's cell table, '#' black, row 0 at the top (checked against the PDF).
  constexpr std::string_view kCells[kCellRows] = {"#.##", "##.#", "#.##", "##.#", "#.##", "##..",
                                                  "#.#.", "##..", "#.#.", "##..", "..#.", ".#..",
                                                  "..#.", ".#..", "..#.", "##..", "#.#.", "##.."};
  const auto black = [&](int row, int col) {
    return row >= 0 && row < kCellRows && col >= 0 && col < kCellCols && kCells[row][col] == '#';
  };
  for (int r = 0; r < kCellRows; ++r) {
    for (int c = 0; c < kCellCols; ++c) {
      if (black(r, c)) d.PdfRect(Paint::kBlack, kLeft + kCell * c, kTop + kCell * r, kCell, kCell);
    }
  }
  // Features: the vertices of the three inner lines x = 100, 150, 200 (vertex column
  // v = 1..3, between cell columns v-1 and v) where the four cells around form a corner.
  // Row-major: vertex rows k = 0..18 top to bottom, then x left to right (docs/boards.md).
  for (int k = 0; k <= kCellRows; ++k) {
    for (int v = 1; v < kCellCols; ++v) {
      const bool tl = black(k - 1, v - 1), tr = black(k - 1, v);
      const bool bl = black(k, v - 1), br = black(k, v);
      const int n = tl + tr + bl + br;
      const bool x_corner = n == 2 && tl == br;
      if (n == 1 || n == 3 || x_corner) {
        d.Feature(x_corner ? FeatureKind::kXCorner : FeatureKind::kLCorner,
                  d.Pdf(kLeft + kCell * v, kTop + kCell * k));
      }
    }
  }
}

// ---- 4. ArUco markers (aruco_marker_board.pdf and round_hole_board.pdf) --------------------

// Draws DICT_4X4_50 marker `id` with its top-left corner at PDF (x, y) in its canonical
// orientation (as the PDFs print all four), and adds its corners as features: top-left,
// top-right, bottom-right, bottom-left as seen facing the print.
// Paints marker `id` of `dictionary` with cells `cell_mm` wide and its top-left corner at PDF
// (x, y), in its canonical orientation.
void PaintArucoMarker(Drawing& d, const ArucoDictionaryInfo& dictionary, int id, double x_pdf,
                      double y_pdf, double cell_mm) {
  const int bits = dictionary.data_bits;
  d.PdfRect(Paint::kBlack, x_pdf, y_pdf, cell_mm * dictionary.marker_cells(),
            cell_mm * dictionary.marker_cells());
  const std::uint64_t code = dictionary.codes[id];
  for (int r = 0; r < bits; ++r) {
    for (int c = 0; c < bits; ++c) {
      if (ArucoCellIsWhite(code, bits, r, c)) {
        // +1: the one-cell black border.
        d.PdfRect(Paint::kWhite, x_pdf + cell_mm * (c + 1), y_pdf + cell_mm * (r + 1), cell_mm,
                  cell_mm);
      }
    }
  }
}

void DrawArucoMarker(Drawing& d, int id, double x_pdf, double y_pdf) {
  constexpr double kCell = 40.0;
  constexpr double kSide = kCell * kAruco4x4MarkerCells;
  PaintArucoMarker(d, ArucoDictionaryInfoOf(ArucoDictionary::k4x4_50), id, x_pdf, y_pdf, kCell);
  d.Feature(FeatureKind::kMarkerCorner, d.Pdf(x_pdf, y_pdf), id);
  d.Feature(FeatureKind::kMarkerCorner, d.Pdf(x_pdf + kSide, y_pdf), id);
  d.Feature(FeatureKind::kMarkerCorner, d.Pdf(x_pdf + kSide, y_pdf + kSide), id);
  d.Feature(FeatureKind::kMarkerCorner, d.Pdf(x_pdf, y_pdf + kSide), id);
}

// The four markers of the ArUco and round-hole boards, in id order (so feature id =
// 4 * rank of the marker id + corner). Positions: docs/boards.md's table, checked against both
// PDFs; they are deliberately not symmetric.
void DrawArucoMarkers(Drawing& d) {
  DrawArucoMarker(d, 4, 434, 130);   // top
  DrawArucoMarker(d, 11, 130, 426);  // left
  DrawArucoMarker(d, 12, 730, 426);  // right
  DrawArucoMarker(d, 19, 430, 730);  // bottom
}

// ---- 5. AprilTag grid (april_board.pdf, A0, or any AprilGrid) -----------------------------

constexpr double kAprilTagMm = 88.0;  // black square side at scale 1
// A grid other than the PDF's is printed with this many gaps of white page around its outer
// corner squares (a quiet zone for the tags' outer edges, without a page to trim).
constexpr double kAprilGridMarginGaps = 2.0;

bool IsApriltagPdfGrid(const BoardParams& p) {
  return p.apriltag_cols == 6 && p.apriltag_rows == 6 && p.apriltag_spacing == 0.3 &&
         p.apriltag_start_id == 0;
}

// The page of an AprilGrid other than the PDF's, mm: the grid with its corner squares and
// the margin.
Eigen::Vector2d AprilGridPageMm(const BoardParams& p) {
  const double gap = p.apriltag_spacing * kAprilTagMm;
  const double pitch = kAprilTagMm + gap;
  const Eigen::Vector2d tags(p.apriltag_cols, p.apriltag_rows);
  return tags * pitch + Eigen::Vector2d::Constant(gap + 2.0 * kAprilGridMarginGaps * gap);
}

void DrawApriltagBoard(Drawing& d, const BoardParams& p) {
  const int cols = p.apriltag_cols, rows = p.apriltag_rows;
  const double kTag = kAprilTagMm;
  const double kSpacing = p.apriltag_spacing * kTag;  // 26.4 mm on the PDF
  const double kPitch = kTag + kSpacing;              // 114.4 mm on the PDF
  // The PDF's grid is not centred on the A0 page: its centre, in board-frame millimetres, as
  // measured from april_board.pdf (tag 0's black square starts at x = 280.517 pt,
  // y = 1176.265 pt from the page's bottom-left; all 36 tags agree to 0.0002 mm). Any other
  // grid is centred on its own page.
  const bool pdf = IsApriltagPdfGrid(p);
  const double kGridCentreX = pdf ? 8.46 : 0.0;
  const double kGridCentreY = pdf ? 150.46 : 0.0;
  // tag36h11 has width_at_border 8 (a 1-bit border around 6 x 6 data cells), so its
  // bit_x, bit_y run 1..6; here the data cells sit inside `border_bits` black cells.
  constexpr int kDataBits = 6;
  const int border_bits = p.apriltag_border_bits;
  const double bit = kTag / (kDataBits + 2 * border_bits);

  const std::unique_ptr<apriltag_family_t, void (*)(apriltag_family_t*)> family(tag36h11_create(),
                                                                                tag36h11_destroy);

  // The small black squares at the tag corners: a (cols + 1) x (rows + 1) lattice of kSpacing
  // squares centred between the tags (and around the outside).
  for (int r = 0; r <= rows; ++r) {
    for (int c = 0; c <= cols; ++c) {
      const double cx = kGridCentreX + (c - 0.5 * cols) * kPitch;
      const double cy = kGridCentreY + (r - 0.5 * rows) * kPitch;
      d.BoardRect(Paint::kBlack, cx - 0.5 * kSpacing, cy - 0.5 * kSpacing, cx + 0.5 * kSpacing,
                  cy + 0.5 * kSpacing);
    }
  }
  // Tag k = cols * row + col, row 0 at the bottom, col 0 at the left (docs/boards.md), with
  // id start_id + k.
  for (int k = 0; k < cols * rows; ++k) {
    const int id = p.apriltag_start_id + k;
    const int row = k / cols, col = k % cols;
    const double cx = kGridCentreX + (col - 0.5 * (cols - 1)) * kPitch;
    const double cy = kGridCentreY + (row - 0.5 * (rows - 1)) * kPitch;
    const double left = cx - 0.5 * kTag, right = cx + 0.5 * kTag;
    const double bottom = cy - 0.5 * kTag, top = cy + 0.5 * kTag;
    d.BoardRect(Paint::kBlack, left, bottom, right, top);
    const std::uint64_t code = family->codes[id];
    for (std::uint32_t i = 0; i < family->nbits; ++i) {
      // libapriltag: bit i is code bit nbits-1-i, 1 = white, at data cell (bit_x, bit_y)
      // counted from the tag's top-left with y down.
      if (((code >> (family->nbits - 1 - i)) & 1u) == 0) continue;
      const int cell_x = border_bits + static_cast<int>(family->bit_x[i]) - 1;
      const int cell_y = border_bits + static_cast<int>(family->bit_y[i]) - 1;
      d.BoardRect(Paint::kWhite, left + bit * cell_x, top - bit * (cell_y + 1),
                  left + bit * (cell_x + 1), top - bit * cell_y);
    }
    // Corners: top-left, top-right, bottom-right, bottom-left of the tag's canonical
    // orientation (the PDF prints every tag upright); feature id = 4 * k + corner.
    d.Feature(FeatureKind::kMarkerCorner, d.Board(left, top), id);
    d.Feature(FeatureKind::kMarkerCorner, d.Board(right, top), id);
    d.Feature(FeatureKind::kMarkerCorner, d.Board(right, bottom), id);
    d.Feature(FeatureKind::kMarkerCorner, d.Board(left, bottom), id);
  }
}

// ---- 6. Round-hole board (round_hole_board.pdf, 1100 x 1100) -------------------------------

void DrawRoundHoleBoard(Drawing& d) {
  constexpr double kCell = 300.0;
  constexpr double kHoleDiameter = 240.0;
  // The four corner cells and the centre cell of the 3 x 3 checker from (100, 100) are black
  // and holed; the PDF paints the holes white. Order: rows top to bottom, left to right.
  constexpr double kHoledCells[5][2] = {{100, 100}, {700, 100}, {400, 400}, {100, 700}, {700, 700}};
  for (const auto& c : kHoledCells) d.PdfRect(Paint::kBlack, c[0], c[1], kCell, kCell);
  DrawArucoMarkers(d);  // feature ids 0..15, as on the ArUco board
  for (const auto& c : kHoledCells) {
    d.PdfCircle(Paint::kHole, c[0] + 0.5 * kCell, c[1] + 0.5 * kCell, kHoleDiameter);
  }
  // Feature ids 16..20: the hole centres, in kHoledCells order.
  for (const auto& c : kHoledCells) {
    d.Feature(FeatureKind::kHoleCentre, d.Pdf(c[0] + 0.5 * kCell, c[1] + 0.5 * kCell));
  }
}

// ---- 7. Generic chessboard -----------------------------------------------------------------

// cols x rows inner corners: (cols+1) x (rows+1) squares, the top-left one black, on a page
// with a one-square white margin (the quiet zone a corner detector needs).
void DrawChecker(Drawing& d, int cols, int rows, double square_mm) {
  const double left = -0.5 * (cols + 1) * square_mm;
  const double top = 0.5 * (rows + 1) * square_mm;
  for (int r = 0; r <= rows; ++r) {
    for (int c = 0; c <= cols; ++c) {
      if ((r + c) % 2 != 0) continue;
      d.BoardRect(Paint::kBlack, left + c * square_mm, top - (r + 1) * square_mm,
                  left + (c + 1) * square_mm, top - r * square_mm);
    }
  }
  // Inner corners row-major from the top-left: id = cols * row + col.
  for (int r = 1; r <= rows; ++r) {
    for (int c = 1; c <= cols; ++c) {
      d.Feature(FeatureKind::kXCorner, d.Board(left + c * square_mm, top - r * square_mm));
    }
  }
}

// ---- 8. Circle grid (OpenCV's layouts) ----------------------------------------------------

// The column of circle (row i, col j) in units of the spacing, OpenCV's object point x over
// squareSize: j in the symmetric grid, 2 j + i % 2 in the asymmetric one.
int CircleGridColumn(const BoardParams& p, int i, int j) {
  return p.asymmetric ? 2 * j + i % 2 : j;
}

// The hexagonal grid's rows and zig-zag columns in spacings: columns half a spacing apart,
// rows sqrt(3) / 2 of one, so that neighbours in a row and in adjacent rows are a spacing
// apart.
constexpr double kHexColumnSpacings = 0.5;
constexpr double kHexRowSpacings = 0.86602540378443865;  // sqrt(3) / 2

// The zig-zag column of the hexagonal grid's first circle in row i (from the top): BoofCV
// numbers its rows from the bottom and starts its row 0 on column 0, each row above on the
// other parity (docs/boards.md §8).
int HexRowOffset(const BoardParams& p, int i) { return (p.rows - 1 - i) % 2; }

// The extent of the circle centres in units of the spacing: (last column, last row). Every
// asymmetric grid has at least two rows, so its odd rows reach one spacing further; every
// hexagonal one (three rows or more) has rows on both parities, so its columns span
// cols - 1 half spacings.
Eigen::Vector2d CircleGridExtent(const BoardParams& p) {
  if (p.hexagonal) {
    return {kHexColumnSpacings * (p.cols - 1), kHexRowSpacings * (p.rows - 1)};
  }
  return {p.asymmetric ? 2.0 * (p.cols - 1) + 1.0 : p.cols - 1.0, p.rows - 1.0};
}

// The quiet zone around the grid, in spacings from the outer centres to the page edge: two,
// so that even the asymmetric grid's largest circles (radius under 0.71 spacing) keep more
// than a spacing of white (or of the black field and then white) around them, as a blob
// detector needs to see each circle on its own background.
constexpr double kCircleGridMarginSpacings = 2.0;

// cols x rows circles of diameter_mm on the page centred on their centres' bounding box;
// black on the white page, or white on a black field reaching one spacing beyond the outer
// centres. Feature id = cols * i + j, row i from the top, col j from the left (OpenCV's order
// of object points); hexagonal: row by row from the top, left to right in a row.
void DrawCircleGrid(Drawing& d, const BoardParams& p) {
  const double s = p.spacing_m * 1e3;
  const Eigen::Vector2d half = 0.5 * s * CircleGridExtent(p);
  if (p.light_circles) {
    d.BoardRect(Paint::kBlack, -half.x() - s, -half.y() - s, half.x() + s, half.y() + s);
  }
  const Paint paint = p.light_circles ? Paint::kWhite : Paint::kBlack;
  if (p.hexagonal) {
    for (int i = 0; i < p.rows; ++i) {
      for (int c = HexRowOffset(p, i); c < p.cols; c += 2) {
        const double x = s * kHexColumnSpacings * c - half.x();
        const double y = half.y() - s * kHexRowSpacings * i;
        d.BoardCircle(paint, x, y, p.diameter_m * 1e3);
        d.Feature(FeatureKind::kCircleCentre, d.Board(x, y));
      }
    }
    return;
  }
  for (int i = 0; i < p.rows; ++i) {
    for (int j = 0; j < p.cols; ++j) {
      const double x = s * CircleGridColumn(p, i, j) - half.x();
      const double y = half.y() - s * i;
      d.BoardCircle(paint, x, y, p.diameter_m * 1e3);
      d.Feature(FeatureKind::kCircleCentre, d.Board(x, y));
    }
  }
}

// ---- 9. Square grid (BoofCV's layout) -----------------------------------------------------

// The extent of the squares, mm: cols squares and cols - 1 gaps across, rows and rows - 1 down.
Eigen::Vector2d SquareGridExtentMm(const BoardParams& p) {
  const double s = p.square_m * 1e3, g = p.gap_m * 1e3;
  return {p.cols * s + (p.cols - 1) * g, p.rows * s + (p.rows - 1) * g};
}

// cols x rows black squares, pitch square + gap, centred on the page. Features: the four
// corners of every square, on the (2 cols) x (2 rows) lattice of corner columns C and rows R,
// both from 0 at the top-left: id = 2 cols * R + C (docs/boards.md §9).
void DrawSquareGrid(Drawing& d, const BoardParams& p) {
  const double s = p.square_m * 1e3, pitch = s + p.gap_m * 1e3;
  const Eigen::Vector2d half = 0.5 * SquareGridExtentMm(p);
  for (int r = 0; r < p.rows; ++r) {
    for (int c = 0; c < p.cols; ++c) {
      const double left = -half.x() + c * pitch, top = half.y() - r * pitch;
      d.BoardRect(Paint::kBlack, left, top - s, left + s, top);
    }
  }
  for (int R = 0; R < 2 * p.rows; ++R) {
    for (int C = 0; C < 2 * p.cols; ++C) {
      const double x = -half.x() + (C / 2) * pitch + (C % 2) * s;
      const double y = half.y() - (R / 2) * pitch - (R % 2) * s;
      d.Feature(FeatureKind::kLCorner, d.Board(x, y));
    }
  }
}

// ---- ChArUco (OpenCV's CharucoBoard) ------------------------------------------------------

// The quiet zone around a ChArUco board's squares, in squares (OpenCV's generateImage leaves
// its margin to the caller; one square keeps the outer squares' edges clear of the page edge).
constexpr int kCharucoMarginSquares = 1;

// cols x rows squares of square_m, in PDF coordinates from the top-left square (OpenCV's board
// frame: x right, y down). The squares OpenCV leaves white hold the markers, ids 0, 1, ... in
// row-major order from the top-left; the others are black. Features: the inner corners,
// id = (cols - 1) * row + col from the top-left (OpenCV's charuco ids).
void DrawCharuco(Drawing& d, const BoardParams& p) {
  const double sq = p.square_m * 1e3;
  const double m = p.marker_m * 1e3;
  const double origin = kCharucoMarginSquares * sq;
  const ArucoDictionaryInfo& dictionary = ArucoDictionaryInfoOf(p.charuco_dictionary);
  int next_id = 0;
  for (int r = 0; r < p.rows; ++r) {
    for (int c = 0; c < p.cols; ++c) {
      const double x = origin + c * sq;
      const double y = origin + r * sq;
      if (!CharucoSquareHasMarker(p, r, c)) {
        d.PdfRect(Paint::kBlack, x, y, sq, sq);
        continue;
      }
      const double inset = 0.5 * (sq - m);
      PaintArucoMarker(d, dictionary, next_id++, x + inset, y + inset,
                       m / dictionary.marker_cells());
    }
  }
  for (int r = 1; r < p.rows; ++r) {
    for (int c = 1; c < p.cols; ++c) {
      d.Feature(FeatureKind::kXCorner, d.Pdf(origin + c * sq, origin + r * sq));
    }
  }
}

// Page sizes in millimetres (the PDFs' MediaBoxes; april_board.pdf is A0, 2383.94 x 3370.39
// pt = 841 x 1189 mm).
Eigen::Vector2d PageSizeMm(const BoardParams& p) {
  switch (p.type) {
    case BoardType::kChessboard:
      return {2600.0, 500.0};
    case BoardType::kCircle:
      return {900.0, 600.0};
    case BoardType::kVertical:
      return {300.0, 1000.0};
    case BoardType::kAruco:
      return {1100.0, 1100.0};
    case BoardType::kApriltag:
      return IsApriltagPdfGrid(p) ? Eigen::Vector2d(841.0, 1189.0) : AprilGridPageMm(p);
    case BoardType::kRoundHole:
      return {1100.0, 1100.0};
    case BoardType::kChecker: {
      const double square_mm = p.square_m * 1e3;
      return {(p.cols + 3) * square_mm, (p.rows + 3) * square_mm};
    }
    case BoardType::kCircleGrid: {
      const Eigen::Vector2d extent =
          CircleGridExtent(p) + Eigen::Vector2d::Constant(2.0 * kCircleGridMarginSpacings);
      return p.spacing_m * 1e3 * extent;
    }
    case BoardType::kSquareGrid:
      // A white margin of one square around the squares (the quiet zone that keeps the outer
      // squares apart from whatever is behind the board).
      return SquareGridExtentMm(p) + Eigen::Vector2d::Constant(2e3 * p.square_m);
    case BoardType::kCharuco: {
      const double margins = 2.0 * kCharucoMarginSquares;
      return p.square_m * 1e3 * Eigen::Vector2d(p.cols + margins, p.rows + margins);
    }
  }
  return {0.0, 0.0};
}

bool IsFiniteIn(double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; }

}  // namespace

bool CharucoSquareHasMarker(const BoardParams& p, int row, int col) {
  // OpenCV: the top-left square is black, markers where row + col is odd; the legacy pattern
  // of an even number of rows starts with a white square instead.
  const bool legacy_white_first = p.charuco_legacy && p.rows % 2 == 0;
  return (row + col) % 2 == (legacy_white_first ? 0 : 1);
}

int CharucoMarkerCount(const BoardParams& p) {
  // Either pattern: half the squares, rounded down (an odd count only with odd rows, where
  // both patterns start black).
  return p.cols * p.rows / 2;
}

const char* BoardTypeName(BoardType type) {
  switch (type) {
    case BoardType::kChessboard:
      return "chessboard";
    case BoardType::kCircle:
      return "circle";
    case BoardType::kVertical:
      return "vertical";
    case BoardType::kAruco:
      return "aruco";
    case BoardType::kApriltag:
      return "apriltag";
    case BoardType::kRoundHole:
      return "round_hole";
    case BoardType::kChecker:
      return "checker";
    case BoardType::kCircleGrid:
      return "circle_grid";
    case BoardType::kSquareGrid:
      return "square_grid";
    case BoardType::kCharuco:
      return "charuco";
  }
  return "unknown";
}

std::optional<BoardType> BoardTypeFromName(std::string_view name) {
  for (BoardType t : kAllBoardTypes) {
    if (name == BoardTypeName(t)) return t;
  }
  return std::nullopt;
}

const char* BoardParamsErrorName(BoardParamsError e) {
  switch (e) {
    case BoardParamsError::kOk:
      return "ok";
    case BoardParamsError::kBadScale:
      return "bad_scale";
    case BoardParamsError::kBadCols:
      return "bad_cols";
    case BoardParamsError::kBadRows:
      return "bad_rows";
    case BoardParamsError::kBadSquare:
      return "bad_square";
    case BoardParamsError::kBadBorderBits:
      return "bad_border_bits";
    case BoardParamsError::kBadSpacing:
      return "bad_spacing";
    case BoardParamsError::kBadDiameter:
      return "bad_diameter";
    case BoardParamsError::kBadTagGrid:
      return "bad_tag_grid";
    case BoardParamsError::kBadTagSpacing:
      return "bad_tag_spacing";
    case BoardParamsError::kBadStartId:
      return "bad_start_id";
    case BoardParamsError::kBadLayout:
      return "bad_layout";
    case BoardParamsError::kBadGap:
      return "bad_gap";
    case BoardParamsError::kBadMarker:
      return "bad_marker";
    case BoardParamsError::kBadMarkerCount:
      return "bad_marker_count";
  }
  return "unknown";
}

BoardParamsError ValidateBoardParams(const BoardParams& p) {
  if (!IsFiniteIn(p.scale, kMinBoardScale, kMaxBoardScale)) return BoardParamsError::kBadScale;
  const int min_side = p.hexagonal ? kMinHexagonalSide : kMinCheckerCorners;
  if (p.cols < min_side || p.cols > kMaxCheckerCorners) {
    return BoardParamsError::kBadCols;
  }
  if (p.rows < min_side || p.rows > kMaxCheckerCorners) {
    return BoardParamsError::kBadRows;
  }
  if (!IsFiniteIn(p.square_m, 0.0, kMaxCheckerSquareM) || p.square_m == 0.0) {
    return BoardParamsError::kBadSquare;
  }
  if (p.apriltag_border_bits != 1 && p.apriltag_border_bits != 2) {
    return BoardParamsError::kBadBorderBits;
  }
  if (!IsFiniteIn(p.spacing_m, 0.0, kMaxCircleSpacingM) || p.spacing_m == 0.0) {
    return BoardParamsError::kBadSpacing;
  }
  if (p.hexagonal && p.asymmetric) return BoardParamsError::kBadLayout;
  // Nearest neighbours: along a row (symmetric), diagonally between rows (asymmetric), or all
  // six around (hexagonal).
  const double nearest_m = p.asymmetric ? p.spacing_m * std::sqrt(2.0) : p.spacing_m;
  if (!(std::isfinite(p.diameter_m) && p.diameter_m > 0.0 && p.diameter_m < nearest_m)) {
    return BoardParamsError::kBadDiameter;
  }
  if (p.apriltag_cols < 1 || p.apriltag_cols > kMaxAprilGridTags || p.apriltag_rows < 1 ||
      p.apriltag_rows > kMaxAprilGridTags || p.apriltag_cols * p.apriltag_rows < 2) {
    return BoardParamsError::kBadTagGrid;
  }
  if (!IsFiniteIn(p.apriltag_spacing, kMinAprilGridSpacing, kMaxAprilGridSpacing)) {
    return BoardParamsError::kBadTagSpacing;
  }
  if (p.apriltag_start_id < 0 ||
      p.apriltag_start_id > kTag36h11Codes - p.apriltag_cols * p.apriltag_rows) {
    return BoardParamsError::kBadStartId;
  }
  if (!IsFiniteIn(p.gap_m, 0.0, kMaxSquareGridGapM) || p.gap_m == 0.0) {
    return BoardParamsError::kBadGap;
  }
  if (p.type == BoardType::kCharuco) {
    if (!(std::isfinite(p.marker_m) && p.marker_m > 0.0 && p.marker_m < p.square_m)) {
      return BoardParamsError::kBadMarker;
    }
    // One marker per white square, each of its own id.
    if (CharucoMarkerCount(p) > ArucoDictionaryInfoOf(p.charuco_dictionary).marker_count()) {
      return BoardParamsError::kBadMarkerCount;
    }
  }
  return BoardParamsError::kOk;
}

const char* FeatureKindName(FeatureKind kind) {
  switch (kind) {
    case FeatureKind::kXCorner:
      return "x_corner";
    case FeatureKind::kLCorner:
      return "l_corner";
    case FeatureKind::kCircleCentre:
      return "circle_centre";
    case FeatureKind::kMarkerCorner:
      return "marker_corner";
    case FeatureKind::kHoleCentre:
      return "hole_centre";
  }
  return "unknown";
}

const char* PaintName(Paint paint) {
  switch (paint) {
    case Paint::kWhite:
      return "white";
    case Paint::kBlack:
      return "black";
    case Paint::kHole:
      return "hole";
    case Paint::kOffBoard:
      return "off_board";
  }
  return "unknown";
}

bool BoardShape::Contains(const Eigen::Vector2d& p) const {
  if (geometry == ShapeGeometry::kCircle) {
    const double r = radius_m();
    return (p - centre_board()).squaredNorm() < r * r;
  }
  return p.x() >= box_board.min().x() && p.x() < box_board.max().x() &&
         p.y() >= box_board.min().y() && p.y() < box_board.max().y();
}

std::optional<Board> Board::Create(const BoardParams& params, BoardParamsError* error) {
  const BoardParamsError e = ValidateBoardParams(params);
  if (error != nullptr) *error = e;
  if (e != BoardParamsError::kOk) return std::nullopt;

  const Eigen::Vector2d page_mm = PageSizeMm(params);
  Drawing d(page_mm.x(), page_mm.y(), params.scale);
  switch (params.type) {
    case BoardType::kChessboard:
      DrawChessboard(d);
      break;
    case BoardType::kCircle:
      DrawCircleBoard(d);
      break;
    case BoardType::kVertical:
      DrawVerticalBoard(d);
      break;
    case BoardType::kAruco:
      DrawArucoMarkers(d);
      break;
    case BoardType::kApriltag:
      DrawApriltagBoard(d, params);
      break;
    case BoardType::kRoundHole:
      DrawRoundHoleBoard(d);
      break;
    case BoardType::kChecker:
      DrawChecker(d, params.cols, params.rows, params.square_m * 1e3);
      break;
    case BoardType::kCircleGrid:
      DrawCircleGrid(d, params);
      break;
    case BoardType::kSquareGrid:
      DrawSquareGrid(d, params);
      break;
    case BoardType::kCharuco:
      DrawCharuco(d, params);
      break;
  }
  Board board;
  board.params_ = params;
  board.page_size_m_ = d.page_size_m();
  board.shapes_ = std::move(d.shapes());
  board.features_ = std::move(d.features());
  board.BuildIndex();
  return board;
}

namespace {

// Conservative geometric tests of a shape against a closed box.
bool ShapeTouches(const BoardShape& s, const Eigen::AlignedBox2d& box) {
  if (!s.box_board.intersects(box)) return false;
  if (s.geometry == ShapeGeometry::kRect) return true;
  const double r = s.radius_m();
  return box.squaredExteriorDistance(s.centre_board()) <= r * r;
}

// Points closer than this fraction of an index cell to the cell's edges are not trusted to
// the cell's uniform paint: 1e-9 is far above the rounding of CellOf()'s arithmetic (~1e-13
// of a cell) and far below anything a renderer samples.
constexpr double kInteriorFraction = 1e-9;

bool ShapeCovers(const BoardShape& s, const Eigen::AlignedBox2d& box) {
  if (s.geometry == ShapeGeometry::kRect) return s.box_board.contains(box);
  const double r2 = s.radius_m() * s.radius_m();
  const Eigen::Vector2d c = s.centre_board();
  for (int i = 0; i < 4; ++i) {
    if ((box.corner(static_cast<Eigen::AlignedBox2d::CornerType>(i)) - c).squaredNorm() >= r2) {
      return false;
    }
  }
  return true;
}

}  // namespace

void Board::BuildIndex() {
  const double w = page_size_m_.x(), h = page_size_m_.y();
  // Cells of half the smallest shape extent leave most cells inside a single shape, so most
  // queries are one table look-up; grown when that would exceed kMaxIndexCells.
  double smallest = std::min(w, h);
  for (const BoardShape& s : shapes_) {
    smallest = std::min(smallest, s.box_board.sizes().minCoeff());
  }
  index_cell_m_ = std::max(0.5 * smallest, std::sqrt(w * h / kMaxIndexCells));
  for (;;) {
    index_cols_ = std::max(1, static_cast<int>(std::ceil(w / index_cell_m_)));
    index_rows_ = std::max(1, static_cast<int>(std::ceil(h / index_cell_m_)));
    if (static_cast<long long>(index_cols_) * index_rows_ <= kMaxIndexCells) break;
    index_cell_m_ *= 1.05;  // the ceil() overshoot is small; a few steps suffice
  }
  const int n_cells = index_cols_ * index_rows_;
  // Cell boxes are grown by a nanometre-scale margin (far above the rounding in CellOf(),
  // ~1e-16 of the page) so that rounding can never put a point in a cell whose list misses
  // a shape that contains it.
  const double margin = 1e-9 * std::max(w, h);
  const Eigen::Vector2d origin = -0.5 * page_size_m_;
  const auto cell_box = [&](int cx, int cy, double grow) {
    const Eigen::Vector2d lo = origin + index_cell_m_ * Eigen::Vector2d(cx, cy);
    return Eigen::AlignedBox2d(lo - Eigen::Vector2d::Constant(grow),
                               lo + Eigen::Vector2d::Constant(index_cell_m_ + grow));
  };
  const auto cell_range = [&](double lo, double hi, int n, int* first, int* last) {
    *first = std::clamp(static_cast<int>(std::floor((lo - margin) / index_cell_m_)), 0, n - 1);
    *last = std::clamp(static_cast<int>(std::floor((hi + margin) / index_cell_m_)), 0, n - 1);
  };

  // Bucket every shape into the cells its bounding box overlaps (counting pass, then fill),
  // in painter's order.
  std::vector<std::uint32_t> count(n_cells + 1, 0);
  const auto for_each_cell = [&](const BoardShape& s, auto&& fn) {
    int x0, x1, y0, y1;
    cell_range(s.box_board.min().x() - origin.x(), s.box_board.max().x() - origin.x(), index_cols_,
               &x0, &x1);
    cell_range(s.box_board.min().y() - origin.y(), s.box_board.max().y() - origin.y(), index_rows_,
               &y0, &y1);
    for (int cy = y0; cy <= y1; ++cy) {
      for (int cx = x0; cx <= x1; ++cx) fn(cy * index_cols_ + cx);
    }
  };
  for (const BoardShape& s : shapes_) for_each_cell(s, [&](int c) { ++count[c + 1]; });
  for (int c = 0; c < n_cells; ++c) count[c + 1] += count[c];
  std::vector<std::uint32_t> bucket(count[n_cells]);
  std::vector<std::uint32_t> fill(count.begin(), count.end() - 1);
  for (std::uint32_t i = 0; i < shapes_.size(); ++i) {
    for_each_cell(shapes_[i], [&](int c) { bucket[fill[c]++] = i; });
  }

  // Per cell keep the shapes that touch it (grown by the margin), topmost first, down to
  // the first one that covers the grown cell: nothing under it can show, even at a point
  // that rounding assigns to this cell from just beyond its edge. The cell is uniform when
  // the topmost shape reaching into its interior (the cell shrunk by half of
  // kInteriorFraction) covers that interior; PaintAt trusts this only for points clear of
  // the cell's edges by kInteriorFraction, so cells that coincide with squares, as on most
  // boards, are uniform, and PaintAt stays exact.
  index_cells_.assign(n_cells, IndexCell{});
  index_shapes_.clear();
  for (int cy = 0; cy < index_rows_; ++cy) {
    for (int cx = 0; cx < index_cols_; ++cx) {
      const int c = cy * index_cols_ + cx;
      const Eigen::AlignedBox2d grown = cell_box(cx, cy, margin);
      const Eigen::AlignedBox2d inner = cell_box(cx, cy, -0.5 * kInteriorFraction * index_cell_m_);
      IndexCell& cell = index_cells_[c];
      cell.begin = static_cast<std::uint32_t>(index_shapes_.size());
      bool decided = false;
      for (std::uint32_t k = count[c + 1]; k > count[c]; --k) {
        const BoardShape& s = shapes_[bucket[k - 1]];
        if (!ShapeTouches(s, grown)) continue;
        if (!decided && ShapeTouches(s, inner)) {  // the topmost shape inside the cell
          decided = true;
          cell.uniform = ShapeCovers(s, inner);
          cell.paint = s.paint;
        }
        index_shapes_.push_back(bucket[k - 1]);
        if (ShapeCovers(s, grown)) break;
      }
      cell.end = static_cast<std::uint32_t>(index_shapes_.size());
    }
  }
}

bool Board::CellOf(const Eigen::Vector2d& p, int* cx, int* cy, bool* interior) const {
  const double hw = 0.5 * page_size_m_.x(), hh = 0.5 * page_size_m_.y();
  // Written so that NaN fails every comparison and lands off the board.
  if (!(p.x() >= -hw && p.x() < hw && p.y() >= -hh && p.y() < hh)) return false;
  const double fx = (p.x() + hw) / index_cell_m_, fy = (p.y() + hh) / index_cell_m_;
  *cx = std::min(static_cast<int>(fx), index_cols_ - 1);
  *cy = std::min(static_cast<int>(fy), index_rows_ - 1);
  const double ux = fx - *cx, uy = fy - *cy;
  *interior = ux >= kInteriorFraction && ux <= 1 - kInteriorFraction && uy >= kInteriorFraction &&
              uy <= 1 - kInteriorFraction;
  return true;
}

Paint Board::PaintAt(const Eigen::Vector2d& p_board) const {
  int cx, cy;
  bool interior;
  if (!CellOf(p_board, &cx, &cy, &interior)) return Paint::kOffBoard;
  const IndexCell& cell = index_cells_[cy * index_cols_ + cx];
  if (cell.uniform && interior) return cell.paint;
  for (std::uint32_t k = cell.begin; k < cell.end; ++k) {
    const BoardShape& s = shapes_[index_shapes_[k]];
    if (s.Contains(p_board)) return s.paint;
  }
  // Unreachable on the page (the page rectangle ends every cell's list); kept total.
  return Paint::kOffBoard;
}

std::optional<Paint> Board::UniformPaintIn(const Eigen::Vector2d& min_board,
                                           const Eigen::Vector2d& max_board) const {
  int x0, y0, x1, y1;
  bool interior0, interior1;
  if (!CellOf(min_board, &x0, &y0, &interior0) || !CellOf(max_board, &x1, &y1, &interior1)) {
    return std::nullopt;
  }
  if (x0 == x1 && y0 == y1) {
    const IndexCell& cell = index_cells_[y0 * index_cols_ + x0];
    if (cell.uniform && interior0 && interior1) return cell.paint;
  }
  // A pixel-sized box meets at most 2 x 2 cells; a larger one is left to the caller.
  if (x1 - x0 > 1 || y1 - y0 > 1) return std::nullopt;
  // Per cell, the topmost of its shapes reaching into the box's part in that cell decides
  // that part. The box is shrunk by a hair so that a shape merely sharing its edge does not
  // count.
  const Eigen::Vector2d hair = Eigen::Vector2d::Constant(kInteriorFraction * index_cell_m_);
  const Eigen::AlignedBox2d box(min_board + hair, max_board - hair);
  if (box.isEmpty()) return std::nullopt;
  const Eigen::Vector2d origin = -0.5 * page_size_m_;
  std::optional<Paint> paint;
  for (int cy = y0; cy <= y1; ++cy) {
    for (int cx = x0; cx <= x1; ++cx) {
      const Eigen::Vector2d lo = origin + index_cell_m_ * Eigen::Vector2d(cx, cy);
      const Eigen::AlignedBox2d part =
          box.intersection(Eigen::AlignedBox2d(lo, lo + Eigen::Vector2d::Constant(index_cell_m_)));
      if (part.isEmpty()) continue;
      const IndexCell& cell = index_cells_[cy * index_cols_ + cx];
      std::optional<Paint> part_paint;
      for (std::uint32_t k = cell.begin; k < cell.end; ++k) {
        const BoardShape& s = shapes_[index_shapes_[k]];
        if (!ShapeTouches(s, part)) continue;
        if (ShapeCovers(s, part)) part_paint = s.paint;
        break;
      }
      if (!part_paint.has_value() || (paint.has_value() && *paint != *part_paint)) {
        return std::nullopt;
      }
      paint = part_paint;
    }
  }
  return paint;
}

double SmallestCellM(const Board& board) {
  double smallest = std::numeric_limits<double>::infinity();
  // shapes()[0] is the white page; every later shape is a printed square, bit run, disc
  // or hole, whose shorter side is one cell.
  for (size_t i = 1; i < board.shapes().size(); ++i) {
    const Eigen::Vector2d size = board.shapes()[i].box_board.sizes();
    if (board.shapes()[i].paint == Paint::kHole) continue;
    smallest = std::min(smallest, size.minCoeff());
  }
  return smallest;
}

}  // namespace linecal

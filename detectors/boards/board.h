#pragma once
// Parametric definitions of the calibration boards of docs/boards.md: their features (with stable
// ids and exact board-frame coordinates), the shapes they are printed with, and a fast point
// query of what is printed where. docs/boards.md documents every board's ids and layout.
//
// Board frame (docs/boards.md, docs/conventions.md): origin at the centre of the printed page, x to
// the right and y up as seen facing the print, z out of the print towards the viewer.
// Everything here is in metres in that frame. The default layouts are 1 PDF unit = 1 mm
// (april_board.pdf: an A0 page); `scale` multiplies every length about the page centre.
//
// A Board is an immutable value: build it once with Board::Create and share it freely (all
// member functions are const and thread-safe).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

#include "detectors/boards/aruco_dictionaries.h"

namespace linecal {

enum class BoardType {
  kChessboard,  // the wide two-group board, chessboard.pdf
  kCircle,      // circle_board.pdf
  kVertical,    // vertical_board.pdf
  kAruco,       // aruco_marker_board.pdf, four DICT_4X4_50 markers
  kApriltag,    // april_board.pdf, a 6 x 6 tag36h11 AprilGrid
  kRoundHole,   // round_hole_board.pdf, five through holes and four ArUco markers
  kChecker,     // generic chessboard: cols x rows inner corners, square_m squares
  kCircleGrid,  // OpenCV's circle grid, symmetric or asymmetric: cols x rows circles;
                // or BoofCV's hexagonal grid (hexagonal)
  kSquareGrid,  // BoofCV's square grid: cols x rows black squares apart by white gaps
  kCharuco,     // OpenCV's ChArUco: cols x rows squares, ArUco markers in the white ones
};

inline constexpr std::array<BoardType, 10> kAllBoardTypes = {
    BoardType::kChessboard, BoardType::kCircle,    BoardType::kVertical, BoardType::kAruco,
    BoardType::kApriltag,   BoardType::kRoundHole, BoardType::kChecker,  BoardType::kCircleGrid,
    BoardType::kSquareGrid, BoardType::kCharuco};

// The board's command-line and config name: "chessboard", "circle", "vertical", "aruco",
// "apriltag", "round_hole", "checker", "circle_grid", "square_grid", "charuco"
// (docs/interfaces.md).
const char* BoardTypeName(BoardType type);
// The inverse of BoardTypeName; nullopt for any other text. Case-sensitive.
std::optional<BoardType> BoardTypeFromName(std::string_view name);

struct BoardParams {
  BoardType type = BoardType::kChessboard;
  // Multiplies every length of the layout (a board printed at another size is the same
  // board with another scale, docs/boards.md). For kChecker it multiplies square_m too, for
  // kSquareGrid square_m and gap_m.
  double scale = 1.0;
  // kChecker: inner corners along x (cols) and y (rows). kCircleGrid: circles per row (cols)
  // and rows of circles (rows), OpenCV's patternSize (cols, rows). kSquareGrid: squares per row
  // (cols) and rows of squares (rows). kCharuco: squares along x and y, OpenCV's CharucoBoard
  // size (cols, rows). Defaults: the classic 9 x 6 boards of docs/boards.md.
  int cols = 9;
  int rows = 6;
  // kChecker, kSquareGrid and kCharuco: the square side. Default 25 mm.
  double square_m = 0.025;
  // kSquareGrid only (docs/boards.md §9): the white space between neighbouring squares, along
  // a row and along a column (BoofCV's spaceWidth). Default 25 mm.
  double gap_m = 0.025;
  // kCircleGrid only (docs/boards.md §8): the centre distance, as OpenCV's squareSize: the
  // distance between neighbours in a row and between rows of the symmetric grid; in the
  // asymmetric grid rows are spacing_m apart and a row's circles 2 * spacing_m apart, every
  // other row shifted by spacing_m; in the hexagonal grid (below) the distance of every pair
  // of neighbours. Default 25 mm.
  double spacing_m = 0.025;
  // kCircleGrid only: the printed circles' diameter, below the distance of nearest
  // neighbours (spacing_m, or spacing_m * sqrt(2) in the asymmetric grid). Default 12.5 mm.
  double diameter_m = 0.0125;
  // kCircleGrid only: OpenCV's CALIB_CB_ASYMMETRIC_GRID layout (true) or the symmetric
  // CALIB_CB_SYMMETRIC_GRID (false, default).
  bool asymmetric = false;
  // kCircleGrid only: white circles on a black field (true) instead of black circles on the
  // white page (false, default; what OpenCV's blob detector looks for by default).
  bool light_circles = false;
  // kCircleGrid only (docs/boards.md §8, "Hexagonal"): BoofCV's hexagonal grid
  // (CIRCLE_HEXAGONAL) instead of OpenCV's layouts. cols and rows are then BoofCV's numCols and
  // numRows: rows of circles, spacing_m * sqrt(3) / 2 apart, on cols zig-zag columns spacing_m
  // / 2 apart, every circle on every other column (row i from the top on the columns
  // (rows - 1 - i) % 2, + 2, ...), so that every circle's six nearest neighbours are
  // spacing_m (BoofCV's shapeDistance) away at 60 degrees to each other. Excludes asymmetric.
  bool hexagonal = false;
  // kApriltag only: black border width in bits. 2 = Kalibr's AprilGrid (the PDF); 1 = the
  // ordinary tag36h11 layout. The black square stays 88 mm either way, so the features do
  // not change; only the bit size does (88 mm / 10 or / 8).
  int apriltag_border_bits = 2;
  // kApriltag only (docs/boards.md §5): the grid, as Kalibr's AprilGrid target describes it.
  // Tags per row (apriltag_cols) and per column (apriltag_rows); the gap between tags as a
  // fraction of the tag's black square (Kalibr's tagSpacing); the id of the tag at the bottom
  // left (ids run left to right, then upward). The black square is 88 mm * scale. The
  // defaults are april_board.pdf; any other grid is printed centred on a page of its own.
  int apriltag_cols = 6;
  int apriltag_rows = 6;
  double apriltag_spacing = 0.3;
  int apriltag_start_id = 0;
  // kCharuco only (docs/boards.md, ChArUco): the side of the markers centred in the white
  // squares, OpenCV's markerLength; below square_m. Default 18.75 mm (3/4 of the square).
  double marker_m = 0.01875;
  // kCharuco only: the OpenCV dictionary of the markers (ids 0, 1, ... of it). Default
  // DICT_4X4_50, OpenCV's usual choice and the one of the station's marker boards.
  ArucoDictionary charuco_dictionary = ArucoDictionary::k4x4_50;
  // kCharuco only: OpenCV's legacy pattern (CharucoBoard::setLegacyPattern, boards made before
  // OpenCV 4.6): with an even number of rows the top-left square is white and holds marker 0;
  // otherwise (and always when false, the default) the top-left square is black.
  bool charuco_legacy = false;
};

enum class BoardParamsError {
  kOk = 0,
  kBadScale,        // not finite or outside [kMinBoardScale, kMaxBoardScale]
  kBadCols,         // outside [kMinCheckerCorners (kMinHexagonalSide), kMaxCheckerCorners]
  kBadRows,         // outside [kMinCheckerCorners (kMinHexagonalSide), kMaxCheckerCorners]
  kBadSquare,       // not finite or outside (0, kMaxCheckerSquareM]
  kBadBorderBits,   // neither 1 nor 2
  kBadSpacing,      // not finite or outside (0, kMaxCircleSpacingM]
  kBadDiameter,     // not finite, not > 0, or not below the nearest neighbours' distance
  kBadTagGrid,      // apriltag_cols or _rows outside [1, kMaxAprilGridTags], or one tag only
  kBadTagSpacing,   // not finite or outside [kMinAprilGridSpacing, kMaxAprilGridSpacing]
  kBadStartId,      // negative, or the grid's last id beyond tag36h11's kTag36h11Codes - 1
  kBadLayout,       // hexagonal and asymmetric both set: two layouts at once
  kBadGap,          // not finite or outside (0, kMaxSquareGridGapM]
  kBadMarker,       // kCharuco: marker_m not finite, not > 0, or not below square_m
  kBadMarkerCount,  // kCharuco: more white squares than charuco_dictionary has markers
};

// A board of 2.6 mm or of 260 m is a typo, not a board: scales outside this range are refused.
inline constexpr double kMinBoardScale = 1e-3;
inline constexpr double kMaxBoardScale = 1e2;
// Two inner corners (or circles, for kCircleGrid) per side give the grid a direction; 100 is
// far beyond any printed target and bounds the shape count (about 10^4 squares or circles).
inline constexpr int kMinCheckerCorners = 2;
inline constexpr int kMaxCheckerCorners = 100;
// A hexagonal grid of two rows or columns has no circle with neighbours on three sides (two
// rows or columns hold a zig-zag line): three a side, five circles, give a detector a lattice.
// Checked when hexagonal is set, whatever the type (as every field).
inline constexpr int kMinHexagonalSide = 3;
// No station uses chessboard squares over 1 m.
inline constexpr double kMaxCheckerSquareM = 1.0;
// Nor circle grids with a centre distance over 1 m.
inline constexpr double kMaxCircleSpacingM = 1.0;
// Nor square grids with gaps over 1 m.
inline constexpr double kMaxSquareGridGapM = 1.0;
// AprilGrids: up to 50 tags a side (far beyond a printed target; tag36h11 has 587 codes), gaps
// of 5% to 100% of a tag (Kalibr's tagSpacing; below 5% the corner squares vanish).
inline constexpr int kMaxAprilGridTags = 50;
inline constexpr double kMinAprilGridSpacing = 0.05;
inline constexpr double kMaxAprilGridSpacing = 1.0;
inline constexpr int kTag36h11Codes = 587;
// kCharuco: whether square (row, col), 0-based from the top-left, is white and holds a marker
// (OpenCV's layout, p.charuco_legacy included), and how many markers the board holds
// (ids 0..count-1, row-major over those squares). O(1).
bool CharucoSquareHasMarker(const BoardParams& p, int row, int col);
int CharucoMarkerCount(const BoardParams& p);

// A short, stable text per error ("bad_scale", ...), for reasons and messages.
const char* BoardParamsErrorName(BoardParamsError e);
// Checks every field (the checker, circle grid, square grid and apriltag fields too, whatever
// the type; marker_m and the marker count only for kCharuco). O(1).
BoardParamsError ValidateBoardParams(const BoardParams& params);

enum class FeatureKind {
  kXCorner,       // two black squares touching diagonally
  kLCorner,       // one (or three) black squares meeting white at a vertex
  kCircleCentre,  // centre of a printed circle (not of its image ellipse)
  kMarkerCorner,  // outer corner of an ArUco marker's or AprilTag's black square
  kHoleCentre,    // centre of a through hole (seen by a LiDAR)
};

// "x_corner", "l_corner", "circle_centre", "marker_corner", "hole_centre".
const char* FeatureKindName(FeatureKind kind);

struct BoardFeature {
  int id = 0;  // stable per board type, 0..features().size()-1 (docs/boards.md)
  Eigen::Vector2d p_board = Eigen::Vector2d::Zero();  // metres, board frame, scaled
  FeatureKind kind = FeatureKind::kXCorner;
  int marker = -1;  // ArUco / AprilTag id for kMarkerCorner, -1 otherwise
};

// What a point of the board looks like.
enum class Paint : std::uint8_t {
  kWhite,     // printed white (the page)
  kBlack,     // printed black
  kHole,      // a through hole: whatever is behind the board shows
  kOffBoard,  // outside the page
};

// "white", "black", "hole", "off_board".
const char* PaintName(Paint paint);

enum class ShapeGeometry : std::uint8_t {
  kRect,    // an axis-aligned rectangle: box_board
  kCircle,  // a disc inscribed in the square box_board
};

// One filled primitive of a board's drawing. A point is inside a rectangle when
// min <= p < max on both axes (half-open, so tiles that share an edge never overlap), and
// inside a circle when |p - centre| < radius.
struct BoardShape {
  ShapeGeometry geometry = ShapeGeometry::kRect;
  Paint paint = Paint::kBlack;  // kWhite, kBlack or kHole
  Eigen::AlignedBox2d box_board;

  Eigen::Vector2d centre_board() const { return box_board.center(); }
  double radius_m() const { return 0.5 * box_board.sizes().x(); }
  bool Contains(const Eigen::Vector2d& p_board) const;
};

class Board {
 public:
  // An empty board, so that Board can be a plain member: no page, shapes or features, and
  // PaintAt() is kOffBoard everywhere. Only Create() makes a real board.
  Board() = default;

  // Builds the board of `params`. Returns nullopt, with the reason in *error when error is
  // not null, when ValidateBoardParams fails. Cost: proportional to the number of shapes
  // (at most about 10^4) plus the point index (at most kMaxIndexCells cells); about a
  // millisecond for the default boards.
  static std::optional<Board> Create(const BoardParams& params, BoardParamsError* error = nullptr);

  const BoardParams& params() const { return params_; }
  BoardType type() const { return params_.type; }
  const char* name() const { return BoardTypeName(params_.type); }

  // Width (x) and height (y) of the printed page, metres, scaled. The page spans
  // [-w/2, w/2) x [-h/2, h/2) in the board frame.
  const Eigen::Vector2d& page_size_m() const { return page_size_m_; }

  // Every feature, ordered by id (features()[i].id == i). Ids per board: docs/boards.md.
  const std::vector<BoardFeature>& features() const { return features_; }

  // The drawing, in painter's order: shapes()[0] is the white page, every later shape is
  // painted over the earlier ones. The board "draws itself" from these (SVG, raster).
  const std::vector<BoardShape>& shapes() const { return shapes_; }

  // What is printed at p_board (metres, board frame): the paint of the last shape in
  // shapes() that contains the point, kOffBoard outside the page (and for NaN).
  // O(1) on average: a uniform grid index over the page holds, per cell, either the one
  // paint that covers it or the few shapes that cross it. Meant to be called per
  // sub-sample of every rendered pixel.
  Paint PaintAt(const Eigen::Vector2d& p_board) const;

  // The paint of the axis-aligned box [min_board, max_board] (all of it but a
  // nanometre-scale band along its edges) when it has one paint; nullopt when it may hold
  // more than one, or is not entirely on the page. Meant for pixel-sized boxes: a box over
  // more than 2 x 2 index cells (over half the smallest shape wide) gives nullopt. O(1) on
  // average: a look-up, or a few shapes of at most four index cells. Lets a renderer
  // supersample only the pixels that an edge crosses.
  std::optional<Paint> UniformPaintIn(const Eigen::Vector2d& min_board,
                                      const Eigen::Vector2d& max_board) const;

  // Bounds the point index: at most 2^18 cells (a few MB), whatever the board.
  static constexpr int kMaxIndexCells = 1 << 18;

 private:
  struct IndexCell {
    std::uint32_t begin = 0;  // range into index_shapes_, topmost shape first
    std::uint32_t end = 0;
    bool uniform = false;  // true: every point clear of the cell's edges has `paint`
    Paint paint = Paint::kWhite;
  };

  void BuildIndex();
  // The index cell of a point on the page (false off the page); *interior: the point is
  // clear of the cell's edges, where the cell's uniform paint can be trusted.
  bool CellOf(const Eigen::Vector2d& p_board, int* cx, int* cy, bool* interior) const;

  BoardParams params_;
  Eigen::Vector2d page_size_m_ = Eigen::Vector2d::Zero();
  std::vector<BoardFeature> features_;
  std::vector<BoardShape> shapes_;

  // The point index: index_cols_ x index_rows_ square cells of index_cell_m_, row-major,
  // from the page's lower-left corner.
  double index_cell_m_ = 0.0;
  int index_cols_ = 0;
  int index_rows_ = 0;
  std::vector<IndexCell> index_cells_;
  std::vector<std::uint32_t> index_shapes_;
};

// The smallest printed square or marker cell of a board, metres: a chessboard square, an
// ArUco or AprilTag bit, the smallest circle. O(shapes).
double SmallestCellM(const Board& board);

}  // namespace linecal

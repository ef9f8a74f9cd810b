#pragma once
// The corpus of real photographs of calibration boards (the camera_real/ folder of the
// external data, docs/external-data.md), in linecal's terms: which board each set shows (as
// BoardParams where linecal has that board), its lens, its photos, and what photos_eval and
// photos_test both run on them: linecal's detector on a photo, the false-positive sweep of
// every linecal board over the photos that do not show it, and OpenCV's detector as the
// reference a found board is checked against. OpenCV stays in this file's .cc, at the test
// edge; detectors/ never sees it.
//
// Renders prove accuracy with exact truth; these photos prove what renders cannot: cut outer
// squares, missing margins, clutter that continues the grid, real distortion, JPEG. Issue 19
// (part 6) sets the bars: found >= 98% (mild) / 95% (wide, fisheye) of the photos that show
// the whole board, no false detection, calibration RMS from linecal's corners no worse than
// from OpenCV's on the same photos.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/detection.h"

namespace linecal::photo_corpus {

// How strongly the lens bends the board. Selects the found-rate bar (98% mild, else 95%),
// the RMS bar (1.0x OpenCV mild, else 1.1x) and the camera model of the per-set calibration
// (fisheye: OpenCV's equidistant model; else pinhole with k1 k2 p1 p2 k3).
enum class Lens { kMild, kWide, kFisheye };

// "mild", "wide", "fisheye".
const char* LensName(Lens lens);

// What OpenCV's reference detector looks for in a set's photos.
enum class Reference {
  kNone,               // OpenCV has no detector used here (square grids, hexagonal, markers)
  kChessboard,         // findChessboardCornersSB
  kSymmetricCircles,   // findCirclesGrid, symmetric
  kAsymmetricCircles,  // findCirclesGrid, asymmetric (OpenCV's layout)
};

struct PhotoSet {
  // Stable name, used by --set and kSetsHeldToTheBar: the folder, plus the file's stem where
  // a folder holds photos of two boards.
  std::string name;
  std::string folder;     // relative to the corpus root (camera_real)
  std::string only_file;  // non-empty: the set is this one file of the folder
  // The board as linecal's BoardParams; nullopt where linecal has no such board yet (the
  // set's photos then only feed the false-positive sweep).
  std::optional<BoardParams> board;
  std::string description;  // what is printed, in words
  Lens lens = Lens::kMild;
  double pitch_m = 0.0;  // physical square side or circle pitch; 0 when not published
  Reference reference = Reference::kNone;
  // OpenCV's pattern size: points along a row (cols) and along a column (rows).
  int reference_cols = 0;
  int reference_rows = 0;
  // File-name prefixes of the cameras of a stereo set, each calibrated on its own; empty:
  // one camera.
  std::vector<std::string> cameras;
  // File names whose photo shows only part of the board (by eye: an inner corner outside
  // the image). They count in found/total but not in the found-rate bar.
  std::vector<std::string> partial_views;
};

// Every set of the corpus, in a fixed order. The table is code, not read from the corpus:
// the board geometry was checked against each folder's calibration_target.yaml (squares, so
// inner corners = squares - 1) and against the photos.
const std::vector<PhotoSet>& Sets();

// The set of that name, or nullptr.
const PhotoSet* FindSet(std::string_view name);

// The photos (.jpg, .jpeg, .png) of `set` under `corpus_dir`, absolute paths sorted by file
// name. Empty when the folder is missing. Cost: one directory listing.
std::vector<std::string> ListPhotos(const std::string& corpus_dir, const PhotoSet& set);

// The file name of a path ("left01.jpg").
std::string FileName(const std::string& path);

// The camera of a photo: the first of set.cameras its file name starts with, else "".
std::string CameraOf(const PhotoSet& set, const std::string& path);

// Whether the photo is listed in set.partial_views.
bool IsPartialView(const PhotoSet& set, const std::string& path);

// Reads the photo as grey (station/io/image_io.h: colour by BT.601 luma) and runs linecal's
// detector of `board` with its default options. Errors: the reader's, or Unimplemented for
// a board type without an image detector.
absl::StatusOr<Detection> DetectInPhoto(const std::string& path, const Board& board);

// A board in words: its type name, with cols x rows for checkers, circle grids and square
// grids ("checker 6x4", "circle_grid 4x11 asymmetric", "circle_grid 28x24 hexagonal",
// "square_grid 3x4", "apriltag").
std::string BoardLabel(const BoardParams& board);

// One board of the false-positive sweep.
struct SweepBoard {
  std::string label;  // BoardLabel: "apriltag", "checker 6x9"
  Board board;
};

// Every linecal board type with default parameters, plus the checker of each chessboard
// set's cols x rows and the circle grid of each circle set's (the corners or circles of one
// board's sub-grid must not pass for a smaller board), without duplicates. Built once.
const std::vector<SweepBoard>& SweepBoards();

// Whether a photo of `set` shows `board`: the same type, and for checkers, circle grids and
// square grids the same count up to a quarter turn (a 6 x 9 board is a 9 x 6 board turned;
// not for a hexagonal grid) and, for circle grids, the same layout (symmetric, asymmetric or
// hexagonal).
bool ShowsBoard(const PhotoSet& set, const BoardParams& board);

// A detection that should not exist.
struct FalseDetection {
  std::string photo;  // path
  std::string board;  // SweepBoard::label
  std::string why;    // "another board's photo", or the mismatch with OpenCV's corners
};

// Runs every SweepBoards() board that `set` does not show on `image`; each found = true is a
// false detection. Cost: one detection per sweep board (tens of ms at 640 x 480).
std::vector<FalseDetection> SweepPhoto(const ImageView8& image, const PhotoSet& set,
                                       const std::string& photo);

// OpenCV's detection of a set's reference pattern: the points in OpenCV's order (row-major
// over cols x rows of its pattern size), pixel-centre convention like linecal's.
struct ReferencePoints {
  bool found = false;
  int cols = 0;
  int rows = 0;
  std::vector<Eigen::Vector2d> uv_px;
};

// Runs OpenCV on the photo: findChessboardCornersSB (exhaustive, accurate) for chessboards,
// findCirclesGrid (plain, then clustering) for circle grids; found = false for
// Reference::kNone. `accurate` adds CALIB_CB_ACCURACY (OpenCV at its best, for comparing
// accuracy); without it the same boards are found in an eighth of the time (64 chessboard
// photos: 3 s against 26 s), enough to check a grid. Cost: up to 0.4 s per photo accurate.
ReferencePoints DetectReference(const ImageView8& image, const PhotoSet& set, bool accurate = true);

// How a found detection of a checker or circle grid compares with OpenCV's corners (circle
// centres) of the same photo.
struct ReferenceCheck {
  // Non-empty: the detection is false, and why. The feature list is not all cols * rows
  // ids 0..n-1 in order; or, where OpenCV found the board, a corner has no OpenCV corner
  // nearer than half the corner spacing, or the order is no symmetry of the grid (a flip or
  // a quarter turn: the colours may fix an orientation OpenCV does not know).
  std::string wrong;
  bool compared = false;  // OpenCV found the board, and the points were compared
  // Agreement, when compared and not wrong: the largest distance between a corner and its
  // OpenCV corner, and how many corners differ by more than the tolerance (an accuracy
  // disagreement, reported but not a false detection: the grid is the right one).
  double max_px = 0.0;
  int worst_id = -1;
  int beyond_tol = 0;
};

// Compares a found detection of `board` with OpenCV's `reference` of the same photo.
ReferenceCheck CheckAgainstReference(const Detection& detection, const Board& board,
                                     const ReferencePoints& reference, double tol_px = 2.0);

}  // namespace linecal::photo_corpus

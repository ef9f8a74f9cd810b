#pragma once
// Square fiducial markers (ArUco, AprilTag): finding and decoding them in an image, and
// verifying a board of them. One implementation for every marker board of docs/boards.md; the
// families differ only through MarkerFamily and the board through Board::features().
//
// Pipeline: local-contrast binarisation (a threshold halfway between the local minimum and
// maximum over tiles, as AprilTag 3 does; low-contrast areas inherit the threshold of their
// neighbours), 4-connected dark components, outer contours approximated by quads
// (detectors/common/contours.h), edge-line refinement of the quad corners, perspective-correct
// sampling of the cell grid through the quad's homography, and decoding against the whole
// family in all four rotations within a Hamming distance.
//
// Image coordinates: pixel-centre convention (docs/conventions.md). Pure functions, no state.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

#include "detectors/boards/board.h"
#include "detectors/common/homography.h"
#include "detectors/core/image_view.h"
#include "detectors/detection.h"

namespace linecal {

// A family of square markers: the cell grid, where each code bit is printed, and the codes.
struct MarkerFamily {
  int cells = 6;         // cells per side, black border included
  int border_cells = 1;  // width of the black border in cells
  // bit_cells[i] = {row, col} (0-based from the marker's top-left in its canonical
  // orientation) of code bit (bits - 1 - i); 1 = white.
  std::vector<std::array<int, 2>> bit_cells;
  std::vector<std::uint64_t> codes;  // codes[id]
  // A code read within this Hamming distance of exactly one (code, rotation) is accepted.
  int max_correction_bits = 1;
};

// One of OpenCV's predefined ArUco dictionaries (detectors/boards/aruco_dictionaries.h): (n + 2)
// x (n + 2) cells for n x n data bits, 1-cell border, at most the dictionary's maxCorrectionBits
// corrected (OpenCV's strictness). Cost: copies the codes (up to 1024).
MarkerFamily ArucoFamily(ArucoDictionary dictionary);
// ArucoFamily(DICT_4X4_50): 6 x 6 cells, at most 1 corrected bit; the station's marker boards.
MarkerFamily Aruco4x4_50Family();
// tag36h11 (libapriltag's codes) with a black border of border_bits (1 or 2) cells:
// 8 x 8 or 10 x 10 cells. At most 2 corrected bits: tag36h11's minimum distance is 11,
// so 2 leaves a margin of 7 bits against decoding a random pattern (AprilTag 3's default
// for this family). Cost: copies 587 codes.
MarkerFamily Tag36h11Family(int border_bits);

struct MarkerDetectOptions {
  // Smallest difference between the local dark and light levels (grey levels) for an area
  // to count as printed contrast; the effective value also grows with the image's noise
  // (noise_contrast_factor x the estimated noise sigma).
  int min_contrast = 12;
  // A noise sigma estimated from the image is multiplied by this. The local extremes are
  // taken over 144 means of 2 x 2 pixels (noise sigma / 2), whose range exceeds 4 sigma with
  // a probability of about 1e-4 (the range of 144 normal samples averages 5.4 of their
  // sigma, with a spread of 0.6).
  double noise_contrast_factor = 4.0;
  // Smallest marker side in pixels (docs/acceptance.md: data cells of 4 px, so an ArUco marker
  // is 24 px; a 50-degree view shortens a side to about 15 px).
  int min_marker_side_px = 12;
  // Largest number of candidate quads decoded: bounds the cost of a pathological image
  // (dense texture); a real scene has tens.
  int max_candidates = 4096;
  // Candidate quads are looked for in the dark pixels, then again after eroding them by
  // 1 .. max_erosion_px pixels: erosion separates markers that touch other dark shapes at a
  // corner (the AprilGrid's corner squares), where blur and gamma leave a bridge of a pixel
  // or two. Each erosion costs about a third of the scan. [0, 4].
  int max_erosion_px = 0;
  // After those passes, while markers are missing, the quads are looked for once more in the
  // pixels darker than the local minimum plus this fraction of the local range (0: no such
  // pass). A quiet zone under a cell wide between a marker and other dark print (the
  // round-hole board's black cells: 2.6-3.4 px at 4 px cells) keeps under half its contrast
  // under blur 1.5 and gamma 1.6, so the halfway threshold joins the marker to that print.
  // Costs a binarisation and a labelling (about 3 ms at 1280 x 720) when it runs. [0, 0.5).
  double near_dark_fraction = 0.25;
  // Whole-board check: largest homography residual relative to the mean marker side (a
  // swapped or misread marker moves corners by whole marker pitches; lens distortion over a
  // large board moves them by a few percent of a marker side at most).
  double max_residual_fraction = 0.06;
  // ... and at most this many of the markers' cells: where the cells are a few pixels, blur
  // and noise can leave a corner read from a misjudged edge half a cell off, within 6% of a
  // marker's side (detectors_eval, full grid: an ArUco board of 4 px cells under the hard
  // lighting with a corner 1.8 px off and a residual of 1.3 px). A quarter of a cell is the
  // same limit the board's placed markers keep (ReadPredictedMarker).
  double max_residual_cells = 0.25;
  // Whole-board check: at least this fraction of the board's sampled printed points
  // (black and white separately) must show that paint.
  double min_paint_agreement = 0.85;

  // Empty when every field is usable, else the name of the first bad one. O(1).
  std::string_view Validate() const;
};

// One decoded marker.
struct DecodedMarker {
  int id = 0;
  // Corners 0 top-left, 1 top-right, 2 bottom-right, 3 bottom-left of the marker in its
  // canonical orientation, sub-pixel (edge-line intersections), pixels.
  std::array<Eigen::Vector2d, 4> corners_px;
  // Corrected bits; for a marker placed by the board (VerifyMarkerBoard), the cells that
  // disagree with its print.
  int hamming = 0;
};

// Everything found in one image.
struct MarkerScan {
  DetectReason reason = DetectReason::kNone;  // kBadImage, kLowContrast, kNoCandidates, kNone
  int quads = 0;                              // candidate quads examined
  // The contrast a marker's light and dark cells had to show (options.min_contrast raised
  // for the image's noise); markers placed by the board model must show it too.
  int min_contrast = 0;
  std::vector<DecodedMarker> markers;
};

// Finds and decodes the markers of `family` in `image`. The view must be valid (the caller
// checks ImageView::Validate). enough_markers > 0: the erosion passes
// (MarkerDetectOptions::max_erosion_px) and the near-dark pass (near_dark_fraction) are
// skipped once that many markers are decoded (a board's marker count: nothing more to
// find); 0 runs them all. Cost: O(W * H) for binarisation and labelling (about 3 ms at
// 1280 x 720, plus about 3 ms per further pass) plus O(perimeter) per component and
// O(cells^2 + codes) per quad.
MarkerScan ScanMarkers(const ImageView8& image, const MarkerFamily& family,
                       const MarkerDetectOptions& options, int enough_markers = 0);

// How many cells of marker `id` of `family` (border included) disagree with what the image
// shows inside `corners_px` (the marker's corners in its canonical order, as
// DecodedMarker::corners_px): the cells are sampled through the quad's homography and judged
// against a plane of illumination plus the marker's contrast, as the markers a board places
// are. Tells a marker that was misread (its cells still show the expected print within a few
// cells) from another marker (most cells differ). nullopt when a cell leaves the image or the
// light and dark cells differ by less than min_contrast. O(cells^2).
std::optional<int> CellsDisagreeingWithMarker(const ImageView8& image, const MarkerFamily& family,
                                              int id,
                                              const std::array<Eigen::Vector2d, 4>& corners_px,
                                              double min_contrast);

// Reads marker `id` of `family` where a board model puts it, as VerifyMarkerBoard reads the
// markers the scan missed: `predicted_px` (its corners in canonical order, clockwise in the
// image) are refined on the marker's edges knowing its cells, and the marker is accepted when
// its cells show its print within the placed-marker tolerance (the larger of the family's
// correction bits and a sixth of its data bits) and no corner moved more than a quarter of a
// cell from its prediction. nullopt otherwise (not there, too blurred or small, or another
// marker). Cost: O(side + cells^2).
std::optional<DecodedMarker> ReadPlacedMarker(const ImageView8& image, const MarkerFamily& family,
                                              int id,
                                              const std::array<Eigen::Vector2d, 4>& predicted_px,
                                              double min_contrast);

// A homography through square markers' edge-located corners, with the one bias a homography
// cannot take up: a gamma after the optics' blur moves every dark-to-light edge by the same
// amount, so every marker grows or shrinks about its centre (0.7-0.8 px RMS at gamma 0.6 or 1.6
// under blur 1.5) while their pitch stays. Corner i of a marker is observed at
// H (p_board[i] + dilation_m * outward_diagonal[i]), the diagonal (+-1, +-1) in the board frame.
struct DilatedHomographyFit {
  HomographyFit fit;  // residuals of the dilated points
  double dilation_m = 0.0;
};

// Fits H and, with 3 markers or more (with two, a marker's size and their spacing are all there
// is to tell the dilation from the homography's scale), the dilation to the corners uv_px[i] of
// board points p_board[i] (`markers` markers). nullopt when a homography fit fails (sizes,
// degenerate points). O(n) per round, four rounds.
std::optional<DilatedHomographyFit> FitDilatedHomography(
    const std::vector<Eigen::Vector2d>& p_board,
    const std::vector<Eigen::Vector2d>& outward_diagonal, const std::vector<Eigen::Vector2d>& uv_px,
    std::size_t markers);

// Identifies `board` (ArUco, AprilTag or round-hole: its marker-corner features, markers of
// `family`) from the markers of `scan`, and checks the whole board: every marker id once (an id
// seen twice: below), one board homography through all their corners within the residual bound, no
// marker of another id on the board's page, and the board's printed paint where it is projected.
// Markers whose black border is under 5 px across their shortest side have their sides
// fitted to the board's blurred page (page_edge_fit.h) before they enter the homography:
// their edge-point corners are biased by the edges next to the border. Markers the scan missed (too
// small, blurred or touching other shapes for a quad to be found) are then looked for where that
// homography puts them: their corners refined on the edges, read as in the scan, and kept only when
// they decode to the expected id in the expected orientation; the homography is fitted again
// through all corners and checked. found = true when all of the board's markers pass; with 2 or
// more markers but not all: found = false, kPartial, their corners. Otherwise no features and the
// reason: kWrongBoard (markers of other ids only, another id on the page, or the paint disagrees),
// kAmbiguous (see below), kVerificationFailed (residual), kTooFewFeatures (one
// marker), scan.reason / kNoCandidates (no markers). An id seen more than once (another board
// of the same ids in view): every choice of one instance per id is verified as above, the
// instances not chosen taken for that board's print; the one choice found whole is the board
// (else the one found partly); none, two alike, or over 16 choices (more than two such boards
// whole in view): kAmbiguous. Cost per choice: O(markers) plus a fixed grid of paint probes
// (about 0.2 ms), plus O(side) per missed marker, plus about 0.4 ms per small marker fitted to
// the page.
// `sibling`: a board that prints the same markers at the same places (the ArUco board for the
// round-hole board and back), or nullptr; the board is then also told from it by the grey
// levels where the two print differently (PaintContrastPrefers on `image`, the scanned
// view), kWrongBoard when the image looks like the sibling, kAmbiguous when it cannot tell.
Detection VerifyMarkerBoard(const MarkerScan& scan, const Board& board, const MarkerFamily& family,
                            const MarkerDetectOptions& options, const ImageView8& image,
                            const Board* sibling);

// Finds `board` as ScanMarkers then VerifyMarkerBoard do, coarse to fine: the markers are
// first looked for in the image averaged over 4 x 4, then over 2 x 2 pixels (a sixteenth and
// a quarter of the pixels to binarise and label), their corners refined on the edges at full
// resolution and the board verified on the full image; the first level that finds the whole
// board gives the result. Only when none does (markers too small for the reduced images, a
// board partly out of view, no board) is the full image scanned, and its result returned.
// Cost: a fraction of the full scan when a reduced level finds the board (the larger the
// markers, the coarser the level); about 1.3 times it when none does.
Detection DetectMarkerBoard(const ImageView8& image, const Board& board, const MarkerFamily& family,
                            const MarkerDetectOptions& options, const Board* sibling,
                            int enough_markers = 0);

}  // namespace linecal

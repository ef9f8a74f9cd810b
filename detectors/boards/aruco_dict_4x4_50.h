#pragma once
// OpenCV's ArUco dictionary DICT_4X4_50, the dictionary of the station's fixed marker boards
// (the ArUco and round-hole boards print its ids 4, 11, 12 and 19): a view of the codes of
// aruco_dictionaries.h, where every predefined dictionary is (checked against OpenCV's in
// tests/detectors/boards/aruco_dict_test.cc).
//
// A marker is 6 x 6 cells: a one-cell black border around 4 x 4 data cells. Code layout, in
// the marker's canonical orientation (as OpenCV draws it with drawMarker): bit 15 (the most
// significant) is the data cell at row 0, column 0 (top-left), then row-major, i.e. the cell
// (row, col) is bit 15 - (4 * row + col). A set bit is a white cell.

#include <cstdint>
#include <span>

#include "detectors/boards/aruco_dictionaries.h"
#include "detectors/boards/aruco_dictionary_codes.h"

namespace linecal {

// Data cells per marker side.
inline constexpr int kAruco4x4DataBits = 4;
// Cells per marker side: the data cells plus the one-cell black border on each side.
inline constexpr int kAruco4x4MarkerCells = kAruco4x4DataBits + 2;
// OpenCV's maxCorrectionBits for DICT_4X4_50: a detector may correct at most this many
// flipped bits and still be as strict as OpenCV.
inline constexpr int kAruco4x4_50MaxCorrectionBits = 1;

// The 50 codes: the first 50 of DICT_4X4_1000, as in OpenCV.
inline constexpr std::span<const std::uint64_t, 50> kAruco4x4_50Codes(kAruco4x4Codes.data(), 50);

// True when data cell (row, col), 0..3 each, of `code` is white. O(1).
inline constexpr bool Aruco4x4CellIsWhite(std::uint64_t code, int row, int col) {
  return ArucoCellIsWhite(code, kAruco4x4DataBits, row, col);
}

}  // namespace linecal

#pragma once
// OpenCV's ArUco dictionary DICT_4X4_50 as data: the 50 marker codes, facts from OpenCV's
// published predefined dictionaries (tests/detectors/boards/aruco_dict_test.cc checks all 50
// against cv::aruco::getPredefinedDictionary, and the board PDFs carry ids 4, 11, 12 and 19).
//
// A marker is 6 x 6 cells: a one-cell black border around 4 x 4 data cells. Code layout, in
// the marker's canonical orientation (as OpenCV draws it with drawMarker): bit 15 (the most
// significant) is the data cell at row 0, column 0 (top-left), then row-major, i.e. the cell
// (row, col) is bit 15 - (4 * row + col). A set bit is a white cell.

#include <array>
#include <cstdint>

namespace linecal {

// Data cells per marker side.
inline constexpr int kAruco4x4DataBits = 4;
// Cells per marker side: the data cells plus the one-cell black border on each side.
inline constexpr int kAruco4x4MarkerCells = kAruco4x4DataBits + 2;
// OpenCV's maxCorrectionBits for DICT_4X4_50: a detector may correct at most this many
// flipped bits and still be as strict as OpenCV.
inline constexpr int kAruco4x4_50MaxCorrectionBits = 1;

inline constexpr std::array<std::uint16_t, 50> kAruco4x4_50Codes = {
    0xB532, 0x0F9A, 0x332D, 0x9946, 0x549E, 0x79CD, 0x9E2E, 0xC4F2, 0xFEDA, 0xCF56,  //  0- 9
    0xF991, 0x11A7, 0x0EB7, 0x2A0F, 0x24B1, 0x263E, 0x4665, 0x6600, 0x6C5E, 0x76AF,  // 10-19
    0x868B, 0xB02B, 0xCCD5, 0xDD82, 0xFE47, 0x9471, 0xACE4, 0xA554, 0x2123, 0x346F,  // 20-29
    0x4415, 0x57B2, 0x9ECF, 0xF0CB, 0x08AE, 0x0929, 0x1875, 0x04FF, 0x0DF6, 0x1C5A,  // 30-39
    0x1718, 0x2A28, 0x328C, 0x38B2, 0x24E8, 0x2EEB, 0x2D3F, 0x4B64, 0x502E, 0x5013,  // 40-49
};

// True when data cell (row, col), 0..3 each, of `code` is white. O(1).
inline constexpr bool Aruco4x4CellIsWhite(std::uint16_t code, int row, int col) {
  return ((code >> (15 - (kAruco4x4DataBits * row + col))) & 1u) != 0;
}

}  // namespace linecal

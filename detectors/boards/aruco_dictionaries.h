#pragma once
// OpenCV's predefined ArUco dictionaries (cv::aruco::PREDEFINED_DICTIONARY_NAME) as data: their
// names, marker sizes, marker counts and maxCorrectionBits, over the codes of
// aruco_dictionary_codes.h (included by aruco_dictionaries.cc only: a few thousand constants) (each
// family stored once: OpenCV's DICT_nXn_50, _100 and _250 are the first markers of DICT_nXn_1000).
// tests/detectors/boards/aruco_dict_test.cc checks every code and every figure against
// cv::aruco::getPredefinedDictionary.
//
// A marker of n x n data bits is (n + 2) x (n + 2) cells: a one-cell black border around the
// data cells. Code layout, in the marker's canonical orientation (as OpenCV draws it): the cell
// (row, col) of the data is bit n * n - 1 - (n * row + col); a set bit is a white cell.

#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

namespace linecal {

// In OpenCV's order (DICT_4X4_50 = 0 ... DICT_ARUCO_ORIGINAL = 16).
enum class ArucoDictionary : std::uint8_t {
  k4x4_50,
  k4x4_100,
  k4x4_250,
  k4x4_1000,
  k5x5_50,
  k5x5_100,
  k5x5_250,
  k5x5_1000,
  k6x6_50,
  k6x6_100,
  k6x6_250,
  k6x6_1000,
  k7x7_50,
  k7x7_100,
  k7x7_250,
  k7x7_1000,
  kArucoOriginal,
};

struct ArucoDictionaryInfo {
  ArucoDictionary dictionary = ArucoDictionary::k4x4_50;
  const char* name = "";  // OpenCV's, e.g. "DICT_5X5_100"
  int data_bits = 0;      // data cells per marker side (OpenCV's markerSize)
  // OpenCV's maxCorrectionBits: a detector that corrects at most this many flipped bits is
  // as strict as OpenCV's.
  int max_correction_bits = 0;
  std::span<const std::uint64_t> codes;  // codes[id], one per marker (OpenCV's bytesList rows)

  int marker_count() const { return static_cast<int>(codes.size()); }
  // Cells per marker side: the data cells plus the one-cell border on each side.
  int marker_cells() const { return data_bits + 2; }
};

// Every dictionary, indexed by its enum value (OpenCV's order). O(1).
std::span<const ArucoDictionaryInfo> AllArucoDictionaries();

// The dictionary's figures and codes. `dictionary` must be one of the enumerators. O(1).
const ArucoDictionaryInfo& ArucoDictionaryInfoOf(ArucoDictionary dictionary);

// The dictionary of OpenCV's name ("DICT_6X6_250"); nullopt for any other text. Case-sensitive,
// as OpenCV's enumerators. O(dictionaries).
std::optional<ArucoDictionary> ArucoDictionaryFromName(std::string_view name);

// True when data cell (row, col), 0..data_bits-1 each, of `code` is white. O(1).
inline constexpr bool ArucoCellIsWhite(std::uint64_t code, int data_bits, int row, int col) {
  return ((code >> (data_bits * data_bits - 1 - (data_bits * row + col))) & 1u) != 0;
}

}  // namespace linecal

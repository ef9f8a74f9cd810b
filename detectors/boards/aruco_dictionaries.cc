#include "detectors/boards/aruco_dictionaries.h"

#include <array>

#include "detectors/boards/aruco_dictionary_codes.h"

namespace linecal {
namespace {

// The figures are OpenCV 4.6's (predefined_dictionaries.hpp, dictionary.cpp), checked against
// cv::aruco::getPredefinedDictionary by tests/detectors/boards/aruco_dict_test.cc.
constexpr std::array<ArucoDictionaryInfo, 17> kDictionaries = {{
    {ArucoDictionary::k4x4_50, "DICT_4X4_50", 4, 1, std::span(kAruco4x4Codes).first(50)},
    {ArucoDictionary::k4x4_100, "DICT_4X4_100", 4, 1, std::span(kAruco4x4Codes).first(100)},
    {ArucoDictionary::k4x4_250, "DICT_4X4_250", 4, 1, std::span(kAruco4x4Codes).first(250)},
    {ArucoDictionary::k4x4_1000, "DICT_4X4_1000", 4, 0, std::span(kAruco4x4Codes)},
    {ArucoDictionary::k5x5_50, "DICT_5X5_50", 5, 3, std::span(kAruco5x5Codes).first(50)},
    {ArucoDictionary::k5x5_100, "DICT_5X5_100", 5, 3, std::span(kAruco5x5Codes).first(100)},
    {ArucoDictionary::k5x5_250, "DICT_5X5_250", 5, 2, std::span(kAruco5x5Codes).first(250)},
    {ArucoDictionary::k5x5_1000, "DICT_5X5_1000", 5, 2, std::span(kAruco5x5Codes)},
    {ArucoDictionary::k6x6_50, "DICT_6X6_50", 6, 6, std::span(kAruco6x6Codes).first(50)},
    {ArucoDictionary::k6x6_100, "DICT_6X6_100", 6, 5, std::span(kAruco6x6Codes).first(100)},
    {ArucoDictionary::k6x6_250, "DICT_6X6_250", 6, 5, std::span(kAruco6x6Codes).first(250)},
    {ArucoDictionary::k6x6_1000, "DICT_6X6_1000", 6, 4, std::span(kAruco6x6Codes)},
    {ArucoDictionary::k7x7_50, "DICT_7X7_50", 7, 9, std::span(kAruco7x7Codes).first(50)},
    {ArucoDictionary::k7x7_100, "DICT_7X7_100", 7, 8, std::span(kAruco7x7Codes).first(100)},
    {ArucoDictionary::k7x7_250, "DICT_7X7_250", 7, 8, std::span(kAruco7x7Codes).first(250)},
    {ArucoDictionary::k7x7_1000, "DICT_7X7_1000", 7, 6, std::span(kAruco7x7Codes)},
    {ArucoDictionary::kArucoOriginal, "DICT_ARUCO_ORIGINAL", 5, 0, std::span(kArucoOriginalCodes)},
}};

}  // namespace

std::span<const ArucoDictionaryInfo> AllArucoDictionaries() { return kDictionaries; }

const ArucoDictionaryInfo& ArucoDictionaryInfoOf(ArucoDictionary dictionary) {
  return kDictionaries[static_cast<std::size_t>(dictionary)];
}

std::optional<ArucoDictionary> ArucoDictionaryFromName(std::string_view name) {
  for (const ArucoDictionaryInfo& info : kDictionaries) {
    if (name == info.name) return info.dictionary;
  }
  return std::nullopt;
}

}  // namespace linecal

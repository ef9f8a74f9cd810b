// The codes and figures of every predefined dictionary of detectors/boards/aruco_dictionaries.h
// (and its DICT_4X4_50 view, aruco_dict_4x4_50.h) against OpenCV's own dictionaries (OpenCV is
// allowed in tests: it is the reference, not a dependency).
#include <gtest/gtest.h>

#include <opencv2/aruco.hpp>

#include "detectors/boards/aruco_dict_4x4_50.h"
#include "detectors/boards/aruco_dictionaries.h"

namespace linecal {
namespace {

TEST(ArucoDict4x4_50, AllFiftyCodesMatchOpenCv) {
  const cv::Ptr<cv::aruco::Dictionary> dict =
      cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50);
  ASSERT_EQ(dict->bytesList.rows, 50);
  ASSERT_EQ(dict->markerSize, kAruco4x4DataBits);
  EXPECT_EQ(dict->maxCorrectionBits, kAruco4x4_50MaxCorrectionBits);
  for (int id = 0; id < 50; ++id) {
    // getBitsFromByteList gives the canonical (rotation 0) data bits, 1 = white.
    const cv::Mat bits =
        cv::aruco::Dictionary::getBitsFromByteList(dict->bytesList.rowRange(id, id + 1), 4);
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) {
        EXPECT_EQ(Aruco4x4CellIsWhite(kAruco4x4_50Codes[id], r, c), bits.at<uchar>(r, c) != 0)
            << "id " << id << " cell " << r << "," << c;
      }
    }
  }
}

TEST(ArucoDict4x4_50, DrawnMarkerMatchesCodes) {
  // drawMarker at one pixel per cell: border black, data as the code says.
  const cv::Ptr<cv::aruco::Dictionary> dict =
      cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50);
  for (int id : {4, 11, 12, 19}) {  // the ids on the ArUco and round-hole boards
    cv::Mat img;
    cv::aruco::drawMarker(dict, id, kAruco4x4MarkerCells, img, 1);
    for (int r = 0; r < kAruco4x4MarkerCells; ++r) {
      for (int c = 0; c < kAruco4x4MarkerCells; ++c) {
        const bool border = r == 0 || c == 0 || r == 5 || c == 5;
        const bool white = !border && Aruco4x4CellIsWhite(kAruco4x4_50Codes[id], r - 1, c - 1);
        EXPECT_EQ(img.at<uchar>(r, c), white ? 255 : 0) << "id " << id << " " << r << "," << c;
      }
    }
  }
}

// Every dictionary: OpenCV's name (and enum value), marker size, marker count and
// maxCorrectionBits, and every marker's data cells.
TEST(ArucoDictionaries, EveryDictionaryMatchesOpenCv) {
  ASSERT_EQ(AllArucoDictionaries().size(), 17u);
  for (std::size_t i = 0; i < AllArucoDictionaries().size(); ++i) {
    const ArucoDictionaryInfo& info = AllArucoDictionaries()[i];
    SCOPED_TRACE(info.name);
    EXPECT_EQ(static_cast<std::size_t>(info.dictionary), i);
    EXPECT_EQ(ArucoDictionaryFromName(info.name), info.dictionary);
    const cv::Ptr<cv::aruco::Dictionary> dict = cv::aruco::getPredefinedDictionary(
        static_cast<cv::aruco::PREDEFINED_DICTIONARY_NAME>(static_cast<int>(info.dictionary)));
    ASSERT_EQ(dict->bytesList.rows, info.marker_count());
    ASSERT_EQ(dict->markerSize, info.data_bits);
    EXPECT_EQ(info.marker_cells(), info.data_bits + 2);
    EXPECT_EQ(dict->maxCorrectionBits, info.max_correction_bits);
    const int n = info.data_bits;
    int wrong = 0;
    for (int id = 0; id < info.marker_count(); ++id) {
      const cv::Mat bits =
          cv::aruco::Dictionary::getBitsFromByteList(dict->bytesList.rowRange(id, id + 1), n);
      for (int r = 0; r < n; ++r) {
        for (int c = 0; c < n; ++c) {
          wrong += ArucoCellIsWhite(info.codes[id], n, r, c) != (bits.at<uchar>(r, c) != 0);
        }
      }
    }
    EXPECT_EQ(wrong, 0);
  }
  EXPECT_EQ(ArucoDictionaryFromName("DICT_5X5_100"), ArucoDictionary::k5x5_100);
  EXPECT_EQ(ArucoDictionaryFromName("DICT_ARUCO_ORIGINAL"), ArucoDictionary::kArucoOriginal);
  EXPECT_FALSE(ArucoDictionaryFromName("dict_5x5_100").has_value());
  EXPECT_FALSE(ArucoDictionaryFromName("DICT_APRILTAG_36h11").has_value());
}

// OpenCV's _50, _100 and _250 dictionaries are the first markers of its _1000 one, which is
// why each family's codes are stored once.
TEST(ArucoDictionaries, SmallerDictionariesArePrefixesOfTheThousand) {
  for (int family = 0; family < 4; ++family) {
    const cv::Ptr<cv::aruco::Dictionary> all = cv::aruco::getPredefinedDictionary(
        static_cast<cv::aruco::PREDEFINED_DICTIONARY_NAME>(4 * family + 3));
    for (int size = 0; size < 3; ++size) {
      const cv::Ptr<cv::aruco::Dictionary> dict = cv::aruco::getPredefinedDictionary(
          static_cast<cv::aruco::PREDEFINED_DICTIONARY_NAME>(4 * family + size));
      SCOPED_TRACE(AllArucoDictionaries()[4 * family + size].name);
      EXPECT_EQ(
          cv::norm(dict->bytesList, all->bytesList.rowRange(0, dict->bytesList.rows), cv::NORM_INF),
          0.0);
      EXPECT_EQ(AllArucoDictionaries()[4 * family + size].codes.data(),
                AllArucoDictionaries()[4 * family + 3].codes.data());
    }
  }
}

// drawMarker of a marker of each marker size at one pixel per cell: border black, data as the
// code says.
TEST(ArucoDictionaries, DrawnMarkersMatchTheCodes) {
  for (const ArucoDictionary d : {ArucoDictionary::k5x5_100, ArucoDictionary::k6x6_250,
                                  ArucoDictionary::k7x7_1000, ArucoDictionary::kArucoOriginal}) {
    const ArucoDictionaryInfo& info = ArucoDictionaryInfoOf(d);
    SCOPED_TRACE(info.name);
    const cv::Ptr<cv::aruco::Dictionary> dict = cv::aruco::getPredefinedDictionary(
        static_cast<cv::aruco::PREDEFINED_DICTIONARY_NAME>(static_cast<int>(d)));
    const int cells = info.marker_cells();
    for (const int id : {0, 17, info.marker_count() - 1}) {
      cv::Mat img;
      cv::aruco::drawMarker(dict, id, cells, img, 1);
      for (int r = 0; r < cells; ++r) {
        for (int c = 0; c < cells; ++c) {
          const bool border = r == 0 || c == 0 || r == cells - 1 || c == cells - 1;
          const bool white =
              !border && ArucoCellIsWhite(info.codes[id], info.data_bits, r - 1, c - 1);
          EXPECT_EQ(img.at<uchar>(r, c), white ? 255 : 0) << "id " << id << " " << r << "," << c;
        }
      }
    }
  }
}

}  // namespace
}  // namespace linecal

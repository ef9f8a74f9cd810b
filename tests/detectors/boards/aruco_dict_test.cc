// The DICT_4X4_50 codes of detectors/boards/aruco_dict_4x4_50.h against OpenCV's own
// dictionary (OpenCV is allowed in tests: it is the reference, not a dependency).
#include <gtest/gtest.h>

#include <opencv2/aruco.hpp>

#include "detectors/boards/aruco_dict_4x4_50.h"

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

}  // namespace
}  // namespace linecal

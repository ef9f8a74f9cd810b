#include "detectors/core/image_view.h"

#include <gtest/gtest.h>

#include <cstring>

namespace linecal {
namespace {

TEST(ImageViewTest, PackedImageIsValid) {
  Image8 img(4, 3, 7);
  img.at(2, 1) = 200;
  const ImageView8 v = img.view();
  EXPECT_EQ(v.Validate(), ImageViewError::kOk);
  EXPECT_EQ(v.At(2, 1), 200);
  EXPECT_EQ(v.At(0, 0), 7);
}

TEST(ImageViewTest, StrideSkipsPadding) {
  // A 3x2 16-bit image in rows of 5 pixels (padding as some camera drivers deliver it).
  std::uint16_t buf[10] = {1, 2, 3, 0, 0, 4, 5, 6, 0, 0};
  const ImageView16 v{buf, 3, 2, 5 * sizeof(std::uint16_t)};
  ASSERT_EQ(v.Validate(), ImageViewError::kOk);
  EXPECT_EQ(v.At(0, 1), 4);
  EXPECT_EQ(v.At(2, 1), 6);
}

TEST(ImageViewTest, RejectsBadViews) {
  std::uint8_t b[16] = {};
  std::uint16_t w[16] = {};
  EXPECT_EQ((ImageView8{b, 0, 4, 4}.Validate()), ImageViewError::kEmpty);
  EXPECT_EQ((ImageView8{b, -1, 4, 4}.Validate()), ImageViewError::kNegativeSize);
  EXPECT_EQ((ImageView8{nullptr, 2, 2, 2}.Validate()), ImageViewError::kNullData);
  EXPECT_EQ((ImageView8{b, 4, 4, 3}.Validate()), ImageViewError::kStrideTooSmall);
  EXPECT_EQ((ImageView16{w, 2, 2, 5}.Validate()), ImageViewError::kStrideMisaligned);
  EXPECT_EQ((ImageView8{b, 20000, 20000, 20000}.Validate()), ImageViewError::kTooLarge);
  EXPECT_STREQ(ImageViewErrorName(ImageViewError::kStrideTooSmall), "stride_too_small");
}

}  // namespace
}  // namespace linecal

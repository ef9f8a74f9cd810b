// The shared binarisation (detectors/common/binarise.h) on synthetic images with known
// levels: the local threshold's fraction of the range, flat areas, the noise estimate and
// the erosion.
#include "detectors/common/binarise.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace linecal {
namespace {

// A dark page (40) with a light square (200) from x = 48, and a vertical ridge of `ridge`
// grey levels at x = 44, within the 12 px threshold window of the square: a quiet zone
// between two dark shapes that blur has left at part of its contrast.
Image8 PageWithRidge(int ridge) {
  Image8 image(96, 64, 40);
  for (int y = 16; y < 48; ++y) {
    for (int x = 48; x < 80; ++x) image.at(x, y) = 200;
  }
  for (int y = 0; y < 64; ++y) image.at(44, y) = static_cast<std::uint8_t>(ridge);
  return image;
}

TEST(BinariseTest, TheDarkFractionDecidesWhetherAFaintRidgeSeparatesDarkShapes) {
  // 40 + 0.4 * 160: a ridge at 40% of the local range.
  const Image8 image = PageWithRidge(104);
  int max_contrast = 0;
  const Image8 halfway = BinariseDark(image.view(), 12, &max_contrast);
  EXPECT_EQ(max_contrast, 160);
  const Image8 near_dark = BinariseDark(image.view(), 12, &max_contrast, 0.25);
  // Near the light square (its tiles within reach), the ridge is dark at halfway and light
  // at a quarter of the range; the square is light and the page dark either way.
  for (int y = 20; y < 44; ++y) {
    EXPECT_EQ(halfway.at(44, y), 1) << y;
    EXPECT_EQ(near_dark.at(44, y), 0) << y;
    EXPECT_EQ(halfway.at(60, y), 0) << y;
    EXPECT_EQ(near_dark.at(60, y), 0) << y;
    EXPECT_EQ(halfway.at(38, y), 1) << y;
    EXPECT_EQ(near_dark.at(38, y), 1) << y;
  }
}

TEST(BinariseTest, AFlatImageHasNoContrastAndNothingDark) {
  const Image8 flat(64, 48, 128);
  int max_contrast = -1;
  const Image8 dark = BinariseDark(flat.view(), 12, &max_contrast);
  EXPECT_EQ(max_contrast, 0);
  for (const std::uint8_t v : dark.pixels) ASSERT_EQ(v, 0);
}

TEST(BinariseTest, NoiseEstimateFollowsGaussianNoiseAndIgnoresEdges) {
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 5.0);
  Image8 image(320, 240);
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      // Printed edges every 40 px: a robust estimate must not see them as noise.
      const double base = ((x / 40 + y / 40) % 2 == 0) ? 60.0 : 190.0;
      image.at(x, y) = static_cast<std::uint8_t>(std::lround(base + noise(rng)));
    }
  }
  EXPECT_NEAR(EstimateNoiseSigma(image.view()), 5.0, 0.5);
  EXPECT_EQ(EstimateNoiseSigma(Image8(2, 2, 9).view()), 0.0);
}

TEST(BinariseTest, ErosionBreaksAOnePixelBridge) {
  Image8 binary(20, 10, 0);
  for (int y = 2; y < 8; ++y) {
    for (int x = 2; x < 8; ++x) binary.at(x, y) = 1;
    for (int x = 12; x < 18; ++x) binary.at(x, y) = 1;
  }
  for (int x = 8; x < 12; ++x) binary.at(x, 5) = 1;  // the bridge
  const Image8 eroded = Erode(binary);
  for (int x = 8; x < 12; ++x) EXPECT_EQ(eroded.at(x, 5), 0) << x;
  EXPECT_EQ(eroded.at(4, 4), 1);
  EXPECT_EQ(eroded.at(14, 4), 1);
  EXPECT_EQ(eroded.at(2, 4), 0);  // the shapes' own border goes too
}

}  // namespace
}  // namespace linecal

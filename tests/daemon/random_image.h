#pragma once
// Test images of uniformly random pixels: every pixel differs from its neighbours, so a
// frame that lost, shifted or mixed any part of the image does not compare equal.

#include <cstdint>
#include <random>

#include "detectors/core/image_view.h"

namespace linecal {

inline Image8 RandomImage(int width, int height, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> value(0, 255);
  Image8 image(width, height);
  for (auto& p : image.pixels) p = static_cast<std::uint8_t>(value(rng));
  return image;
}

}  // namespace linecal

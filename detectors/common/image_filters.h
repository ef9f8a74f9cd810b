#pragma once
// Image filters for the board detectors: a float image, separable Gaussian blur, and
// bilinear sampling. Pixel (x, y) has its centre at image coordinate (u, v) = (x, y)
// (conventions.md); borders are handled by clamping (replicating the edge pixel).

#include <vector>

#include <Eigen/Core>

#include "detectors/core/image_view.h"

namespace linecal {

// A tightly packed float image (grey levels of the source, not rescaled).
struct ImageF {
  int width = 0;
  int height = 0;
  std::vector<float> pixels;

  ImageF() = default;
  ImageF(int w, int h) : width(w), height(h), pixels(static_cast<std::size_t>(w) * h, 0.0f) {}
  float at(int x, int y) const { return pixels[static_cast<std::size_t>(y) * width + x]; }
  float& at(int x, int y) { return pixels[static_cast<std::size_t>(y) * width + x]; }
  const float* Row(int y) const { return pixels.data() + static_cast<std::size_t>(y) * width; }
  float* Row(int y) { return pixels.data() + static_cast<std::size_t>(y) * width; }
};

// The image blurred by a Gaussian of sigma_px (the kernel is cut at 3 sigma, where its tail
// holds 0.3 % of the weight). sigma_px <= 0 copies the image. The view must be valid
// (ImageView::Validate() == kOk). Cost: O(width * height * sigma) (two 1-D passes);
// about 3 ms for 1280 x 720 at sigma 1.5.
ImageF GaussianBlur(const ImageView8& image, double sigma_px);

// The bilinear interpolation of `image` at (u, v), pixel-centre convention; coordinates
// outside the image are clamped to its border. The image must not be empty. O(1).
float SampleBilinear(const ImageF& image, double u, double v);

}  // namespace linecal

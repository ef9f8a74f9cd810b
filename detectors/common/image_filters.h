#pragma once
// Image filters for the board detectors: a float image, separable Gaussian blur, and
// bilinear sampling. Pixel (x, y) has its centre at image coordinate (u, v) = (x, y)
// (docs/conventions.md); borders are handled by clamping (replicating the edge pixel).

#include <Eigen/Core>
#include <algorithm>
#include <vector>

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

// The brightest minus the darkest pixel of the (valid) view, grey levels: bounds the
// contrast of anything in it, blurred or not. Cost: one pass over the image (vectorised).
int GreyRange(const ImageView8& image);

// The image blurred by a Gaussian of sigma_px (the kernel is cut at 3 sigma, where its tail
// holds 0.3 % of the weight). sigma_px <= 0 copies the image. The view must be valid
// (ImageView::Validate() == kOk). Cost: O(width * height * sigma) (two 1-D passes);
// about 3 ms for 1280 x 720 at sigma 1.5.
ImageF GaussianBlur(const ImageView8& image, double sigma_px);

// The image at half resolution: pixel (x, y) is the rounded mean of the 2 x 2 block
// (2x..2x+1, 2y..2y+1), so its centre lies at (2x + 0.5, 2y + 0.5) in the input (an odd last
// row or column is dropped). The view must be valid and at least 2 x 2. The 2 x 2 mean is
// all the anti-aliasing the corner search needs: it blurs the half image again (sigma 1.5
// px) before taking derivatives. Cost: one pass over the input, O(width * height).
Image8 HalveImage(const ImageView8& image);

// The coarse levels of a coarse-to-fine search: levels[k - 1] is the image halved k times
// (HalveImage), for every k >= 1 whose short side keeps at least min_short_side_px pixels;
// empty when even the first halving would go below. Cost: 1/3 of a pass over the image.
std::vector<Image8> HalvingPyramid(const ImageView8& image, int min_short_side_px);

// A point of pyramid level `level` (0: the image itself; k: halved k times) in the image's
// own pixel coordinates: a level-k pixel spans 2^k input pixels, its centre sits at
// 2^k u + (2^k - 1) / 2. O(1).
Eigen::Vector2d LevelToImage(const Eigen::Vector2d& uv_level, int level);

// The bilinear interpolation of `image` at (u, v), pixel-centre convention; coordinates
// outside the image are clamped to its border. The image must not be empty. O(1). Inline:
// the corner tests call it thousands of times per frame (32 per response peak).
inline float SampleBilinear(const ImageF& image, double u, double v) {
  u = std::clamp(u, 0.0, static_cast<double>(image.width - 1));
  v = std::clamp(v, 0.0, static_cast<double>(image.height - 1));
  const int x0 = std::min(static_cast<int>(u), image.width - 2 < 0 ? 0 : image.width - 2);
  const int y0 = std::min(static_cast<int>(v), image.height - 2 < 0 ? 0 : image.height - 2);
  const int x1 = std::min(x0 + 1, image.width - 1);
  const int y1 = std::min(y0 + 1, image.height - 1);
  const float fx = static_cast<float>(u - x0);
  const float fy = static_cast<float>(v - y0);
  const float top = image.at(x0, y0) + fx * (image.at(x1, y0) - image.at(x0, y0));
  const float bottom = image.at(x0, y1) + fx * (image.at(x1, y1) - image.at(x0, y1));
  return top + fy * (bottom - top);
}

}  // namespace linecal

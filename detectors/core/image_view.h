#pragma once
// Non-owning views of grey images, and a small owning image for those who need one.
//
// Pixel (x, y) of a view is at byte offset y * stride_bytes + x * sizeof(T) from `data`; its
// centre is image coordinate (u, v) = (x, y) (docs/conventions.md). Views never own memory: the
// caller keeps the buffer alive while a view of it is used.

#include <cstddef>
#include <cstdint>
#include <vector>

namespace linecal {

// Largest accepted width or height. A real station camera is at most a few thousand pixels
// wide; the limit makes a corrupt header fail fast instead of allocating gigabytes.
inline constexpr int kMaxImageSide = 16384;

enum class ImageViewError {
  kOk = 0,
  kNullData,          // data == nullptr with a non-zero size
  kEmpty,             // width or height is 0
  kNegativeSize,      // width or height below 0
  kTooLarge,          // width or height above kMaxImageSide
  kStrideTooSmall,    // stride_bytes < width * sizeof(T)
  kStrideMisaligned,  // stride_bytes not a multiple of sizeof(T)
};

// A short, stable text for each error ("stride_too_small", ...), for reasons and messages.
const char* ImageViewErrorName(ImageViewError e);

template <typename T>
struct ImageView {
  static_assert(sizeof(T) == 1 || sizeof(T) == 2, "grey images are 8 or 16 bit");

  const T* data = nullptr;
  int width = 0;
  int height = 0;
  std::ptrdiff_t stride_bytes = 0;

  // O(1). Callers index only views for which Validate() is kOk.
  const T* Row(int y) const {
    return reinterpret_cast<const T*>(reinterpret_cast<const std::uint8_t*>(data) +
                                      y * stride_bytes);
  }
  T At(int x, int y) const { return Row(y)[x]; }

  ImageViewError Validate() const {
    if (width < 0 || height < 0) return ImageViewError::kNegativeSize;
    if (width == 0 || height == 0) return ImageViewError::kEmpty;
    if (width > kMaxImageSide || height > kMaxImageSide) return ImageViewError::kTooLarge;
    if (data == nullptr) return ImageViewError::kNullData;
    if (stride_bytes % static_cast<std::ptrdiff_t>(sizeof(T)) != 0) {
      return ImageViewError::kStrideMisaligned;
    }
    if (stride_bytes < static_cast<std::ptrdiff_t>(width * sizeof(T))) {
      return ImageViewError::kStrideTooSmall;
    }
    return ImageViewError::kOk;
  }
};

using ImageView8 = ImageView<std::uint8_t>;
using ImageView16 = ImageView<std::uint16_t>;

// A tightly packed owning grey image. Allocates width * height pixels; the caller checks the
// size against kMaxImageSide before constructing one from untrusted input.
template <typename T>
struct Image {
  int width = 0;
  int height = 0;
  std::vector<T> pixels;

  Image() = default;
  Image(int w, int h, T fill = T{})
      : width(w), height(h), pixels(static_cast<std::size_t>(w) * h, fill) {}

  T& at(int x, int y) { return pixels[static_cast<std::size_t>(y) * width + x]; }
  T at(int x, int y) const { return pixels[static_cast<std::size_t>(y) * width + x]; }

  ImageView<T> view() const {
    return ImageView<T>{pixels.data(), width, height,
                        static_cast<std::ptrdiff_t>(width * sizeof(T))};
  }
};

using Image8 = Image<std::uint8_t>;
using Image16 = Image<std::uint16_t>;

}  // namespace linecal

#pragma once
// Image files: reading PNG and JPEG into grey images, writing grey and RGB PNG.
//
// Readers take PNG (1-16 bit, grey, grey+alpha, palette, RGB, RGBA; interlaced or not) and
// JPEG (baseline or progressive, grey or YCbCr), recognised by their signature, not by the
// file name. Colour becomes grey with the ITU-R BT.601 luma weights
// (0.299 R + 0.587 G + 0.114 B, as OpenCV's RGB2GRAY); alpha and transparency are dropped.
// Every error is a status whose message names the file and the problem
// ("img.png: too large: 20000 x 10 pixels (max 16384 per side)"); images wider or taller
// than kMaxImageSide are refused from the header, before any pixel memory is allocated.
//
// Cost: one decode of the file; memory about twice the decoded image.

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "detectors/core/image_view.h"
#include "station/io/input_budget.h"

namespace linecal {

// A tightly packed 8-bit RGB image, for drawings (overlays, figures). Pixel (x, y) is
// rgb[3 * (y * width + x) + {0, 1, 2}].
struct RgbImage {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> rgb;

  RgbImage() = default;
  RgbImage(int w, int h, std::array<std::uint8_t, 3> fill = {0, 0, 0});

  std::uint8_t* at(int x, int y) { return &rgb[3 * (static_cast<std::size_t>(y) * width + x)]; }
  const std::uint8_t* at(int x, int y) const {
    return &rgb[3 * (static_cast<std::size_t>(y) * width + x)];
  }
};

struct PngWriteOptions {
  // > 0: written as the pHYs chunk (pixels per metre, both axes), so that a printer or a
  // viewer knows the physical size. 0: no pHYs chunk.
  double pixels_per_metre = 0.0;
};

// Reads a PNG or JPEG file as 8-bit grey. 16-bit samples are rounded to 8 bits (v / 257).
// Errors: NotFound (no such file), InvalidArgument (not PNG/JPEG, corrupt, unsupported
// colour space such as CMYK JPEG, too large).
absl::StatusOr<Image8> ReadImage8(const std::string& path);

// ReadImage8 under a budget (station/io/input_budget.h): a file of more than
// budget.max_file_bytes (from stat) or an image of more than budget.max_image_pixels (from its
// header, before any pixel memory is allocated) is refused with OverBudget's InvalidArgument.
// Memory: at most about 7 bytes a pixel of the budget (a 16-bit RGB decode plus the result).
absl::StatusOr<Image8> ReadImage8(const std::string& path, const InputBudget& budget);

// ReadImage8 of a file's bytes in memory (an upload); `name` stands for the file in messages
// ("photo: not a PNG or JPEG file"). The budget's max_file_bytes applies to bytes.size().
absl::StatusOr<Image8> DecodeImage8(std::string_view bytes, const std::string& name,
                                    const InputBudget& budget);

// Reads a PNG or JPEG file as 16-bit grey. 16-bit PNG samples are kept; 8-bit samples v
// become v * 257 (so 255 maps to 65535). Errors as ReadImage8.
absl::StatusOr<Image16> ReadImage16(const std::string& path);

// Write grey or RGB PNG files (overwriting `path`). The view must be valid
// (ImageView::Validate). On failure the partial file is removed. Errors: InvalidArgument
// for an invalid view, Internal/PermissionDenied/NotFound-style errors from the file system
// with the path in the message.
absl::Status WritePng8(const std::string& path, const ImageView8& image,
                       const PngWriteOptions& options = {});
absl::Status WritePng16(const std::string& path, const ImageView16& image,
                        const PngWriteOptions& options = {});
absl::Status WritePngRgb(const std::string& path, const RgbImage& image,
                         const PngWriteOptions& options = {});

// The PNG file WritePngRgb writes (without pHYs), as bytes in memory: an image sent over the
// network. `name` stands for the image in messages. Errors as WritePngRgb's.
absl::StatusOr<std::string> EncodePngRgb(const RgbImage& image, const std::string& name);

}  // namespace linecal

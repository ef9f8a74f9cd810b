#pragma once
// Writing JPEG files for tests (the project itself only reads JPEG: station/io/image_io.h):
// what a camera or a phone would have written, through libjpeg's defaults (4:2:0 chroma
// for colour).

// jpeglib.h needs <cstdio> (FILE) before it.
// clang-format off
#include <cstdio>
#include <jpeglib.h>
// clang-format on
#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <string>

namespace linecal::testing_jpeg {

// Writes packed 8-bit rows as a JPEG: components 1 (grey) or 3 (RGB). A file that cannot be
// opened fails the calling test.
inline void WriteJpeg(const std::string& path, int w, int h, int components,
                      const std::uint8_t* pixels, int quality) {
  jpeg_compress_struct cinfo{};
  jpeg_error_mgr err;
  cinfo.err = jpeg_std_error(&err);
  jpeg_create_compress(&cinfo);
  std::FILE* f = std::fopen(path.c_str(), "wb");
  ASSERT_NE(f, nullptr) << path;
  jpeg_stdio_dest(&cinfo, f);
  cinfo.image_width = w;
  cinfo.image_height = h;
  cinfo.input_components = components;
  cinfo.in_color_space = components == 1 ? JCS_GRAYSCALE : JCS_RGB;
  jpeg_set_defaults(&cinfo);
  jpeg_set_quality(&cinfo, quality, TRUE);
  jpeg_start_compress(&cinfo, TRUE);
  for (int y = 0; y < h; ++y) {
    JSAMPROW row = const_cast<JSAMPROW>(pixels + static_cast<std::size_t>(y) * w * components);
    jpeg_write_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_compress(&cinfo);
  jpeg_destroy_compress(&cinfo);
  std::fclose(f);
}

}  // namespace linecal::testing_jpeg

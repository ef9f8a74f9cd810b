// Image file I/O: PNG and JPEG reading in every layout a camera or a tool writes, PNG
// writing with pHYs, and errors that name the file.
#include "station/io/image_io.h"

#include <gtest/gtest.h>
#include <png.h>
#include <unistd.h>

#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "tests/station/io/jpeg_test_writer.h"

namespace linecal {
namespace {

using testing_jpeg::WriteJpeg;

class ImageIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("linecal_image_io_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  std::filesystem::path dir_;
};

// Writes a PNG of any layout with libpng directly (the reader must take files that
// WritePng* never writes: palette, alpha, low bit depths, interlacing). `rows` hold the
// samples as PNG stores them (16-bit big-endian).
void WriteRawPng(const std::string& path, int w, int h, int bit_depth, int colour_type,
                 const std::vector<std::vector<std::uint8_t>>& rows, bool interlaced = false,
                 const std::vector<png_color>& palette = {}) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  ASSERT_NE(f, nullptr);
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  png_set_user_limits(png, 1 << 20, 1 << 20);
  png_init_io(png, f);
  png_set_IHDR(png, info, w, h, bit_depth, colour_type,
               interlaced ? PNG_INTERLACE_ADAM7 : PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  if (!palette.empty()) {
    png_set_PLTE(png, info, palette.data(), static_cast<int>(palette.size()));
  }
  png_write_info(png, info);
  std::vector<png_bytep> ptrs;
  for (const auto& r : rows) ptrs.push_back(const_cast<png_bytep>(r.data()));
  png_write_image(png, ptrs.data());
  png_write_end(png, info);
  png_destroy_write_struct(&png, &info);
  std::fclose(f);
}

void WriteGreyJpeg(const std::string& path, const Image8& image, int quality) {
  WriteJpeg(path, image.width, image.height, 1, image.pixels.data(), quality);
}

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST_F(ImageIoTest, Grey8RoundTripWithStride) {
  // A view with padding at the end of each row: the writer must honour stride_bytes.
  constexpr int kW = 37, kH = 11, kStride = 48;
  std::vector<std::uint8_t> buffer(kStride * kH, 0xAB);
  for (int y = 0; y < kH; ++y) {
    for (int x = 0; x < kW; ++x)
      buffer[y * kStride + x] = static_cast<std::uint8_t>(x * 7 + y * 13);
  }
  const ImageView8 view{buffer.data(), kW, kH, kStride};
  ASSERT_TRUE(WritePng8(Path("a.png"), view).ok());
  const absl::StatusOr<Image8> back = ReadImage8(Path("a.png"));
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->width, kW);
  ASSERT_EQ(back->height, kH);
  for (int y = 0; y < kH; ++y) {
    for (int x = 0; x < kW; ++x) EXPECT_EQ(back->at(x, y), view.At(x, y)) << x << "," << y;
  }
}

TEST_F(ImageIoTest, Grey16RoundTripAndDepthConversion) {
  Image16 image(5, 3);
  const std::uint16_t values[5] = {0, 1, 257 * 100, 40000, 65535};
  for (int y = 0; y < 3; ++y) {
    for (int x = 0; x < 5; ++x) image.at(x, y) = values[x];
  }
  ASSERT_TRUE(WritePng16(Path("a.png"), image.view()).ok());
  const absl::StatusOr<Image16> back16 = ReadImage16(Path("a.png"));
  ASSERT_TRUE(back16.ok()) << back16.status();
  EXPECT_EQ(back16->pixels, image.pixels);
  // To 8 bits: v / 257 rounded.
  const absl::StatusOr<Image8> back8 = ReadImage8(Path("a.png"));
  ASSERT_TRUE(back8.ok());
  const std::uint8_t expected8[5] = {0, 0, 100, 156, 255};  // 40000 / 257 = 155.6
  for (int x = 0; x < 5; ++x) EXPECT_EQ(back8->at(x, 1), expected8[x]) << x;
  // An 8-bit file read as 16 bits: v * 257.
  Image8 eight(2, 1);
  eight.at(0, 0) = 1;
  eight.at(1, 0) = 255;
  ASSERT_TRUE(WritePng8(Path("b.png"), eight.view()).ok());
  const absl::StatusOr<Image16> wide = ReadImage16(Path("b.png"));
  ASSERT_TRUE(wide.ok());
  EXPECT_EQ(wide->at(0, 0), 257);
  EXPECT_EQ(wide->at(1, 0), 65535);
}

TEST_F(ImageIoTest, ColourBecomesBt601Luma) {
  RgbImage rgb(4, 1);
  const std::uint8_t colours[4][3] = {{255, 0, 0}, {0, 255, 0}, {0, 0, 255}, {10, 200, 90}};
  for (int x = 0; x < 4; ++x) std::memcpy(rgb.at(x, 0), colours[x], 3);
  ASSERT_TRUE(WritePngRgb(Path("c.png"), rgb).ok());
  const absl::StatusOr<Image8> grey = ReadImage8(Path("c.png"));
  ASSERT_TRUE(grey.ok()) << grey.status();
  for (int x = 0; x < 4; ++x) {
    const double luma = 0.299 * colours[x][0] + 0.587 * colours[x][1] + 0.114 * colours[x][2];
    EXPECT_EQ(grey->at(x, 0), std::lround(luma)) << x;
  }
}

TEST_F(ImageIoTest, OtherPngLayouts) {
  // 16-bit RGBA, big-endian samples: alpha is dropped, colour becomes luma.
  WriteRawPng(Path("rgba16.png"), 1, 1, 16, PNG_COLOR_TYPE_RGB_ALPHA,
              {{0x10, 0x00, 0x80, 0x00, 0xFF, 0xFF, 0x00, 0x00}});
  const absl::StatusOr<Image16> rgba = ReadImage16(Path("rgba16.png"));
  ASSERT_TRUE(rgba.ok()) << rgba.status();
  EXPECT_EQ(rgba->at(0, 0), std::lround(0.299 * 0x1000 + 0.587 * 0x8000 + 0.114 * 0xFFFF));

  // 1-bit grey: 0 -> 0, 1 -> 255.
  WriteRawPng(Path("bits.png"), 8, 1, 1, PNG_COLOR_TYPE_GRAY, {{0b10110000}});
  const absl::StatusOr<Image8> bits = ReadImage8(Path("bits.png"));
  ASSERT_TRUE(bits.ok()) << bits.status();
  const std::uint8_t expected_bits[8] = {255, 0, 255, 255, 0, 0, 0, 0};
  for (int x = 0; x < 8; ++x) EXPECT_EQ(bits->at(x, 0), expected_bits[x]) << x;

  // Palette: indices to RGB to luma.
  WriteRawPng(Path("pal.png"), 2, 1, 8, PNG_COLOR_TYPE_PALETTE, {{1, 0}}, false,
              {png_color{0, 0, 0}, png_color{200, 100, 50}});
  const absl::StatusOr<Image8> pal = ReadImage8(Path("pal.png"));
  ASSERT_TRUE(pal.ok()) << pal.status();
  EXPECT_EQ(pal->at(0, 0), std::lround(0.299 * 200 + 0.587 * 100 + 0.114 * 50));
  EXPECT_EQ(pal->at(1, 0), 0);

  // Grey + alpha, interlaced (Adam7 needs the whole image at once).
  std::vector<std::vector<std::uint8_t>> rows(9, std::vector<std::uint8_t>(2 * 9));
  for (int y = 0; y < 9; ++y) {
    for (int x = 0; x < 9; ++x) {
      rows[y][2 * x] = static_cast<std::uint8_t>(10 * x + y);
      rows[y][2 * x + 1] = 0;  // fully transparent: ignored
    }
  }
  WriteRawPng(Path("ga.png"), 9, 9, 8, PNG_COLOR_TYPE_GRAY_ALPHA, rows, true);
  const absl::StatusOr<Image8> ga = ReadImage8(Path("ga.png"));
  ASSERT_TRUE(ga.ok()) << ga.status();
  for (int y = 0; y < 9; ++y) {
    for (int x = 0; x < 9; ++x) EXPECT_EQ(ga->at(x, y), 10 * x + y);
  }
}

TEST_F(ImageIoTest, PhysChunkRecordsResolution) {
  Image8 image(3, 2, 128);
  ASSERT_TRUE(WritePng8(Path("dpi.png"), image.view(), PngWriteOptions{11811.02}).ok());
  const std::string bytes = ReadBytes(Path("dpi.png"));
  const std::size_t at = bytes.find("pHYs");
  ASSERT_NE(at, std::string::npos);
  // pHYs data: x and y pixels per unit (big-endian uint32), then unit 1 = metre.
  const auto u32 = [&](std::size_t i) {
    return (static_cast<std::uint32_t>(static_cast<std::uint8_t>(bytes[i])) << 24) |
           (static_cast<std::uint32_t>(static_cast<std::uint8_t>(bytes[i + 1])) << 16) |
           (static_cast<std::uint32_t>(static_cast<std::uint8_t>(bytes[i + 2])) << 8) |
           static_cast<std::uint32_t>(static_cast<std::uint8_t>(bytes[i + 3]));
  };
  EXPECT_EQ(u32(at + 4), 11811u);  // 300 dpi
  EXPECT_EQ(u32(at + 8), 11811u);
  EXPECT_EQ(bytes[at + 12], 1);
  // Without the option there is no pHYs chunk.
  ASSERT_TRUE(WritePng8(Path("plain.png"), image.view()).ok());
  EXPECT_EQ(ReadBytes(Path("plain.png")).find("pHYs"), std::string::npos);
}

TEST_F(ImageIoTest, JpegGreyAndColour) {
  Image8 grey(16, 16);
  for (int y = 0; y < 16; ++y) {
    for (int x = 0; x < 16; ++x) grey.at(x, y) = x < 8 ? 40 : 210;
  }
  WriteGreyJpeg(Path("g.jpg"), grey, 100);
  const absl::StatusOr<Image8> g = ReadImage8(Path("g.jpg"));
  ASSERT_TRUE(g.ok()) << g.status();
  ASSERT_EQ(g->width, 16);
  ASSERT_EQ(g->height, 16);
  // Quality 100 keeps flat 8 x 8 blocks within a couple of grey levels.
  constexpr int kJpegTolerance = 2;
  EXPECT_NEAR(g->at(2, 2), 40, kJpegTolerance);
  EXPECT_NEAR(g->at(13, 13), 210, kJpegTolerance);

  RgbImage rgb(16, 16, {200, 100, 50});
  WriteJpeg(Path("c.jpg"), rgb.width, rgb.height, 3, rgb.rgb.data(), 100);
  const absl::StatusOr<Image16> c = ReadImage16(Path("c.jpg"));
  ASSERT_TRUE(c.ok()) << c.status();
  // JPEG's Y is the BT.601 luma too; read as 16 bits it is scaled by 257.
  EXPECT_NEAR(c->at(8, 8), 257 * (0.299 * 200 + 0.587 * 100 + 0.114 * 50), 257 * kJpegTolerance);
}

// DecodeImage8 reads bytes in memory (an upload) as ReadImage8 reads the same bytes in a file,
// under the budget's byte and pixel limits, naming the upload in its errors.
TEST_F(ImageIoTest, DecodeImage8ReadsBytesAsTheFile) {
  Image8 grey(40, 30);
  for (int y = 0; y < 30; ++y) {
    for (int x = 0; x < 40; ++x) grey.at(x, y) = static_cast<std::uint8_t>(x * 6 + y);
  }
  ASSERT_TRUE(WritePng8(Path("g.png"), grey.view()).ok());
  WriteGreyJpeg(Path("g.jpg"), grey, 90);
  for (const char* name : {"g.png", "g.jpg"}) {
    const absl::StatusOr<Image8> file = ReadImage8(Path(name));
    const absl::StatusOr<Image8> memory = DecodeImage8(ReadBytes(Path(name)), "photo", {});
    ASSERT_TRUE(file.ok() && memory.ok()) << name << ": " << memory.status();
    ASSERT_EQ(memory->width, 40);
    ASSERT_EQ(memory->height, 30);
    for (int y = 0; y < 30; ++y) {
      for (int x = 0; x < 40; ++x) ASSERT_EQ(memory->at(x, y), file->at(x, y)) << name;
    }
  }
  const std::string png = ReadBytes(Path("g.png"));
  EXPECT_EQ(DecodeImage8("not an image", "photo", {}).status().message(),
            "photo: not a PNG or JPEG file");
  EXPECT_EQ(DecodeImage8("", "photo", {}).status().message(), "photo: empty");
  InputBudget small;
  small.max_file_bytes = static_cast<std::int64_t>(png.size()) - 1;
  EXPECT_EQ(DecodeImage8(png, "photo", small).status().message(),
            OverBudget("photo", static_cast<std::int64_t>(png.size()), "bytes",
                       small.max_file_bytes, "max_file_bytes")
                .message());
  InputBudget few;
  few.max_image_pixels = 40 * 30 - 1;
  EXPECT_NE(DecodeImage8(png, "photo", few).status().message().find("photo: 1200 pixels exceed"),
            std::string::npos);
  EXPECT_EQ(DecodeImage8(png.substr(0, png.size() / 2), "photo", {})
                .status()
                .message()
                .rfind("photo: bad PNG", 0),
            0u);
}

TEST_F(ImageIoTest, ErrorsNameTheFile) {
  const absl::StatusOr<Image8> missing = ReadImage8(Path("missing.png"));
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("missing.png"), std::string::npos);

  std::ofstream(Path("text.png")) << "hello, not an image";
  const absl::StatusOr<Image8> text = ReadImage8(Path("text.png"));
  EXPECT_EQ(text.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(text.status().message().find("text.png: not a PNG or JPEG"), std::string::npos)
      << text.status();

  // A truncated PNG: the signature and half of the rest.
  Image8 image(64, 64, 7);
  ASSERT_TRUE(WritePng8(Path("full.png"), image.view()).ok());
  const std::string bytes = ReadBytes(Path("full.png"));
  std::ofstream(Path("cut.png"), std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  const absl::StatusOr<Image8> cut = ReadImage8(Path("cut.png"));
  EXPECT_EQ(cut.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(cut.status().message().find("cut.png: bad PNG"), std::string::npos) << cut.status();

  // A truncated JPEG.
  WriteGreyJpeg(Path("full.jpg"), image, 90);
  const std::string jpeg = ReadBytes(Path("full.jpg"));
  std::ofstream(Path("cut.jpg"), std::ios::binary) << jpeg.substr(0, 200);
  const absl::StatusOr<Image8> cut_jpeg = ReadImage8(Path("cut.jpg"));
  EXPECT_EQ(cut_jpeg.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(cut_jpeg.status().message().find("cut.jpg: bad JPEG: Premature end"), std::string::npos)
      << cut_jpeg.status();
}

TEST_F(ImageIoTest, RefusesHugeImagesFromTheHeader) {
  // 20000 x 1: over kMaxImageSide on one side, tiny on disk.
  const int w = kMaxImageSide + 3616;
  WriteRawPng(Path("wide.png"), w, 1, 8, PNG_COLOR_TYPE_GRAY,
              {std::vector<std::uint8_t>(static_cast<std::size_t>(w), 0)});
  const absl::StatusOr<Image8> wide = ReadImage8(Path("wide.png"));
  EXPECT_EQ(wide.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(wide.status().message().find("wide.png: too large: 20000 x 1"), std::string::npos)
      << wide.status();
  // The writers refuse them too.
  std::vector<std::uint8_t> row(static_cast<std::size_t>(w), 0);
  const ImageView8 view{row.data(), w, 1, w};
  EXPECT_FALSE(WritePng8(Path("w.png"), view).ok());
}

TEST_F(ImageIoTest, WriteErrors) {
  Image8 image(2, 2);
  const absl::Status no_dir = WritePng8(Path("no/such/dir/x.png"), image.view());
  EXPECT_EQ(no_dir.code(), absl::StatusCode::kNotFound);
  EXPECT_NE(no_dir.message().find("no/such/dir/x.png"), std::string::npos);
  const ImageView8 bad{nullptr, 2, 2, 2};
  EXPECT_EQ(WritePng8(Path("bad.png"), bad).code(), absl::StatusCode::kInvalidArgument);
  RgbImage wrong(2, 2);
  wrong.rgb.pop_back();
  EXPECT_EQ(WritePngRgb(Path("rgb.png"), wrong).code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace linecal

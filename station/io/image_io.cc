#include "station/io/image_io.h"

// jpeglib.h needs <cstdio> (FILE) before it, and jerror.h needs jpeglib.h.
// clang-format off
#include <cstdio>
#include <jpeglib.h>
#include <jerror.h>
// clang-format on
#include <png.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <csetjmp>
#include <cstdlib>
#include <cstring>
#include <memory>

#include "absl/strings/str_cat.h"

// libpng and libjpeg report errors with longjmp. Every function below that calls setjmp
// holds only trivially destructible locals (raw pointers, ints), so that a longjmp out of
// the C library never skips a C++ destructor; all C++ objects live in their callers.

namespace linecal {
namespace {

using FilePtr = std::unique_ptr<std::FILE, int (*)(std::FILE*)>;

// The status for a failed fopen/fclose: NotFound and PermissionDenied where errno says so.
absl::Status FileError(const std::string& path, const char* what, int err) {
  const std::string message = absl::StrCat(path, ": ", what, ": ", std::strerror(err));
  if (err == ENOENT) return absl::NotFoundError(message);
  if (err == EACCES || err == EPERM) return absl::PermissionDeniedError(message);
  return absl::InternalError(message);
}

absl::Status TooLarge(const std::string& path, long long w, long long h) {
  return absl::InvalidArgumentError(absl::StrCat(path, ": too large: ", w, " x ", h,
                                                 " pixels (max ", kMaxImageSide, " per side)"));
}

// The size checks of a header, before any pixel memory is allocated: the budget's pixels,
// then the format's side limit.
absl::Status CheckHeaderSize(const std::string& path, std::uint64_t w, std::uint64_t h,
                             const InputBudget& budget) {
  if (w * h > static_cast<std::uint64_t>(budget.max_image_pixels)) {
    return OverBudget(path, static_cast<std::int64_t>(w * h), "pixels", budget.max_image_pixels,
                      "max_image_pixels");
  }
  if (w > static_cast<std::uint64_t>(kMaxImageSide) ||
      h > static_cast<std::uint64_t>(kMaxImageSide)) {
    return TooLarge(path, static_cast<long long>(w), static_cast<long long>(h));
  }
  return absl::OkStatus();
}

// A decoded image before the conversion to grey: 1 (grey) or 3 (RGB) channels of 8 or 16
// bits in native byte order, rows packed.
struct Decoded {
  int width = 0;
  int height = 0;
  int channels = 1;
  int bit_depth = 8;
  std::vector<std::uint8_t> bytes;

  std::size_t row_bytes() const {
    return static_cast<std::size_t>(width) * channels * (bit_depth / 8);
  }
  // Sample c of pixel (x, y), in [0, 255] or [0, 65535].
  std::uint32_t Sample(int x, int y, int c) const {
    const std::size_t i =
        static_cast<std::size_t>(y) * width * channels + static_cast<std::size_t>(x) * channels + c;
    if (bit_depth == 8) return bytes[i];
    std::uint16_t v;
    std::memcpy(&v, &bytes[2 * i], sizeof v);
    return v;
  }
  // Grey value of pixel (x, y) in the sample range: BT.601 luma for colour.
  double Grey(int x, int y) const {
    if (channels == 1) return Sample(x, y, 0);
    return 0.299 * Sample(x, y, 0) + 0.587 * Sample(x, y, 1) + 0.114 * Sample(x, y, 2);
  }
};

// ---- PNG -------------------------------------------------------------------------------

constexpr std::uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
// JPEG files open with an SOI marker followed by another marker.
constexpr std::uint8_t kJpegSignature[3] = {0xFF, 0xD8, 0xFF};

struct PngErrorState {
  char message[256] = "";
};

extern "C" void PngOnError(png_structp png, png_const_charp message) {
  auto* state = static_cast<PngErrorState*>(png_get_error_ptr(png));
  std::snprintf(state->message, sizeof state->message, "%s", message);
  png_longjmp(png, 1);
}
extern "C" void PngOnWarning(png_structp, png_const_charp) {}  // warnings change nothing

// Owns a libpng read struct and its info struct.
struct PngReadHandles {
  png_structp png = nullptr;
  png_infop info = nullptr;
  ~PngReadHandles() {
    if (png != nullptr) png_destroy_read_struct(&png, info != nullptr ? &info : nullptr, nullptr);
  }
};

struct PngHeader {
  png_uint_32 width = 0;
  png_uint_32 height = 0;
  int channels = 0;
  int bit_depth = 0;
  png_size_t row_bytes = 0;
};

// Reads the header and sets the transformations to 8/16-bit grey or RGB without alpha.
bool PngReadHeader(png_structp png, png_infop info, std::FILE* file, PngHeader* header) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_init_io(png, file);
  png_read_info(png, info);
  const int colour = png_get_color_type(png, info);
  if (colour == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (colour == PNG_COLOR_TYPE_GRAY && png_get_bit_depth(png, info) < 8) {
    png_set_expand_gray_1_2_4_to_8(png);
  }
  png_set_strip_alpha(png);
  if (png_get_bit_depth(png, info) == 16 && std::endian::native == std::endian::little) {
    png_set_swap(png);  // PNG stores 16-bit samples big-endian
  }
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  header->width = png_get_image_width(png, info);
  header->height = png_get_image_height(png, info);
  header->channels = png_get_channels(png, info);
  header->bit_depth = png_get_bit_depth(png, info);
  header->row_bytes = png_get_rowbytes(png, info);
  return true;
}

bool PngReadRows(png_structp png, png_infop info, png_bytepp rows) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_read_image(png, rows);
  png_read_end(png, info);
  return true;
}

absl::StatusOr<Decoded> DecodePng(const std::string& path, std::FILE* file,
                                  const InputBudget& budget) {
  PngErrorState error;
  PngReadHandles handles;
  handles.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &error, PngOnError, PngOnWarning);
  if (handles.png != nullptr) handles.info = png_create_info_struct(handles.png);
  png_structp png = handles.png;
  png_infop info = handles.info;
  if (png == nullptr || info == nullptr) {
    return absl::ResourceExhaustedError(absl::StrCat(path, ": cannot allocate a PNG decoder"));
  }
  PngHeader header;
  if (!PngReadHeader(png, info, file, &header)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": bad PNG: ", error.message));
  }
  if (absl::Status s = CheckHeaderSize(path, header.width, header.height, budget); !s.ok()) {
    return s;
  }
  Decoded out;
  out.width = static_cast<int>(header.width);
  out.height = static_cast<int>(header.height);
  out.channels = header.channels;  // 1 or 3 after the transformations
  out.bit_depth = header.bit_depth;
  if ((out.channels != 1 && out.channels != 3) || (out.bit_depth != 8 && out.bit_depth != 16) ||
      header.row_bytes != out.row_bytes()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": unsupported PNG layout (", out.channels,
                                                   " channels, ", out.bit_depth, " bits)"));
  }
  out.bytes.resize(out.row_bytes() * out.height);
  std::vector<png_bytep> rows(out.height);
  for (int y = 0; y < out.height; ++y) rows[y] = out.bytes.data() + out.row_bytes() * y;
  if (!PngReadRows(png, info, rows.data())) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": bad PNG: ", error.message));
  }
  return out;
}

// ---- JPEG ------------------------------------------------------------------------------

struct JpegErrorState {
  jpeg_error_mgr manager;  // first member: libjpeg sees a jpeg_error_mgr*
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX] = "";
};

extern "C" void JpegOnError(j_common_ptr cinfo) {
  auto* state = reinterpret_cast<JpegErrorState*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, state->message);
  std::longjmp(state->jump, 1);
}
// libjpeg pads a truncated file with grey and only warns; a station must not calibrate on
// such a frame, so that warning is an error. Other warnings and traces change nothing.
extern "C" void JpegOnMessage(j_common_ptr cinfo, int level) {
  if (level < 0 && cinfo->err->msg_code == JWRN_JPEG_EOF) JpegOnError(cinfo);
}

// Reads the header and asks libjpeg for grey output (the Y channel for YCbCr, i.e. BT.601
// luma). Returns 0 on success, 1 on a libjpeg error, 2 for a colour space without grey.
int JpegReadHeader(jpeg_decompress_struct* cinfo, JpegErrorState* error, std::FILE* file) {
  if (setjmp(error->jump)) return 1;
  jpeg_create_decompress(cinfo);
  jpeg_stdio_src(cinfo, file);
  jpeg_read_header(cinfo, TRUE);
  if (cinfo->jpeg_color_space != JCS_GRAYSCALE && cinfo->jpeg_color_space != JCS_YCbCr &&
      cinfo->jpeg_color_space != JCS_RGB) {
    return 2;
  }
  cinfo->out_color_space = JCS_GRAYSCALE;
  return 0;
}

bool JpegReadRows(jpeg_decompress_struct* cinfo, JpegErrorState* error, std::uint8_t* pixels,
                  std::size_t row_bytes) {
  if (setjmp(error->jump)) return false;
  jpeg_start_decompress(cinfo);
  while (cinfo->output_scanline < cinfo->output_height) {
    JSAMPROW row = pixels + row_bytes * cinfo->output_scanline;
    jpeg_read_scanlines(cinfo, &row, 1);
  }
  jpeg_finish_decompress(cinfo);
  return true;
}

absl::StatusOr<Decoded> DecodeJpeg(const std::string& path, std::FILE* file,
                                   const InputBudget& budget) {
  jpeg_decompress_struct cinfo{};  // zeroed: safe to destroy even if creation fails
  JpegErrorState error{};
  cinfo.err = jpeg_std_error(&error.manager);
  error.manager.error_exit = JpegOnError;
  error.manager.emit_message = JpegOnMessage;
  const std::unique_ptr<jpeg_decompress_struct, void (*)(jpeg_decompress_struct*)> cleanup(
      &cinfo, jpeg_destroy_decompress);
  const int header = JpegReadHeader(&cinfo, &error, file);
  if (header == 1) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": bad JPEG: ", error.message));
  }
  if (header == 2) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": unsupported JPEG colour space (CMYK/YCCK)"));
  }
  if (absl::Status s = CheckHeaderSize(path, cinfo.image_width, cinfo.image_height, budget);
      !s.ok()) {
    return s;
  }
  Decoded out;
  out.width = static_cast<int>(cinfo.image_width);
  out.height = static_cast<int>(cinfo.image_height);
  out.bytes.resize(out.row_bytes() * out.height);
  if (!JpegReadRows(&cinfo, &error, out.bytes.data(), out.row_bytes())) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": bad JPEG: ", error.message));
  }
  return out;
}

// `file` read from its start; `path` names it in messages.
absl::StatusOr<Decoded> DecodeStream(const std::string& path, std::FILE* file,
                                     const InputBudget& budget) {
  std::uint8_t magic[8] = {};
  const std::size_t n = std::fread(magic, 1, sizeof magic, file);
  std::rewind(file);
  if (n == sizeof magic && std::memcmp(magic, kPngSignature, sizeof kPngSignature) == 0) {
    return DecodePng(path, file, budget);
  }
  if (n >= sizeof kJpegSignature &&
      std::memcmp(magic, kJpegSignature, sizeof kJpegSignature) == 0) {
    return DecodeJpeg(path, file, budget);
  }
  return absl::InvalidArgumentError(absl::StrCat(path, ": not a PNG or JPEG file"));
}

absl::StatusOr<Decoded> Decode(const std::string& path, const InputBudget& budget) {
  if (absl::Status s = CheckFileBytes(path, budget); !s.ok()) return s;
  FilePtr file(std::fopen(path.c_str(), "rb"), std::fclose);
  if (file == nullptr) return FileError(path, "cannot open", errno);
  return DecodeStream(path, file.get(), budget);
}

Image8 ToImage8(const Decoded& d) {
  // To 8 bits: 16-bit values scale by 255/65535 = 1/257.
  const double to_8 = d.bit_depth == 16 ? 1.0 / 257.0 : 1.0;
  Image8 out(d.width, d.height);
  for (int y = 0; y < d.height; ++y) {
    for (int x = 0; x < d.width; ++x) {
      out.at(x, y) = static_cast<std::uint8_t>(std::lround(d.Grey(x, y) * to_8));
    }
  }
  return out;
}

// ---- PNG writing -------------------------------------------------------------------------

struct PngLayout {
  int width;
  int height;
  int bit_depth;
  int colour_type;
  double pixels_per_metre;
};

bool PngWriteAll(png_structp png, png_infop info, std::FILE* file, const PngLayout& layout,
                 png_bytepp rows) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_init_io(png, file);
  png_set_IHDR(png, info, layout.width, layout.height, layout.bit_depth, layout.colour_type,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  if (layout.pixels_per_metre > 0) {
    const auto ppm = static_cast<png_uint_32>(std::lround(layout.pixels_per_metre));
    png_set_pHYs(png, info, ppm, ppm, PNG_RESOLUTION_METER);
  }
  png_write_info(png, info);
  if (layout.bit_depth == 16 && std::endian::native == std::endian::little) {
    png_set_swap(png);  // rows hold native 16-bit samples; PNG wants big-endian
  }
  png_write_image(png, rows);
  png_write_end(png, info);
  return true;
}

absl::Status CheckPngLayout(const std::string& name, const PngLayout& layout) {
  if (layout.width <= 0 || layout.height <= 0 || layout.width > kMaxImageSide ||
      layout.height > kMaxImageSide) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": cannot write a ", layout.width, " x ", layout.height, " image"));
  }
  if (!(layout.pixels_per_metre >= 0) || !std::isfinite(layout.pixels_per_metre)) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": bad pixels_per_metre ", layout.pixels_per_metre));
  }
  return absl::OkStatus();
}

// Encodes the PNG into `file`; false (and error->message) when libpng fails. `row(y)` gives
// the bytes of row y; libpng copies each row before transforming it, so the caller's pixels
// are never written. The layout must pass CheckPngLayout.
template <typename RowFn>
bool EncodePng(std::FILE* file, const PngLayout& layout, RowFn row, PngErrorState* error) {
  std::vector<png_bytep> rows(layout.height);
  for (int y = 0; y < layout.height; ++y) rows[y] = const_cast<png_bytep>(row(y));
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, error, PngOnError, PngOnWarning);
  png_infop info = png != nullptr ? png_create_info_struct(png) : nullptr;
  const bool ok =
      png != nullptr && info != nullptr && PngWriteAll(png, info, file, layout, rows.data());
  png_destroy_write_struct(&png, &info);
  return ok;
}

template <typename RowFn>
absl::Status WritePng(const std::string& path, PngLayout layout, RowFn row) {
  if (absl::Status s = CheckPngLayout(path, layout); !s.ok()) return s;
  std::FILE* raw = std::fopen(path.c_str(), "wb");
  if (raw == nullptr) return FileError(path, "cannot create", errno);
  PngErrorState error;
  const bool ok = EncodePng(raw, layout, row, &error);
  const bool write_error = std::ferror(raw) != 0;
  const int close_errno = std::fclose(raw) != 0 ? errno : 0;
  if (ok && !write_error && close_errno == 0) return absl::OkStatus();
  std::remove(path.c_str());
  if (!ok) return absl::InternalError(absl::StrCat(path, ": PNG encoding failed: ", error.message));
  return FileError(path, "write failed", write_error ? EIO : close_errno);
}

absl::Status CheckRgbBuffer(const std::string& name, const RgbImage& image) {
  if (image.rgb.size() != 3 * static_cast<std::size_t>(std::max(image.width, 0)) *
                              static_cast<std::size_t>(std::max(image.height, 0))) {
    return absl::InvalidArgumentError(absl::StrCat(name, ": RGB image buffer size ",
                                                   image.rgb.size(), " does not match ",
                                                   image.width, " x ", image.height));
  }
  return absl::OkStatus();
}

template <typename T>
absl::Status WriteGreyPng(const std::string& path, const ImageView<T>& image,
                          const PngWriteOptions& options) {
  if (image.Validate() != ImageViewError::kOk) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": invalid image: ", ImageViewErrorName(image.Validate())));
  }
  return WritePng(path,
                  PngLayout{image.width, image.height, 8 * static_cast<int>(sizeof(T)),
                            PNG_COLOR_TYPE_GRAY, options.pixels_per_metre},
                  [&](int y) { return reinterpret_cast<const std::uint8_t*>(image.Row(y)); });
}

}  // namespace

RgbImage::RgbImage(int w, int h, std::array<std::uint8_t, 3> fill) : width(w), height(h) {
  rgb.resize(3 * static_cast<std::size_t>(w) * h);
  for (std::size_t i = 0; i < rgb.size(); i += 3) {
    rgb[i] = fill[0];
    rgb[i + 1] = fill[1];
    rgb[i + 2] = fill[2];
  }
}

absl::StatusOr<Image8> ReadImage8(const std::string& path) {
  return ReadImage8(path, InputBudget::Unlimited());
}

absl::StatusOr<Image8> ReadImage8(const std::string& path, const InputBudget& budget) {
  absl::StatusOr<Decoded> decoded = Decode(path, budget);
  if (!decoded.ok()) return decoded.status();
  return ToImage8(*decoded);
}

absl::StatusOr<Image8> DecodeImage8(std::string_view bytes, const std::string& name,
                                    const InputBudget& budget) {
  if (static_cast<std::int64_t>(bytes.size()) > budget.max_file_bytes) {
    return OverBudget(name, static_cast<std::int64_t>(bytes.size()), "bytes", budget.max_file_bytes,
                      "max_file_bytes");
  }
  if (bytes.empty()) return absl::InvalidArgumentError(absl::StrCat(name, ": empty"));
  // fmemopen only reads the buffer ("rb"), whatever its non-const parameter says.
  FilePtr file(fmemopen(const_cast<char*>(bytes.data()), bytes.size(), "rb"), std::fclose);
  if (file == nullptr) return FileError(name, "cannot open", errno);
  absl::StatusOr<Decoded> decoded = DecodeStream(name, file.get(), budget);
  if (!decoded.ok()) return decoded.status();
  return ToImage8(*decoded);
}

absl::StatusOr<Image16> ReadImage16(const std::string& path) {
  absl::StatusOr<Decoded> decoded = Decode(path, InputBudget::Unlimited());
  if (!decoded.ok()) return decoded.status();
  const Decoded& d = *decoded;
  // To 16 bits: 8-bit values scale by 65535/255 = 257.
  const double to_16 = d.bit_depth == 8 ? 257.0 : 1.0;
  Image16 out(d.width, d.height);
  for (int y = 0; y < d.height; ++y) {
    for (int x = 0; x < d.width; ++x) {
      out.at(x, y) = static_cast<std::uint16_t>(std::lround(d.Grey(x, y) * to_16));
    }
  }
  return out;
}

absl::Status WritePng8(const std::string& path, const ImageView8& image,
                       const PngWriteOptions& options) {
  return WriteGreyPng(path, image, options);
}

absl::Status WritePng16(const std::string& path, const ImageView16& image,
                        const PngWriteOptions& options) {
  return WriteGreyPng(path, image, options);
}

absl::Status WritePngRgb(const std::string& path, const RgbImage& image,
                         const PngWriteOptions& options) {
  if (absl::Status s = CheckRgbBuffer(path, image); !s.ok()) return s;
  return WritePng(
      path, PngLayout{image.width, image.height, 8, PNG_COLOR_TYPE_RGB, options.pixels_per_metre},
      [&](int y) { return image.at(0, y); });
}

absl::StatusOr<std::string> EncodePngRgb(const RgbImage& image, const std::string& name) {
  if (absl::Status s = CheckRgbBuffer(name, image); !s.ok()) return s;
  const PngLayout layout{image.width, image.height, 8, PNG_COLOR_TYPE_RGB, 0.0};
  if (absl::Status s = CheckPngLayout(name, layout); !s.ok()) return s;
  char* buffer = nullptr;
  size_t size = 0;
  std::FILE* memory = open_memstream(&buffer, &size);
  if (memory == nullptr) return FileError(name, "cannot open a memory stream", errno);
  PngErrorState error;
  const bool ok = EncodePng(
      memory, layout, [&](int y) { return image.at(0, y); }, &error);
  const bool closed = std::fclose(memory) == 0;  // sets buffer and size
  std::string png = ok && closed ? std::string(buffer, size) : "";
  std::free(buffer);
  if (!ok) return absl::InternalError(absl::StrCat(name, ": PNG encoding failed: ", error.message));
  if (!closed) return FileError(name, "write failed", errno);
  return png;
}

}  // namespace linecal

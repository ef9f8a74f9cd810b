// Fuzzes the image reader (ReadImage8: PNG and JPEG) under a small InputBudget
// (station/io/input_budget.h), with files whose headers claim any size. Input byte 0 picks the
// file: even, the remaining bytes as they are (seeds/image: a small PNG, a small JPEG, a
// 74-byte PNG claiming 16384 x 16384); odd, a PNG built here whose IHDR takes its width,
// height, bit depth and colour type from bytes 1-10 and whose IDAT holds the rest, so that
// size claims are reached without the fuzzer having to find a chunk CRC. Invariants: no
// crash; an image is returned only within the budget's pixels; every refusal names the file;
// no single allocation above 64 MB (-malloc_limit_mb in CMakeLists: the budget's
// 1 Mpx decoded at 16-bit RGB is 6 MB, so a reader that trusts a claim trips it).
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "station/io/image_io.h"
#include "station/io/input_budget.h"
#include "tests/support/crafted_files.h"

namespace {

using linecal::testing_support::Be32;
using linecal::testing_support::PngChunk;

std::filesystem::path Scratch() {
  // Per process: libFuzzer may run several jobs in one directory.
  const std::filesystem::path shm = "/dev/shm";
  const std::filesystem::path dir =
      std::filesystem::is_directory(shm) ? shm : std::filesystem::temp_directory_path();
  return dir / ("linecal_image_fuzz_" + std::to_string(getpid()));
}

// A PNG whose header claims what bytes [0, 10) say: width and height (32 bits each), bit
// depth and colour type; the rest is its IDAT.
std::string ClaimingPng(const std::uint8_t* data, std::size_t size) {
  const auto be32 = [data](std::size_t at) {
    return static_cast<std::uint32_t>(data[at]) << 24 | data[at + 1] << 16 | data[at + 2] << 8 |
           data[at + 3];
  };
  const std::string ihdr = Be32(be32(0)) + Be32(be32(4)) + static_cast<char>(data[8]) +
                           static_cast<char>(data[9]) + std::string(3, '\0');
  const std::string idat(reinterpret_cast<const char*>(data) + 10, size - 10);
  return "\x89PNG\r\n\x1a\n" + PngChunk("IHDR", ihdr) + PngChunk("IDAT", idat) +
         PngChunk("IEND", "");
}

linecal::InputBudget SmallBudget() {
  linecal::InputBudget budget;
  budget.max_file_bytes = 1 << 20;
  budget.max_image_pixels = 1 << 20;
  return budget;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = Scratch().string() + ".img";
  static const linecal::InputBudget budget = SmallBudget();
  if (size < 1) return 0;
  std::string file;
  if (data[0] % 2 == 1) {
    if (size < 11) return 0;
    file = ClaimingPng(data + 1, size - 1);
  } else {
    file.assign(reinterpret_cast<const char*>(data) + 1, size - 1);
  }
  std::ofstream(path, std::ios::binary | std::ios::trunc) << file;
  const absl::StatusOr<linecal::Image8> image = linecal::ReadImage8(path, budget);
  if (image.ok()) {
    const std::int64_t pixels = std::int64_t{image->width} * image->height;
    if (image->width <= 0 || image->height <= 0 || pixels > budget.max_image_pixels) {
      __builtin_trap();
    }
  } else if (image.status().message().find(path) == std::string::npos) {
    __builtin_trap();  // every refusal names the file
  }
  return 0;
}

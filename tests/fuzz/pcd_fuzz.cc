// Fuzzes ReadPcd (the guard on the header, our ASCII reader, PCL's binary and
// binary_compressed readers). Input byte 0 picks the file: 0 the remaining bytes as they
// are; 1-3 a small valid ascii / binary / binary_compressed file with the remaining bytes
// XORed in from the offset given by bytes 1-2. Invariants: no crash, no unbounded
// allocation, finite points; under a budget, no claim beyond it is believed (issue 21).
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "station/io/input_budget.h"
#include "station/sensors/lidar/pcd.h"

namespace {

std::filesystem::path Scratch() {
  // Per process: libFuzzer may run several jobs in one directory.
  const std::filesystem::path shm = "/dev/shm";
  const std::filesystem::path dir =
      std::filesystem::is_directory(shm) ? shm : std::filesystem::temp_directory_path();
  return dir / ("linecal_pcd_fuzz_" + std::to_string(getpid()) + ".pcd");
}

std::vector<std::string> Templates() {
  std::vector<linecal::LidarPoint> points(5);
  for (int i = 0; i < 5; ++i) {
    points[i] = {1.0f * i,
                 2.0f,
                 -0.5f * i,
                 7.0f * i,
                 static_cast<std::uint16_t>(i),
                 1'700'000'000'000'000'000 + i};
  }
  std::vector<std::string> out;
  for (linecal::PcdEncoding e : {linecal::PcdEncoding::kAscii, linecal::PcdEncoding::kBinary,
                                 linecal::PcdEncoding::kBinaryCompressed}) {
    const std::filesystem::path path = Scratch();
    (void)linecal::WritePcd(path, points, e);
    std::ifstream in(path, std::ios::binary);
    out.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  return out;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::vector<std::string> templates = Templates();
  static const std::filesystem::path path = Scratch();
  std::string file;
  if (size >= 3 && data[0] % 4 != 0) {
    file = templates[data[0] % 4 - 1];
    const std::size_t offset = static_cast<std::size_t>(data[1] << 8 | data[2]) % file.size();
    for (std::size_t i = 3; i < size; ++i) {
      const std::size_t at = offset + i - 3;
      if (at < file.size()) {
        file[at] ^= static_cast<char>(data[i]);
      } else {
        file.push_back(static_cast<char>(data[i]));
      }
    }
  } else if (size > 0) {
    file.assign(reinterpret_cast<const char*>(data) + 1, size - 1);
  }
  std::ofstream(path, std::ios::binary | std::ios::trunc) << file;
  const absl::StatusOr<linecal::PcdCloud> cloud = linecal::ReadPcd(path);
  if (cloud.ok()) {
    for (const linecal::LidarPoint& p : cloud->points) {
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) __builtin_trap();
    }
  }
  // The same file under a budget of 1000 points: a header's claim beyond it is refused before
  // anything is allocated for it (-malloc_limit_mb in CMakeLists), and no more points return.
  static const linecal::InputBudget budget = [] {
    linecal::InputBudget b;
    b.max_scan_points = 1000;
    b.max_file_bytes = 1 << 20;
    return b;
  }();
  const absl::StatusOr<linecal::PcdCloud> budgeted = linecal::ReadPcd(path, budget);
  if (budgeted.ok() &&
      static_cast<std::int64_t>(budgeted->points.size()) > budget.max_scan_points) {
    __builtin_trap();
  }
  return 0;
}

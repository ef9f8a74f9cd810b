// Fuzzes the candump log parser: any input is an error or frames that satisfy
// ValidateCanFrame and survive formatting and re-parsing (to the log's microseconds).
#include <chrono>
#include <cstdint>
#include <string_view>

#include "station/io/candump.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using linecal::CanFrame;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const absl::StatusOr<std::vector<CanFrame>> frames = linecal::ParseCandumpLog(text, "fuzz");
  if (!frames.ok()) return 0;
  for (const CanFrame& frame : *frames) {
    if (!linecal::ValidateCanFrame(frame).ok()) __builtin_trap();
    const absl::StatusOr<std::string> line = linecal::FormatCandumpLine(frame);
    if (!line.ok()) __builtin_trap();
    const absl::StatusOr<CanFrame> back = linecal::ParseCandumpLine(*line);
    if (!back.ok()) __builtin_trap();
    CanFrame expected = frame;
    expected.time = std::chrono::floor<std::chrono::microseconds>(frame.time);
    if (!(*back == expected)) __builtin_trap();
  }
  return 0;
}

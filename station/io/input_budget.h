#pragma once
// Limits on what one input file may make the readers allocate, and the hygiene of error
// messages about untrusted file contents.
//
// A capture comes from outside (a station, a simulator, a USB stick); a tiny file can claim a
// huge size (a 74-byte PNG claiming 16384 x 16384 RGB16, a PCD header claiming 100M points).
// The readers that take an InputBudget check every claim against it from the header, before
// they allocate for it, so that what they allocate is bounded by the budget and not by the
// file's word. docs/capture-format.md ("Input budget") justifies the defaults against the
// largest real sensors; linecald's configuration sets them (`input_budget`, docs/daemon.md).

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "absl/status/status.h"

namespace linecal {

struct InputBudget {
  // Bytes of any one file, on disk and decoded (a PCD's point data). 1 GiB: a 50 Mpx 16-bit
  // frame uncompressed is 100 MB and a 5M-point scan of 32-byte points 160 MB; ten times
  // that is still no real sensor's file.
  std::int64_t max_file_bytes = std::int64_t{1} << 30;
  // Pixels of one image (width x height), from its header. 50 Mpx: the largest machine
  // vision sensors in production lines (IMX-class 24-45 Mpx) with a margin.
  std::int64_t max_image_pixels = 50'000'000;
  // Points of one LiDAR scan, from its PCD header. 5M: a 128-beam rotating LiDAR at 2048
  // columns gives 262,144 points a rotation; twenty times that covers dense flash LiDARs.
  std::int64_t max_scan_points = 5'000'000;
  // Lines of one CAN log. 2M: a radar's 3.6 s record at a saturated 1 Mbit/s bus is ~30,000
  // frames (~8,000 frames/s); 2M lines is over four minutes of a saturated CAN FD bus.
  std::int64_t max_can_lines = 2'000'000;
  // Frame and scan entries of one manifest, all sensors together. 1000: the daemon records at
  // most 100 frames or rotations a sensor (a request's frames_per_sensor), and a car has up to
  // ten cameras and LiDARs (the reference car seven), so it never writes a capture it would
  // then refuse; a cycle normally uses 1-10 a sensor.
  std::int64_t max_manifest_frames = 1000;

  // No limit beyond the readers' own format limits (for tools that read trusted files).
  static InputBudget Unlimited();
  // InvalidArgument naming the field ("input_budget.max_image_pixels: must be >= 1") when a
  // limit is < 1.
  absl::Status Validate() const;
};

// The refusal of an input over budget, naming the file, the value, the limit and its key:
//   frames/0003.png: 268435456 pixels exceed the budget of 50000000
//   (input_budget.max_image_pixels)      <- one line
// `what` is the unit of `value` ("pixels", "bytes", "points", "lines", "frames"); `key` the
// field of InputBudget ("max_image_pixels"). InvalidArgument.
absl::Status OverBudget(std::string_view file, std::int64_t value, std::string_view what,
                        std::int64_t limit, std::string_view key);

// OverBudget's message without the file, for callers that locate it themselves (a manifest
// field): "2000 frames exceed the budget of 1000 (input_budget.max_manifest_frames)".
std::string OverBudgetText(std::int64_t value, std::string_view what, std::int64_t limit,
                           std::string_view key);

// OverBudget(path, size, "bytes", ...) when the file at `path` is larger than
// budget.max_file_bytes (its size from stat, so a sparse file is refused unread); OK when it
// fits or when it cannot be stat'ed (the reader's open reports that). Cost: one stat.
absl::Status CheckFileBytes(const std::filesystem::path& path, const InputBudget& budget);

// A short, sanitized piece of untrusted text for an error message: at most `max_chars`
// characters, every byte outside printable ASCII as '?', quoted, "..." when cut. Error
// messages about file contents name the file and line and show at most this much, so that a
// file that is not what it claims (a secret behind a symlink) does not end up in a result.
std::string Snippet(std::string_view text, std::size_t max_chars = 12);

}  // namespace linecal

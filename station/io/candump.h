#pragma once
// CAN frames and can-utils `candump -l` log files (the CAN part of a capture, docs/interfaces.md).
//
// One frame a line: `(1600000000.000000) can0 123#DEADBEEF` — `(seconds.microseconds)`,
// the interface, then the frame in can-utils' compact form:
//   123#DEADBEEF          classic CAN, 11-bit id (exactly 3 hex digits), 0..8 data bytes
//   12345678#DEADBEEF     classic CAN, 29-bit id (exactly 8 hex digits)
//   123#R   123#R5        remote frame (optional requested length digit 0..8)
//   123##1DEADBEEF        CAN FD: `##`, one flags nibble (kCanFdBitRateSwitch | ...), 0..64 bytes
//   20000004#0004000000000000   error frame: 8 hex digits with the error flag 0x20000000 set
// Data bytes may be separated by '.', hex digits may be upper or lower case; a trailing
// direction token (` R` / ` T`, written by `candump -x`) is accepted and ignored. The
// classic-CAN "len8_dlc" suffix (`#..._D`) and CAN XL frames are not supported (rejected).

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "station/io/input_budget.h"

namespace linecal {

// Wall-clock time of a CAN frame since the Unix epoch: candump logs and SocketCAN receive
// timestamps are both CLOCK_REALTIME. Files hold microseconds (candump's resolution).
using CanTime = std::chrono::sys_time<std::chrono::nanoseconds>;

// Payload limits of ISO 11898-1: classic CAN carries 8 bytes, CAN FD 64.
inline constexpr int kCanMaxDataBytes = 8;
inline constexpr int kCanFdMaxDataBytes = 64;
// Identifier ranges: 11-bit standard and 29-bit extended ids.
inline constexpr uint32_t kCanStandardIdMax = 0x7FF;
inline constexpr uint32_t kCanExtendedIdMax = 0x1FFFFFFF;
// The error-frame flag in an id (linux/can.h CAN_ERR_FLAG); the remaining 29 bits are the
// error class (linux/can/error.h).
inline constexpr uint32_t kCanErrorFlag = 0x20000000;
// CAN FD flags nibble (linux/can.h CANFD_BRS, CANFD_ESI, CANFD_FDF).
inline constexpr uint8_t kCanFdBitRateSwitch = 0x1;
inline constexpr uint8_t kCanFdErrorStateIndicator = 0x2;
inline constexpr uint8_t kCanFdFormatIndicator = 0x4;
// Longest interface name Linux accepts (IFNAMSIZ - 1).
inline constexpr size_t kCanMaxInterfaceName = 15;

struct CanFrame {
  CanTime time{};
  std::string interface;  // e.g. "can0": 1..15 characters, no white space
  // 11-bit when !extended, 29-bit when extended; for error frames the error class (without
  // kCanErrorFlag).
  uint32_t id = 0;
  bool extended = false;
  bool fd = false;
  uint8_t fd_flags = 0;  // CAN FD only: kCanFdBitRateSwitch | kCanFdErrorStateIndicator | ...
  bool remote = false;   // remote request: no data; `len` is the requested length
  bool error = false;    // error frame (classic, written with 8 hex id digits)
  uint8_t len = 0;       // payload bytes: 0..8 classic, CAN FD one of 0..8,12,16,20,24,32,48,64
  std::array<uint8_t, kCanFdMaxDataBytes> data{};  // bytes past `len` are zero

  // The payload (empty for remote frames; never past `data`, even for a `len` that
  // ValidateCanFrame would refuse). Points into this frame.
  std::span<const uint8_t> payload() const {
    return {data.data(), remote ? size_t{0} : std::min(size_t{len}, data.size())};
  }
  bool operator==(const CanFrame&) const = default;
};

// Checks the invariants above (id range, lengths, flag combinations, interface name).
// InvalidArgument naming the field. Cost: O(1).
absl::Status ValidateCanFrame(const CanFrame& frame);

// Parses one log line (no newline; a trailing '\r' is accepted). InvalidArgument with a
// message naming the bad part; never crashes on any input. Cost: O(line length).
absl::StatusOr<CanFrame> ParseCandumpLine(std::string_view line);

// Parses a whole log. Blank lines are skipped. The first bad line stops parsing with
// InvalidArgument "<source_name>:<line number>: <problem>"; the problem quotes at most a
// short, sanitized token of the line (Snippet), never the line. Cost: O(text size).
absl::StatusOr<std::vector<CanFrame>> ParseCandumpLog(std::string_view text,
                                                      std::string_view source_name);

// Reads and parses a log file. NotFound when it cannot be opened, otherwise as ParseCandumpLog
// with the path as the source name. Cost: one read of the file; memory ~100 bytes a frame.
absl::StatusOr<std::vector<CanFrame>> ReadCandumpLog(const std::filesystem::path& path);

// ReadCandumpLog under a budget (station/io/input_budget.h): a file of more than
// budget.max_file_bytes (from stat, so a sparse file is refused unread) or of more than
// budget.max_can_lines lines is refused with OverBudget's InvalidArgument naming the file. The
// file is read line by line: memory is the longest line plus ~100 bytes a frame.
absl::StatusOr<std::vector<CanFrame>> ReadCandumpLog(const std::filesystem::path& path,
                                                     const InputBudget& budget);

// Formats one frame as a log line (no newline) the way `candump -l` does: 10-digit seconds,
// 6-digit microseconds (the time is rounded down to whole microseconds), upper-case hex.
// InvalidArgument when ValidateCanFrame fails or the time is before 1970.
absl::StatusOr<std::string> FormatCandumpLine(const CanFrame& frame);

// Writes frames as a log file (one line each, '\n'-terminated), replacing the file.
// InvalidArgument for a bad frame (naming its index), Internal when the file cannot be written.
absl::Status WriteCandumpLog(const std::filesystem::path& path, std::span<const CanFrame> frames);

}  // namespace linecal

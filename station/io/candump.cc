#include "station/io/candump.h"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <limits>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "station/io/input_budget.h"

namespace linecal {
namespace {

// The CAN FD payload lengths a DLC can encode (ISO 11898-1: DLC 9..15 → 12..64 bytes).
bool IsCanFdLength(int len) {
  if (len <= kCanMaxDataBytes) return len >= 0;
  return len == 12 || len == 16 || len == 20 || len == 24 || len == 32 || len == 48 || len == 64;
}

int HexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

bool IsBlank(char c) { return c == ' ' || c == '\t'; }

// A token of the line in a message: short and sanitized (input_budget.h, Snippet), since a
// "log" may be any file. 20 characters show a timestamp or an 8-digit id with its first data
// bytes whole.
std::string Quoted(std::string_view s) {
  constexpr size_t kMaxShown = 20;
  return Snippet(s, kMaxShown);
}

// "(seconds.fraction)" → time. The fraction has 1..9 digits and is read as a decimal fraction
// (candump writes 6).
absl::StatusOr<CanTime> ParseTimestamp(std::string_view token) {
  const auto bad = [&](const char* why) {
    return absl::InvalidArgumentError(
        absl::StrCat("bad timestamp ", Quoted(token), ": ", why, " (expected '(seconds.micros)')"));
  };
  if (token.size() < 4 || token.front() != '(' || token.back() != ')') return bad("no parentheses");
  const std::string_view body = token.substr(1, token.size() - 2);
  const size_t dot = body.find('.');
  if (dot == std::string_view::npos) return bad("no '.'");
  const std::string_view sec_digits = body.substr(0, dot);
  const std::string_view frac_digits = body.substr(dot + 1);
  // 12 digits hold every second count an int64 of nanoseconds can (9.2e9 s) without the
  // accumulation below overflowing; the range check follows.
  constexpr size_t kMaxSecondDigits = 12;
  constexpr size_t kMaxFractionDigits = 9;  // nanoseconds
  if (sec_digits.empty() || sec_digits.size() > kMaxSecondDigits) return bad("seconds");
  if (frac_digits.empty() || frac_digits.size() > kMaxFractionDigits) return bad("fraction");
  int64_t seconds = 0;
  for (char c : sec_digits) {
    if (c < '0' || c > '9') return bad("non-digit");
    seconds = seconds * 10 + (c - '0');
  }
  int64_t fraction_ns = 0;
  for (size_t i = 0; i < kMaxFractionDigits; ++i) {
    int digit = 0;
    if (i < frac_digits.size()) {
      const char c = frac_digits[i];
      if (c < '0' || c > '9') return bad("non-digit");
      digit = c - '0';
    }
    fraction_ns = fraction_ns * 10 + digit;
  }
  constexpr int64_t kNsPerSecond = 1'000'000'000;
  if (seconds > (std::numeric_limits<int64_t>::max() - fraction_ns) / kNsPerSecond) {
    return bad("out of range");
  }
  return CanTime(std::chrono::nanoseconds(seconds * kNsPerSecond + fraction_ns));
}

// Hex data bytes with optional '.' separators into frame->data; sets frame->len.
absl::Status ParseData(std::string_view hex, int max_bytes, CanFrame* frame) {
  int len = 0;
  size_t i = 0;
  while (i < hex.size()) {
    if (hex[i] == '.') {
      ++i;
      continue;
    }
    if (i + 1 >= hex.size() || hex[i + 1] == '.') {
      return absl::InvalidArgumentError(
          absl::StrCat("odd number of hex digits in data ", Quoted(hex)));
    }
    const int hi = HexValue(hex[i]);
    const int lo = HexValue(hex[i + 1]);
    if (hi < 0 || lo < 0) {
      return absl::InvalidArgumentError(absl::StrCat("bad hex digit in data ", Quoted(hex)));
    }
    if (len == max_bytes) {
      return absl::InvalidArgumentError(
          absl::StrCat("more than ", max_bytes, " data bytes in ", Quoted(hex)));
    }
    frame->data[len++] = static_cast<uint8_t>(hi << 4 | lo);
    i += 2;
  }
  frame->len = static_cast<uint8_t>(len);
  return absl::OkStatus();
}

// "ID#DATA", "ID#R[n]" or "ID##fDATA" into *frame (id, flags, data).
absl::Status ParseFrameToken(std::string_view token, CanFrame* frame) {
  const size_t hash = token.find('#');
  if (hash == std::string_view::npos) {
    return absl::InvalidArgumentError(absl::StrCat("no '#' in frame ", Quoted(token)));
  }
  const std::string_view id_text = token.substr(0, hash);
  // can-utils writes 11-bit ids with 3 hex digits and 29-bit ids (and error frames) with 8.
  constexpr size_t kStandardIdDigits = 3;
  constexpr size_t kExtendedIdDigits = 8;
  if (id_text.size() != kStandardIdDigits && id_text.size() != kExtendedIdDigits) {
    return absl::InvalidArgumentError(absl::StrCat(
        "bad CAN id ", Quoted(id_text), " (3 hex digits for an 11-bit id, 8 for a 29-bit id)"));
  }
  uint32_t id = 0;
  for (char c : id_text) {
    const int v = HexValue(c);
    if (v < 0) return absl::InvalidArgumentError(absl::StrCat("bad CAN id ", Quoted(id_text)));
    id = id << 4 | static_cast<uint32_t>(v);
  }
  if (id_text.size() == kStandardIdDigits) {
    if (id > kCanStandardIdMax) {
      return absl::InvalidArgumentError(
          absl::StrFormat("11-bit CAN id 0x%03X out of range (max 0x7FF)", id));
    }
  } else if ((id & kCanErrorFlag) != 0) {
    frame->error = true;
    id &= ~kCanErrorFlag;
  } else {
    frame->extended = true;
  }
  if (id > kCanExtendedIdMax) {
    return absl::InvalidArgumentError(
        absl::StrFormat("CAN id %s has flag bits 30/31 set", std::string(id_text)));
  }
  frame->id = id;

  std::string_view rest = token.substr(hash + 1);
  if (!rest.empty() && rest.front() == '#') {
    if (frame->error) {
      return absl::InvalidArgumentError("an error frame cannot be a CAN FD frame");
    }
    frame->fd = true;
    if (rest.size() < 2 || HexValue(rest[1]) < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("CAN FD frame ", Quoted(token), " lacks its flags nibble after '##'"));
    }
    frame->fd_flags = static_cast<uint8_t>(HexValue(rest[1]));
    if (absl::Status s = ParseData(rest.substr(2), kCanFdMaxDataBytes, frame); !s.ok()) return s;
    if (!IsCanFdLength(frame->len)) {
      return absl::InvalidArgumentError(
          absl::StrCat("CAN FD payload of ", frame->len,
                       " bytes is not a CAN FD length (0-8, 12, 16, 20, 24, 32, 48, 64)"));
    }
    return absl::OkStatus();
  }
  if (!rest.empty() && rest.front() == 'R') {
    if (frame->error) return absl::InvalidArgumentError("an error frame cannot be a remote frame");
    frame->remote = true;
    if (rest.size() == 1) return absl::OkStatus();
    if (rest.size() == 2 && rest[1] >= '0' && rest[1] <= '8') {
      frame->len = static_cast<uint8_t>(rest[1] - '0');
      return absl::OkStatus();
    }
    return absl::InvalidArgumentError(
        absl::StrCat("bad remote frame ", Quoted(token), " (expected R or R0..R8)"));
  }
  return ParseData(rest, kCanMaxDataBytes, frame);
}

}  // namespace

absl::Status ValidateCanFrame(const CanFrame& f) {
  if (f.interface.empty() || f.interface.size() > kCanMaxInterfaceName) {
    return absl::InvalidArgumentError(
        absl::StrCat("interface name ", Quoted(f.interface), " must have 1..15 characters"));
  }
  for (char c : f.interface) {
    if (c <= ' ' || c == 0x7F) {
      return absl::InvalidArgumentError(absl::StrCat("interface name ", Quoted(f.interface),
                                                     " holds white space or a control character"));
    }
  }
  const uint32_t id_max = f.extended || f.error ? kCanExtendedIdMax : kCanStandardIdMax;
  if (f.id > id_max) {
    return absl::InvalidArgumentError(
        absl::StrFormat("CAN id 0x%X out of range (max 0x%X)", f.id, id_max));
  }
  if (f.error && (f.extended || f.fd || f.remote)) {
    return absl::InvalidArgumentError("an error frame is neither extended, CAN FD nor remote");
  }
  if (f.fd) {
    if (f.remote) return absl::InvalidArgumentError("CAN FD has no remote frames");
    if (!IsCanFdLength(f.len)) {
      return absl::InvalidArgumentError(
          absl::StrCat("CAN FD length ", f.len, " is not a CAN FD length"));
    }
    if (f.fd_flags > 0xF) {
      return absl::InvalidArgumentError(
          absl::StrCat("CAN FD flags ", f.fd_flags, " exceed one nibble"));
    }
  } else {
    if (f.fd_flags != 0) return absl::InvalidArgumentError("fd_flags set on a classic CAN frame");
    if (f.len > kCanMaxDataBytes) {
      return absl::InvalidArgumentError(absl::StrCat("classic CAN length ", f.len, " exceeds 8"));
    }
  }
  const size_t used = f.payload().size();
  if (std::any_of(f.data.begin() + used, f.data.end(), [](uint8_t b) { return b != 0; })) {
    return absl::InvalidArgumentError(
        absl::StrCat("data bytes past the payload (", used, " bytes) are not zero"));
  }
  return absl::OkStatus();
}

absl::StatusOr<CanFrame> ParseCandumpLine(std::string_view line) {
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  // A line has 3 fields, or 4 with candump -x's direction token.
  constexpr int kMaxFields = 4;
  std::array<std::string_view, kMaxFields> fields;
  int count = 0;
  size_t i = 0;
  while (i < line.size()) {
    if (IsBlank(line[i])) {
      ++i;
      continue;
    }
    size_t end = i;
    while (end < line.size() && !IsBlank(line[end])) ++end;
    if (count == kMaxFields) {
      return absl::InvalidArgumentError(
          absl::StrCat("unexpected text ", Quoted(line.substr(i)), " after the frame"));
    }
    fields[count++] = line.substr(i, end - i);
    i = end;
  }
  if (count < 3) {
    // The line itself is not shown: a file with fewer than 3 fields is probably no log at all.
    return absl::InvalidArgumentError(
        absl::StrCat("expected '(seconds.micros) interface ID#DATA', got ", count, " field(s)"));
  }
  if (count == kMaxFields && fields[3] != "R" && fields[3] != "T") {
    return absl::InvalidArgumentError(
        absl::StrCat("unexpected text ", Quoted(fields[3]), " after the frame (only R or T)"));
  }
  CanFrame frame;
  absl::StatusOr<CanTime> time = ParseTimestamp(fields[0]);
  if (!time.ok()) return time.status();
  frame.time = *time;
  if (fields[1].size() > kCanMaxInterfaceName) {
    return absl::InvalidArgumentError(
        absl::StrCat("interface name ", Quoted(fields[1]), " longer than 15 characters"));
  }
  frame.interface = std::string(fields[1]);
  if (absl::Status s = ParseFrameToken(fields[2], &frame); !s.ok()) return s;
  // What the line-level checks leave to the frame's own invariants (e.g. control characters
  // in the interface name): a parsed frame is always one FormatCandumpLine accepts.
  if (absl::Status s = ValidateCanFrame(frame); !s.ok()) return s;
  return frame;
}

namespace {

// One line of a log (line_number counts from 1) appended to `frames`; blank lines are skipped.
absl::Status ParseLogLine(std::string_view line, std::string_view source_name, size_t line_number,
                          std::vector<CanFrame>* frames) {
  if (std::all_of(line.begin(), line.end(), [](char c) { return IsBlank(c) || c == '\r'; })) {
    return absl::OkStatus();
  }
  absl::StatusOr<CanFrame> frame = ParseCandumpLine(line);
  if (!frame.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat(std::string(source_name), ":", line_number, ": ", frame.status().message()));
  }
  frames->push_back(*std::move(frame));
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::vector<CanFrame>> ParseCandumpLog(std::string_view text,
                                                      std::string_view source_name) {
  std::vector<CanFrame> frames;
  // A typical candump line is ~40 bytes; reserving avoids most reallocation.
  constexpr size_t kTypicalLineBytes = 40;
  frames.reserve(text.size() / kTypicalLineBytes);
  size_t line_number = 0;
  size_t start = 0;
  while (start < text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view line = text.substr(start, end - start);
    start = end + 1;
    if (absl::Status s = ParseLogLine(line, source_name, ++line_number, &frames); !s.ok()) {
      return s;
    }
  }
  return frames;
}

absl::StatusOr<std::vector<CanFrame>> ReadCandumpLog(const std::filesystem::path& path) {
  return ReadCandumpLog(path, InputBudget::Unlimited());
}

absl::StatusOr<std::vector<CanFrame>> ReadCandumpLog(const std::filesystem::path& path,
                                                     const InputBudget& budget) {
  if (absl::Status s = CheckFileBytes(path, budget); !s.ok()) return s;
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return absl::NotFoundError(absl::StrCat(path.string(), ": cannot open CAN log"));
  }
  // Line by line, so that memory is one line plus the frames, never the file twice.
  const std::string source = path.string();
  std::vector<CanFrame> frames;
  std::string line;
  size_t line_number = 0;
  while (std::getline(in, line)) {
    if (static_cast<std::int64_t>(++line_number) > budget.max_can_lines) {
      return OverBudget(source, static_cast<std::int64_t>(line_number), "or more lines",
                        budget.max_can_lines, "max_can_lines");
    }
    if (absl::Status s = ParseLogLine(line, source, line_number, &frames); !s.ok()) return s;
  }
  if (in.bad()) {
    return absl::InternalError(absl::StrCat(path.string(), ": read error"));
  }
  return frames;
}

absl::StatusOr<std::string> FormatCandumpLine(const CanFrame& f) {
  if (absl::Status s = ValidateCanFrame(f); !s.ok()) return s;
  const int64_t ns = f.time.time_since_epoch().count();
  if (ns < 0) return absl::InvalidArgumentError("frame time before 1970");
  constexpr int64_t kNsPerUs = 1000;
  constexpr int64_t kUsPerSecond = 1'000'000;
  const int64_t us = ns / kNsPerUs;
  std::string out =
      absl::StrFormat("(%010d.%06d) %s ", us / kUsPerSecond, us % kUsPerSecond, f.interface);
  if (f.error) {
    absl::StrAppendFormat(&out, "%08X#", f.id | kCanErrorFlag);
  } else if (f.extended) {
    absl::StrAppendFormat(&out, "%08X#", f.id);
  } else {
    absl::StrAppendFormat(&out, "%03X#", f.id);
  }
  if (f.remote) {
    out += 'R';
    if (f.len > 0) out += static_cast<char>('0' + f.len);
    return out;
  }
  if (f.fd) absl::StrAppendFormat(&out, "#%X", f.fd_flags);
  for (uint8_t byte : f.payload()) absl::StrAppendFormat(&out, "%02X", byte);
  return out;
}

absl::Status WriteCandumpLog(const std::filesystem::path& path, std::span<const CanFrame> frames) {
  std::string text;
  for (size_t i = 0; i < frames.size(); ++i) {
    absl::StatusOr<std::string> line = FormatCandumpLine(frames[i]);
    if (!line.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("frame ", i, ": ", line.status().message()));
    }
    text += *line;
    text += '\n';
  }
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
  out.close();
  if (!out) return absl::InternalError(absl::StrCat(path.string(), ": cannot write CAN log"));
  return absl::OkStatus();
}

}  // namespace linecal

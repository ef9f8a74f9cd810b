#include "station/io/candump.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

namespace linecal {
namespace {

using std::chrono::microseconds;
using std::chrono::nanoseconds;
using std::chrono::seconds;
using std::string_view_literals::operator""sv;

constexpr int64_t kLogEpochS = 1600000000;  // the timestamp of docs/sensors.md's example line

CanFrame ParseOk(std::string_view line) {
  absl::StatusOr<CanFrame> frame = ParseCandumpLine(line);
  EXPECT_TRUE(frame.ok()) << line << ": " << frame.status();
  return frame.ok() ? *frame : CanFrame{};
}

std::vector<uint8_t> Bytes(const CanFrame& f) { return {f.payload().begin(), f.payload().end()}; }

TEST(CandumpParseTest, ClassicStandardFrame) {
  const CanFrame f = ParseOk("(1600000000.000000) can0 123#DEADBEEF");
  EXPECT_EQ(f.time, CanTime(seconds(kLogEpochS)));
  EXPECT_EQ(f.interface, "can0");
  EXPECT_EQ(f.id, 0x123u);
  EXPECT_FALSE(f.extended);
  EXPECT_FALSE(f.fd);
  EXPECT_FALSE(f.remote);
  EXPECT_FALSE(f.error);
  EXPECT_EQ(Bytes(f), (std::vector<uint8_t>{0xDE, 0xAD, 0xBE, 0xEF}));
}

TEST(CandumpParseTest, ExtendedIdHasEightDigits) {
  const CanFrame f = ParseOk("(1600000000.250000) vcan1 1F334455#1122334455667788");
  EXPECT_EQ(f.time, CanTime(seconds(kLogEpochS) + microseconds(250000)));
  EXPECT_TRUE(f.extended);
  EXPECT_EQ(f.id, 0x1F334455u);
  EXPECT_EQ(f.len, 8);
  // An 8-digit id below 0x800 is still a 29-bit frame.
  const CanFrame low = ParseOk("(1600000000.000000) can0 00000123#");
  EXPECT_TRUE(low.extended);
  EXPECT_EQ(low.id, 0x123u);
  EXPECT_EQ(low.len, 0);
}

TEST(CandumpParseTest, RemoteFrames) {
  const CanFrame r0 = ParseOk("(1600000000.000000) can0 123#R");
  EXPECT_TRUE(r0.remote);
  EXPECT_EQ(r0.len, 0);
  EXPECT_TRUE(r0.payload().empty());
  const CanFrame r5 = ParseOk("(1600000000.000000) can0 123#R5");
  EXPECT_TRUE(r5.remote);
  EXPECT_EQ(r5.len, 5);
  EXPECT_TRUE(r5.payload().empty());
}

TEST(CandumpParseTest, CanFdFrames) {
  const CanFrame f = ParseOk("(1600000000.000000) can0 123##1DEADBEEF");
  EXPECT_TRUE(f.fd);
  EXPECT_EQ(f.fd_flags, kCanFdBitRateSwitch);
  EXPECT_EQ(Bytes(f), (std::vector<uint8_t>{0xDE, 0xAD, 0xBE, 0xEF}));
  std::string line = "(1600000000.000000) can0 12345678##3";
  for (int i = 0; i < kCanFdMaxDataBytes; ++i) line += "A5";
  const CanFrame big = ParseOk(line);
  EXPECT_TRUE(big.extended);
  EXPECT_EQ(big.fd_flags, kCanFdBitRateSwitch | kCanFdErrorStateIndicator);
  EXPECT_EQ(big.len, kCanFdMaxDataBytes);
  EXPECT_EQ(big.data[63], 0xA5);
}

TEST(CandumpParseTest, ErrorFrameCarriesFlagInId) {
  const CanFrame f = ParseOk("(1600000000.000000) can0 20000004#0004000000000000");
  EXPECT_TRUE(f.error);
  EXPECT_FALSE(f.extended);
  EXPECT_EQ(f.id, 0x4u);  // CAN_ERR_CRTL: controller problems
  EXPECT_EQ(f.len, 8);
  EXPECT_EQ(f.data[1], 0x04);
}

TEST(CandumpParseTest, AcceptsSeparatorsCaseDirectionAndFractions) {
  const CanFrame f = ParseOk("(1600000000.000001)\tcan0  7ff#de.ad.be.ef T\r");
  EXPECT_EQ(f.id, 0x7FFu);
  EXPECT_EQ(Bytes(f), (std::vector<uint8_t>{0xDE, 0xAD, 0xBE, 0xEF}));
  EXPECT_EQ(f.time, CanTime(seconds(kLogEpochS) + microseconds(1)));
  // The fraction is a decimal fraction whatever its number of digits.
  EXPECT_EQ(ParseOk("(1.5) can0 123#").time, CanTime(nanoseconds(1'500'000'000)));
  EXPECT_EQ(ParseOk("(1.000000007) can0 123#").time, CanTime(nanoseconds(1'000'000'007)));
}

struct BadLine {
  std::string_view line;
  const char* message_part;
};

TEST(CandumpParseTest, MalformedLinesAreErrorsNamingTheProblem) {
  const BadLine cases[] = {
      {"", "expected '(seconds.micros) interface ID#DATA'"},
      {"(1600000000.000000) can0", "expected '(seconds.micros) interface ID#DATA'"},
      {"1600000000.000000 can0 123#00", "bad timestamp"},
      {"(1600000000) can0 123#00", "bad timestamp"},
      {"(16000x0000.000000) can0 123#00", "bad timestamp"},
      {"(1600000000.0000000000) can0 123#00", "bad timestamp"},
      {"(99999999999.000000) can0 123#00", "out of range"},
      {"(1600000000.000000) can0 123DEADBEEF", "no '#'"},
      {"(1600000000.000000) can0 1234#00", "bad CAN id"},
      {"(1600000000.000000) can0 12G#00", "bad CAN id"},
      {"(1600000000.000000) can0 800#00", "11-bit CAN id 0x800 out of range"},
      {"(1600000000.000000) can0 40000000#00", "flag bits 30/31"},
      {"(1600000000.000000) can0 123#DEADBEE", "odd number of hex digits"},
      {"(1600000000.000000) can0 123#DEADBEXF", "bad hex digit"},
      {"(1600000000.000000) can0 123#001122334455667788", "more than 8 data bytes"},
      {"(1600000000.000000) can0 123#R9", "bad remote frame"},
      {"(1600000000.000000) can0 123##", "lacks its flags nibble"},
      {"(1600000000.000000) can0 123##1001122334455667788", "not a CAN FD length"},
      {"(1600000000.000000) can0 20000004##1", "error frame cannot be a CAN FD frame"},
      {"(1600000000.000000) can0 20000004#R", "error frame cannot be a remote frame"},
      {"(1600000000.000000) can0 123#00 X", "only R or T"},
      {"(1600000000.000000) can0 123#00 R extra", "unexpected text"},
      {"(1600000000.000000) averyveryverylongname0 123#00", "longer than 15"},
      {"(1600000000.000000) c\0n0 123#00"sv, "control character"},
  };
  for (const BadLine& c : cases) {
    const absl::StatusOr<CanFrame> f = ParseCandumpLine(c.line);
    ASSERT_FALSE(f.ok()) << c.line;
    EXPECT_EQ(f.status().code(), absl::StatusCode::kInvalidArgument) << c.line;
    EXPECT_NE(f.status().message().find(c.message_part), std::string::npos)
        << c.line << " → " << f.status().message();
  }
}

TEST(CandumpParseTest, ErrorsInALogNameSourceAndLine) {
  const std::string text =
      "(1600000000.000000) can0 123#00\n"
      "\n"
      "(1600000000.000100) can0 123#0\n";
  const absl::StatusOr<std::vector<CanFrame>> frames = ParseCandumpLog(text, "run.log");
  ASSERT_FALSE(frames.ok());
  EXPECT_EQ(frames.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(frames.status().message().rfind("run.log:3: odd number of hex digits", 0), 0u)
      << frames.status().message();
}

TEST(CandumpParseTest, BinaryGarbageIsAnErrorNotACrash) {
  std::mt19937 rng(7);  // fixed seed
  std::uniform_int_distribution<int> byte(0, 255);
  for (int trial = 0; trial < 2000; ++trial) {
    std::string line = "(1600000000.000000) can0 ";
    const int n = trial % 90;
    for (int i = 0; i < n; ++i) line += static_cast<char>(byte(rng));
    const absl::StatusOr<CanFrame> f = ParseCandumpLine(line);
    if (f.ok()) {
      EXPECT_TRUE(ValidateCanFrame(*f).ok()) << line;
    }
  }
}

TEST(CandumpReadTest, MissingFileIsNotFound) {
  const absl::StatusOr<std::vector<CanFrame>> frames = ReadCandumpLog("/nonexistent/x.log");
  ASSERT_FALSE(frames.ok());
  EXPECT_EQ(frames.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(frames.status().message().find("/nonexistent/x.log"), std::string::npos);
}

TEST(CandumpFormatTest, WritesCandumpsForm) {
  CanFrame f;
  f.time = CanTime(seconds(kLogEpochS) + microseconds(42) + nanoseconds(999));  // ns dropped
  f.interface = "can0";
  f.id = 0x123;
  f.len = 4;
  f.data = {0xDE, 0xAD, 0xBE, 0xEF};
  EXPECT_EQ(*FormatCandumpLine(f), "(1600000000.000042) can0 123#DEADBEEF");
  f.fd = true;
  f.fd_flags = kCanFdBitRateSwitch;
  EXPECT_EQ(*FormatCandumpLine(f), "(1600000000.000042) can0 123##1DEADBEEF");
  f.fd = false;
  f.fd_flags = 0;
  f.extended = true;
  EXPECT_EQ(*FormatCandumpLine(f), "(1600000000.000042) can0 00000123#DEADBEEF");
  CanFrame r;
  r.time = CanTime(seconds(3));
  r.interface = "can1";
  r.id = 0x7FF;
  r.remote = true;
  r.len = 2;
  EXPECT_EQ(*FormatCandumpLine(r), "(0000000003.000000) can1 7FF#R2");
  CanFrame e;
  e.interface = "can0";
  e.error = true;
  e.id = 0x4;
  e.len = 8;
  e.data[1] = 0x04;
  EXPECT_EQ(*FormatCandumpLine(e), "(0000000000.000000) can0 20000004#0004000000000000");
}

TEST(CandumpFormatTest, RejectsInvalidFrames) {
  CanFrame f;
  f.interface = "can0";
  f.id = 0x800;  // needs 29 bits but not extended
  EXPECT_EQ(FormatCandumpLine(f).status().code(), absl::StatusCode::kInvalidArgument);
  f.id = 0x100;
  f.len = 9;
  EXPECT_EQ(FormatCandumpLine(f).status().code(), absl::StatusCode::kInvalidArgument);
  f.len = 1;
  f.interface = "can 0";
  EXPECT_EQ(FormatCandumpLine(f).status().code(), absl::StatusCode::kInvalidArgument);
  f.interface = "can0";
  f.fd = true;
  f.len = 9;  // not a CAN FD length
  EXPECT_EQ(FormatCandumpLine(f).status().code(), absl::StatusCode::kInvalidArgument);
  f.len = 1;
  f.time = CanTime(seconds(-1));
  EXPECT_EQ(FormatCandumpLine(f).status().code(), absl::StatusCode::kInvalidArgument);
}

// Random valid frames of every kind, on whole microseconds (the log's resolution).
std::vector<CanFrame> RandomFrames(int count, uint32_t seed) {
  std::mt19937 rng(seed);
  const auto uniform = [&](int lo, int hi) {
    return std::uniform_int_distribution<int>(lo, hi)(rng);
  };
  const int kFdLengths[] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64};
  std::vector<CanFrame> frames;
  int64_t t_us = kLogEpochS * 1'000'000;
  for (int i = 0; i < count; ++i) {
    CanFrame f;
    t_us += uniform(1, 5000);
    f.time = CanTime(microseconds(t_us));
    f.interface = uniform(0, 1) ? "can0" : "vcan12";
    const int kind = uniform(0, 5);  // classic std, classic ext, remote, FD std, FD ext, error
    f.extended = kind == 1 || kind == 4;
    f.id = static_cast<uint32_t>(
        uniform(0, f.extended ? int{kCanExtendedIdMax} : int{kCanStandardIdMax}));
    if (kind == 2) {
      f.remote = true;
      f.len = static_cast<uint8_t>(uniform(0, 8));
    } else if (kind == 5) {
      f.error = true;
      f.id = static_cast<uint32_t>(uniform(0, 0x3FF));  // the error classes of linux/can/error.h
      f.len = 8;
    } else if (kind == 3 || kind == 4) {
      f.fd = true;
      f.fd_flags = static_cast<uint8_t>(uniform(0, 15));
      f.len = static_cast<uint8_t>(kFdLengths[uniform(0, 15)]);
    } else {
      f.len = static_cast<uint8_t>(uniform(0, 8));
    }
    for (int b = 0; b < static_cast<int>(f.payload().size()); ++b)
      f.data[b] = static_cast<uint8_t>(uniform(0, 255));
    frames.push_back(f);
  }
  return frames;
}

std::filesystem::path TempPath(const std::string& name) {
  return std::filesystem::path(testing::TempDir()) / name;
}

TEST(CandumpRoundTripTest, WriteThenReadGivesTheSameFrames) {
  const std::vector<CanFrame> frames = RandomFrames(3000, 11);
  const std::filesystem::path path = TempPath("roundtrip.log");
  ASSERT_TRUE(WriteCandumpLog(path, frames).ok());
  const absl::StatusOr<std::vector<CanFrame>> back = ReadCandumpLog(path);
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->size(), frames.size());
  for (size_t i = 0; i < frames.size(); ++i) {
    ASSERT_EQ((*back)[i], frames[i]) << "frame " << i << ": " << *FormatCandumpLine(frames[i]);
  }
}

// can-utils as an independent oracle: log2long prints every frame of a log in a long form.
std::string RunTool(const std::string& command) {
  std::string out;
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return out;
  char buffer[4096];
  size_t n;
  while ((n = fread(buffer, 1, sizeof buffer, pipe)) > 0) out.append(buffer, n);
  pclose(pipe);
  return out;
}

bool HaveTool(const std::string& name) {
  return std::system(("command -v " + name + " >/dev/null 2>&1").c_str()) == 0;
}

TEST(CandumpOracleTest, Log2longAgreesWithOurParser) {
  if (!HaveTool("log2long")) GTEST_SKIP() << "can-utils not installed (tools/packages.txt)";
  const std::vector<CanFrame> frames = RandomFrames(500, 23);
  const std::filesystem::path path = TempPath("oracle_long.log");
  ASSERT_TRUE(WriteCandumpLog(path, frames).ok());
  const absl::StatusOr<std::vector<CanFrame>> ours = ReadCandumpLog(path);
  ASSERT_TRUE(ours.ok()) << ours.status();
  // log2long: "(sec.usec)  iface  ID  [len]  BB BB ..  'ascii'" or "remote request" or
  // "... ERRORFRAME"; FD lengths are printed with two digits ("[04]").
  std::istringstream lines(RunTool("log2long < " + path.string()));
  std::string line;
  size_t i = 0;
  while (std::getline(lines, line)) {
    ASSERT_LT(i, ours->size());
    const CanFrame& f = (*ours)[i++];
    std::istringstream in(line);
    std::string stamp, iface, id, len;
    in >> stamp >> iface >> id >> len;
    EXPECT_EQ(iface, f.interface) << line;
    const uint32_t oracle_id = static_cast<uint32_t>(std::stoul(id, nullptr, 16));
    EXPECT_EQ(oracle_id, f.error ? (f.id | kCanErrorFlag) : f.id) << line;
    EXPECT_EQ(id.size() == 8, f.extended || f.error) << line;
    EXPECT_EQ(std::stoi(len.substr(1)), f.len) << line;
    EXPECT_EQ(len.size() == 4, f.fd) << line;  // "[NN]" marks CAN FD
    EXPECT_EQ(line.find("remote request") != std::string::npos, f.remote) << line;
    EXPECT_EQ(line.find("ERRORFRAME") != std::string::npos, f.error) << line;
    std::vector<uint8_t> bytes;
    std::string token;
    while (in >> token && token.size() == 2 && std::isxdigit(token[0]) && std::isxdigit(token[1])) {
      bytes.push_back(static_cast<uint8_t>(std::stoul(token, nullptr, 16)));
    }
    EXPECT_EQ(bytes, Bytes(f)) << line;
    char expected_stamp[32];
    const int64_t us = std::chrono::duration_cast<microseconds>(f.time.time_since_epoch()).count();
    std::snprintf(expected_stamp, sizeof expected_stamp, "(%lld.%06lld)",
                  static_cast<long long>(us / 1'000'000), static_cast<long long>(us % 1'000'000));
    EXPECT_EQ(stamp, expected_stamp) << line;
  }
  EXPECT_EQ(i, ours->size());
}

TEST(CandumpOracleTest, Log2ascAgreesOnCanFdFlags) {
  if (!HaveTool("log2asc")) GTEST_SKIP() << "can-utils not installed (tools/packages.txt)";
  std::vector<CanFrame> fd_frames;
  for (const CanFrame& f : RandomFrames(400, 31)) {
    if (f.fd) fd_frames.push_back(f);
  }
  ASSERT_GT(fd_frames.size(), 50u);
  for (CanFrame& f : fd_frames) f.interface = "can0";
  const std::filesystem::path path = TempPath("oracle_asc.log");
  ASSERT_TRUE(WriteCandumpLog(path, fd_frames).ok());
  const absl::StatusOr<std::vector<CanFrame>> ours = ReadCandumpLog(path);
  ASSERT_TRUE(ours.ok()) << ours.status();
  // log2asc CAN FD lines: "time CANFD channel Rx id [name] BRS ESI DLC len data..."
  std::istringstream lines(RunTool("log2asc -I " + path.string() + " can0"));
  std::string line;
  size_t i = 0;
  while (std::getline(lines, line)) {
    if (line.find("CANFD") == std::string::npos) continue;
    ASSERT_LT(i, ours->size());
    const CanFrame& f = (*ours)[i++];
    std::istringstream in(line);
    std::string time, canfd, channel, dir, id;
    int brs, esi, dlc, len;
    in >> time >> canfd >> channel >> dir >> id >> brs >> esi >> std::hex >> dlc >> std::dec >> len;
    EXPECT_EQ(static_cast<uint32_t>(std::stoul(id, nullptr, 16)), f.id) << line;
    EXPECT_EQ(id.back() == 'x', f.extended) << line;
    EXPECT_EQ(brs != 0, (f.fd_flags & kCanFdBitRateSwitch) != 0) << line;
    EXPECT_EQ(esi != 0, (f.fd_flags & kCanFdErrorStateIndicator) != 0) << line;
    EXPECT_EQ(len, f.len) << line;
  }
  EXPECT_EQ(i, ours->size());
}

}  // namespace
}  // namespace linecal

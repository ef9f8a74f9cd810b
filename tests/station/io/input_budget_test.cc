// The input budget (issue 21, item 4) on real crafted files: tiny or sparse files that claim
// huge sizes are refused from their headers, before the readers allocate for the claim, with
// the file, the value, the limit and its key in the message.
#include "station/io/input_budget.h"

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "station/io/candump.h"
#include "station/io/image_io.h"
#include "station/sensors/lidar/pcd.h"
#include "tests/support/crafted_files.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using testing_support::HugeClaimPng;

fs::path TempPath(const std::string& name) {
  return fs::path(testing::TempDir()) /
         (std::to_string(::getpid()) + "_" +
          testing::UnitTest::GetInstance()->current_test_info()->name() + "_" + name);
}

void WriteBytes(const fs::path& p, const std::string& bytes) {
  std::ofstream(p, std::ios::binary | std::ios::trunc) << bytes;
}

long MaxRssKb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_maxrss;
}

TEST(InputBudget, TinyPngClaimingHugeSizeIsRefusedBeforeDecoding) {
  const fs::path png = TempPath("huge.png");
  const std::string bytes = HugeClaimPng();
  ASSERT_EQ(bytes.size(), 74u);
  WriteBytes(png, bytes);
  const absl::StatusOr<Image8> image = ReadImage8(png.string(), InputBudget{});
  ASSERT_FALSE(image.ok());
  EXPECT_EQ(image.status().message(), png.string() +
                                          ": 268435456 pixels exceed the budget of 50000000 "
                                          "(input_budget.max_image_pixels)");

  // The peak memory of the refusal, measured in a child process so that nothing else of
  // this test counts: a decode would take 1.6 GB; 32 MB is far above a header's read.
  constexpr long kMaxGrowthKb = 32 * 1024;
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    const long before = MaxRssKb();
    const bool refused = !ReadImage8(png.string(), InputBudget{}).ok();
    _exit(refused && MaxRssKb() - before < kMaxGrowthKb ? 0 : 1);
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "the refusal grew the peak RSS by 32 MB or more";
  fs::remove(png);
}

TEST(InputBudget, ImageWithinTheBudgetIsRead) {
  const fs::path png = TempPath("ok.png");
  ASSERT_TRUE(WritePng8(png.string(), Image8(100, 50).view()).ok());
  InputBudget budget;
  budget.max_image_pixels = 5000;  // exactly 100 x 50: the limit is inclusive
  const absl::StatusOr<Image8> image = ReadImage8(png.string(), budget);
  ASSERT_TRUE(image.ok()) << image.status();
  EXPECT_EQ(image->width, 100);
  budget.max_image_pixels = 4999;
  EXPECT_EQ(ReadImage8(png.string(), budget).status().message(),
            png.string() +
                ": 5000 pixels exceed the budget of 4999 "
                "(input_budget.max_image_pixels)");
  fs::remove(png);
}

TEST(InputBudget, SparseTwoGigabyteCanLogIsRefusedByBytesUnread) {
  const fs::path log = TempPath("can.log");
  WriteBytes(log, "");
  constexpr std::uintmax_t kTwoGiB = std::uintmax_t{2} << 30;
  fs::resize_file(log, kTwoGiB);  // sparse: no disk space, and no read should happen
  const absl::StatusOr<std::vector<CanFrame>> frames = ReadCandumpLog(log, InputBudget{});
  ASSERT_FALSE(frames.ok());
  EXPECT_EQ(frames.status().message(), log.string() +
                                           ": 2147483648 bytes exceed the budget of 1073741824 "
                                           "(input_budget.max_file_bytes)");
  fs::remove(log);
}

TEST(InputBudget, CanLogOverTheLineBudgetIsRefused) {
  const fs::path log = TempPath("can.log");
  std::string text;
  for (int i = 0; i < 11; ++i) text += "(1600000000.000000) can0 701#00\n";
  WriteBytes(log, text);
  InputBudget budget;
  budget.max_can_lines = 10;
  const absl::StatusOr<std::vector<CanFrame>> frames = ReadCandumpLog(log, budget);
  ASSERT_FALSE(frames.ok());
  EXPECT_EQ(frames.status().message(), log.string() +
                                           ": 11 or more lines exceed the budget of 10 "
                                           "(input_budget.max_can_lines)");
  budget.max_can_lines = 11;
  const absl::StatusOr<std::vector<CanFrame>> all = ReadCandumpLog(log, budget);
  ASSERT_TRUE(all.ok()) << all.status();
  EXPECT_EQ(all->size(), 11u);
  fs::remove(log);
}

// A compressed PCD whose 12 MB (sparse) body could, at LZF's ratio, hold the 100M points of
// 12 bytes its header claims: refused from the header, before the 1.2 GB buffer.
TEST(InputBudget, PcdClaimingHundredMillionPointsIsRefused) {
  const fs::path pcd = TempPath("scan.pcd");
  const std::string header =
      "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 100000000\n"
      "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 100000000\nDATA binary_compressed\n";
  WriteBytes(pcd, header);
  fs::resize_file(pcd, header.size() + (12u << 20));
  const absl::StatusOr<PcdCloud> cloud = ReadPcd(pcd, InputBudget{});
  ASSERT_FALSE(cloud.ok());
  EXPECT_EQ(cloud.status().message(), pcd.string() +
                                          ": 100000000 points exceed the budget of 5000000 "
                                          "(input_budget.max_scan_points)");
  fs::remove(pcd);
}

TEST(InputBudget, PcdFileAndDecodedDataAreHeldToTheByteBudget) {
  const fs::path pcd = TempPath("scan.pcd");
  const std::string header =
      "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 100\n"
      "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 100\nDATA binary_compressed\n";
  // 100 bytes of body: within LZF's ratio of the 1200 bytes the header announces.
  WriteBytes(pcd, header + std::string(100, '\0'));
  const std::int64_t file_bytes = static_cast<std::int64_t>(header.size()) + 100;
  InputBudget budget;
  budget.max_file_bytes = file_bytes - 1;
  EXPECT_EQ(ReadPcd(pcd, budget).status().message(),
            pcd.string() + ": " + std::to_string(file_bytes) + " bytes exceed the budget of " +
                std::to_string(file_bytes - 1) + " (input_budget.max_file_bytes)");
  // The file fits, the 100 x 12 bytes it decodes to do not.
  budget.max_file_bytes = 1000;
  EXPECT_EQ(ReadPcd(pcd, budget).status().message(),
            pcd.string() +
                ": decoded point data: 1200 bytes exceed the budget of 1000 "
                "(input_budget.max_file_bytes)");
  budget.max_file_bytes = 1200;
  budget.max_scan_points = 99;
  EXPECT_EQ(ReadPcd(pcd, budget).status().message(),
            pcd.string() + ": 100 points exceed the budget of 99 (input_budget.max_scan_points)");
  fs::remove(pcd);
}

// Parse errors name the file and line, and quote at most a short, sanitized token: a "log"
// that is really a secret does not end up in a message (and from there in a stored result).
TEST(InputBudget, CanLogErrorsDoNotQuoteTheFile) {
  const absl::StatusOr<std::vector<CanFrame>> one =
      ParseCandumpLog("password=hunter2-and-the-rest-of-the-secret\n", "can.log");
  ASSERT_FALSE(one.ok());
  EXPECT_EQ(one.status().message(),
            "can.log:1: expected '(seconds.micros) interface ID#DATA', got 1 field(s)");
  const absl::StatusOr<std::vector<CanFrame>> three =
      ParseCandumpLog("\n(1.0) can0 SECRET0123456789abcdefSECRET\n", "can.log");
  ASSERT_FALSE(three.ok());
  EXPECT_EQ(three.status().message(), "can.log:2: no '#' in frame 'SECRET0123456789abcd...'");
  EXPECT_EQ(Snippet("a\x01\xff"
                    "bcdefghijklmnop"),
            "'a??bcdefghij...'");
}

TEST(InputBudget, ValidateNamesTheKey) {
  EXPECT_TRUE(InputBudget{}.Validate().ok());
  InputBudget b;
  b.max_can_lines = 0;
  EXPECT_EQ(b.Validate().message(), "input_budget.max_can_lines: must be >= 1, got 0");
}

}  // namespace
}  // namespace linecal

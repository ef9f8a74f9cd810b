// linecald's log (daemon/log/daemon_log.h): logfmt lines through spdlog, filtered by level,
// and every line a cycle logs carrying its cycle id and VIN.
#include "daemon/log/daemon_log.h"

#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>

#include <filesystem>
#include <memory>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "daemon/core/station_core.h"
#include "tests/daemon/scratch_dir.h"
#include "tests/daemon/test_car.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

// Routes spdlog's default logger into a string for one test, then back to stderr (the
// stream dies with the test).
class CapturedLog {
 public:
  explicit CapturedLog(LogLevel level) {
    InstallDaemonLog(level, std::make_shared<spdlog::sinks::ostream_sink_mt>(out_));
  }
  ~CapturedLog() { InstallDaemonLog(LogLevel::kInfo); }
  std::vector<std::string> Lines() const {
    return absl::StrSplit(out_.str(), '\n', absl::SkipEmpty());
  }

 private:
  std::ostringstream out_;
};

TEST(DaemonLogTest, LinesAreKeyValuePairsWithTheMessageQuoted) {
  EXPECT_EQ(FormatLogFields({LogLevel::kInfo, "listening on 127.0.0.1:0 (port 4242)"}),
            "msg=\"listening on 127.0.0.1:0 (port 4242)\"");
  EXPECT_EQ(FormatLogFields({LogLevel::kError, "say \"hi\"\nC:\\ no"}),
            "msg=\"say \\\"hi\\\"\\nC:\\\\ no\"");
  EXPECT_EQ(FormatLogFields({LogLevel::kDebug, "event started", 12, "1M8GDM9AXKP042788"}),
            "msg=\"event started\" cycle=12 vin=1M8GDM9AXKP042788");
}

TEST(DaemonLogTest, LevelsNameAndFilter) {
  for (LogLevel l : {LogLevel::kDebug, LogLevel::kInfo, LogLevel::kWarning, LogLevel::kError}) {
    EXPECT_EQ(ParseLogLevel(LogLevelName(l)), l);
  }
  EXPECT_EQ(ParseLogLevel("verbose"), std::nullopt);
  const CapturedLog log(LogLevel::kWarning);
  WriteLog({LogLevel::kInfo, "hidden"});
  WriteLog({LogLevel::kWarning, "shown"});
  WriteLog({LogLevel::kError, "also shown", 3, "1M8GDM9AXKP042788"});
  EXPECT_EQ(log.Lines(), (std::vector<std::string>{
                             "level=warning msg=\"shown\"",
                             "level=error msg=\"also shown\" cycle=3 vin=1M8GDM9AXKP042788"}));
}

// A simulator cycle of the two-sensor car through the core's default log (WriteLog) at
// debug: its start, each event and its end are logged, each line ending in its cycle and VIN.
TEST(DaemonLogTest, EveryLineOfACycleCarriesItsCycleIdAndVin) {
  const fs::path dir = testing_daemon::FreshTestDir("daemon_log");
  testing_daemon::WriteTwoSensorCar((dir / "car.json").string(), "two_sensor");
  StationCoreConfig config;
  config.station_path = std::string(LINECAL_SOURCE_DIR) + "/deploy/stations/reference.json";
  config.car_model_paths = {(dir / "car.json").string()};
  config.db_path = (dir / "station.db").string();
  config.data_root = (dir / "data").string();
  const std::string vin = "1M8GDM9AXKP042788";
  std::vector<std::string> lines;
  int64_t id = 0;
  {
    const CapturedLog log(LogLevel::kDebug);
    absl::StatusOr<std::unique_ptr<StationCore>> core = StationCore::Create(config);
    ASSERT_TRUE(core.ok()) << core.status();
    CycleRequest request;
    request.vin = vin;
    request.car_model_id = "two_sensor";
    request.aligner = {0.012, -0.008, 0.05 * std::numbers::pi / 180};
    absl::StatusOr<int64_t> started = (*core)->StartCycle(request);
    ASSERT_TRUE(started.ok()) << started.status();
    id = *started;
    (*core)->WaitIdle();
    lines = log.Lines();
  }
  fs::remove_all(dir);
  // started, sensor_acquired x2, sensor_verdict x2, cycle_ended: six events, and the two
  // info lines of the start and the end.
  ASSERT_EQ(lines.size(), 8u) << testing::PrintToString(lines);
  const std::string fields = absl::StrCat(" cycle=", id, " vin=", vin);
  for (const std::string& line : lines) {
    EXPECT_EQ(line.rfind("level=", 0), 0u) << line;
    EXPECT_TRUE(line.ends_with(fields)) << line;
  }
  EXPECT_EQ(lines.front(), absl::StrCat("level=info msg=\"cycle ", id,
                                        " started (car model two_sensor)\"", fields));
  EXPECT_EQ(lines[1], absl::StrCat("level=debug msg=\"event started: two_sensor\"", fields));
  EXPECT_EQ(
      lines.back().rfind(absl::StrCat("level=info msg=\"cycle ", id, " ended done, verdict "), 0),
      0u)
      << lines.back();
}

}  // namespace
}  // namespace linecal

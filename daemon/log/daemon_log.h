#pragma once
// linecald's log: leveled records, one line each, written through spdlog (thread-safe, the
// level of the configuration's log_level), machine-readable as key=value pairs (logfmt):
//   level=info msg="cycle 12 started (car model reference)" cycle=12 vin=1M8GDM9AXKP042788
//   level=warning msg="plant database: connection refused; ..."
// msg is quoted with its quotes and backslashes escaped and its line breaks as \n, so a line
// splits into its pairs whatever the message holds. Every line about a cycle (logged while
// it runs, or about its end) carries cycle=<id> vin=<VIN>.
// The daemon's parts (station core, plant forwarder, listener watchdog) log through a
// LogSink their options give; linecald's writes to spdlog's default logger (WriteLog).

#include <spdlog/common.h>

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <utility>

namespace linecal {

enum class LogLevel { kDebug, kInfo, kWarning, kError };

// "debug", "info", "warning", "error": the words of log_level and of the lines.
const char* LogLevelName(LogLevel level);
// The inverse of LogLevelName; nullopt for any other word.
std::optional<LogLevel> ParseLogLevel(std::string_view name);

struct LogRecord {
  LogRecord(LogLevel level, std::string message, int64_t cycle = 0, std::string vin = "")
      : level(level), message(std::move(message)), cycle(cycle), vin(std::move(vin)) {}

  LogLevel level = LogLevel::kInfo;
  std::string message;
  int64_t cycle = 0;  // the cycle the line is about; 0: none
  std::string vin;    // that cycle's VIN
};

// Where a part of the daemon hands its records.
using LogSink = std::function<void(const LogRecord& record)>;

// The line of `record` after its level: msg="..." and, for a cycle, cycle=<id> vin=<VIN>.
// Pure; O(message).
std::string FormatLogFields(const LogRecord& record);

// Makes spdlog's default logger linecald's: records at `level` and above, each a line
// "level=<level> <FormatLogFields>" to `sink` (null: stderr, unbuffered). Call it before
// other threads log (spdlog::set_default_logger is not safe against concurrent logging).
void InstallDaemonLog(LogLevel level, spdlog::sink_ptr sink = nullptr);

// Writes `record` through spdlog's default logger; before InstallDaemonLog, to stderr at
// level info. Thread-safe.
void WriteLog(const LogRecord& record);

}  // namespace linecal

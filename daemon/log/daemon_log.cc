#include "daemon/log/daemon_log.h"

#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <memory>
#include <mutex>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

spdlog::level::level_enum ToSpdlog(LogLevel level) {
  switch (level) {
    case LogLevel::kDebug:
      return spdlog::level::debug;
    case LogLevel::kInfo:
      return spdlog::level::info;
    case LogLevel::kWarning:
      return spdlog::level::warn;
    case LogLevel::kError:
      return spdlog::level::err;
  }
  return spdlog::level::info;
}

std::string Quoted(std::string_view text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (c == '\n') {
      out += "\\n";
    } else {
      out += c;
    }
  }
  return out + "\"";
}

std::atomic<bool> installed{false};
std::once_flag default_installed;

}  // namespace

const char* LogLevelName(LogLevel level) {
  switch (level) {
    case LogLevel::kDebug:
      return "debug";
    case LogLevel::kInfo:
      return "info";
    case LogLevel::kWarning:
      return "warning";
    case LogLevel::kError:
      return "error";
  }
  return "info";
}

std::optional<LogLevel> ParseLogLevel(std::string_view name) {
  for (LogLevel l : {LogLevel::kDebug, LogLevel::kInfo, LogLevel::kWarning, LogLevel::kError}) {
    if (name == LogLevelName(l)) return l;
  }
  return std::nullopt;
}

std::string FormatLogFields(const LogRecord& record) {
  std::string line = absl::StrCat("msg=", Quoted(record.message));
  if (record.cycle != 0) absl::StrAppend(&line, " cycle=", record.cycle, " vin=", record.vin);
  return line;
}

void InstallDaemonLog(LogLevel level, spdlog::sink_ptr sink) {
  if (!sink) sink = std::make_shared<spdlog::sinks::stderr_sink_mt>();
  auto logger = std::make_shared<spdlog::logger>("linecald", std::move(sink));
  // spdlog's name of its warn level is "warning"; the record's fields follow the level.
  logger->set_pattern("level=%l %v");
  logger->set_level(ToSpdlog(level));
  // Each line reaches journald or the log file as it is written, errors or not.
  logger->flush_on(spdlog::level::trace);
  spdlog::set_default_logger(std::move(logger));
  installed = true;
}

void WriteLog(const LogRecord& record) {
  if (!installed) {
    std::call_once(default_installed, [] {
      if (!installed) InstallDaemonLog(LogLevel::kInfo);
    });
  }
  spdlog::default_logger_raw()->log(ToSpdlog(record.level), "{}", FormatLogFields(record));
}

}  // namespace linecal

// linecal capture check DIR: validates a capture (docs/capture-format.md).
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>

#include "absl/strings/str_cat.h"
#include "station/capture/capture.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"
#include "tools/linecal/input_budget_flags.h"

namespace linecal::tools {

int RunCaptureCheck(const Args& args) {
  std::vector<cli::OptionSpec> options = {
      {"DIR", "", "the capture directory", /*required=*/true, /*repeated=*/false,
       /*positional=*/true},
      {"json", "", "print the summary as JSON"}};
  for (cli::OptionSpec& o : InputBudgetOptions()) options.push_back(std::move(o));
  cli::CommandLine cl("linecal capture check DIR [--json] [--max-image-pixels N ...]",
                      "Validates a capture directory: manifest, station and car files, every "
                      "sensor's data files (read as calibrate reads them: frames decoded, scans "
                      "and CAN logs parsed, within the input budget). Exit 0 when valid, 2 with "
                      "the offending path and field otherwise.",
                      std::move(options));
  if (auto code = cli::ParseOrExit(cl, "capture check", args)) return *code;
  const absl::StatusOr<InputBudget> budget = InputBudgetFromFlags(cl);
  if (!budget.ok()) return cli::BadInput("capture check", std::string(budget.status().message()));
  absl::StatusOr<Capture> c = ReadCapture(cl.Get("DIR"), *budget);
  if (!c.ok()) return cli::BadInput("capture check", std::string(c.status().message()));
  // The data through the readers calibration uses, under the same budget (CheckCaptureData).
  if (absl::Status s = CheckCaptureData(*c); !s.ok()) {
    return cli::BadInput("capture check", std::string(s.message()));
  }

  const CaptureManifest& m = c->manifest;
  if (cl.Has("json")) {
    nlohmann::json sensors = nlohmann::json::array();
    for (const CaptureSensor& s : m.sensors) {
      sensors.push_back({{"name", s.name},
                         {"kind", SensorKindName(s.kind)},
                         {"frames", s.frames.size()},
                         {"packets", s.packets.has_value()},
                         {"can_log", s.can_log.has_value()}});
    }
    const nlohmann::json out = {{"valid", true},      {"version", m.version},
                                {"vin", m.vin},       {"car_model", m.car_model},
                                {"origin", m.origin}, {"station", c->station.name},
                                {"sensors", sensors}};
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    std::printf("capture %s: valid (format v%d, %s)\n", c->dir.c_str(), m.version,
                m.origin.c_str());
    std::printf("  VIN %s, car model %s, station %s\n", m.vin.c_str(), m.car_model.c_str(),
                c->station.name.c_str());
    for (const CaptureSensor& s : m.sensors) {
      std::printf("  %-20s %-7s %zu frame(s)%s%s\n", s.name.c_str(), SensorKindName(s.kind),
                  s.frames.size(), s.packets ? ", packets" : "", s.can_log ? ", CAN log" : "");
    }
  }
  return cli::kExitOk;
}

}  // namespace linecal::tools

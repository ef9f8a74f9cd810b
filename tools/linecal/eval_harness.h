#pragma once
// The harness of the `linecal eval ...` commands: their common flags, the loop over random
// cars (or trials) with its progress line, the bars every evaluation holds the reported
// uncertainty to, and the output as a table or as one JSON object. Each command keeps what is
// its own: its simulation, its statistics, its columns and its bars (eval_stats.h holds the
// statistics they share).

#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_format.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/eval_stats.h"

namespace linecal::tools {

// The reported 1-sigma against the spread of the errors (docs/acceptance.md, "Solvers"): RMS
// error / RMS sigma within [0.8, 1.2], and the 95% intervals cover 93..97% of the errors.
inline constexpr double kSigmaRatioLow = 0.8, kSigmaRatioHigh = 1.2;
inline constexpr double kCoverageLow = 0.93, kCoverageHigh = 0.97;
// Radar yaw p95 (docs/acceptance.md, "Solvers" and "Uncertainty on the full-physics
// evaluation"), and a wrong verdict is allowed only with the truth within this many σ of a
// tolerance edge (the latter section).
inline constexpr double kRadarYawP95BarDeg = 0.05;
inline constexpr double kWrongVerdictEdgeSigmas = 1.0;

// The flags of an evaluation over random cars: --station, --car (their targets must exist in
// the station), --cars (default 200, [1, 100000]: 200 put the 95th percentiles and the
// coverage within about +-1.5 percentage points), --seed (default 1) and --frames
// (`default_frames`, [1, 100]). The error names the flag or the file.
struct EvalInputs {
  StationLayout station;
  CarModel car;
  int cars = 0;
  int seed = 0;
  int frames = 0;
};
// --station and --car into `in`; the error names the file. Reads both files.
absl::Status ReadStationAndCar(const cli::CommandLine& cl, EvalInputs* in);
// --cars and --seed into `in`; the error names the flag and the value.
absl::Status ReadCarsAndSeed(const cli::CommandLine& cl, EvalInputs* in);
// All of the above in this order: station, car, cars, seed, frames, then the targets' check.
absl::StatusOr<EvalInputs> ReadEvalInputs(const cli::CommandLine& cl, int default_frames);

// Runs trial(0) .. trial(count - 1) in order and prints "<label>: i / count cars" to stderr
// after every `progress_every`-th. Stops at the first trial that fails and returns its error.
absl::Status RunTrials(int count, int progress_every, std::string_view label,
                       const std::function<absl::Status(int)>& trial);

// Whether every component's error/sigma and coverage are within the bars above.
bool SigmaMeetsBars(const MountingSummary& s);
// The largest of the p95 |errors| of yaw, pitch, roll (radians) and of x, y, z (metres).
double MaxAngleP95(const MountingSummary& s);
double MaxPositionP95(const MountingSummary& s);

// "reason count, reason count" in the map's order; empty for no reasons. O(size).
std::string ReasonsText(const std::map<std::string, int>& reasons);

// Adds per component (yaw .. z) of a mounting evaluation "<c>_p95_abs_error_deg" (angles) or
// "_mm" (positions), "<c>_error_over_sigma" and "<c>_coverage95" to `row`.
void AddMountingColumns(const MountingSummary& s, nlohmann::json* row);

// The output of an evaluation: a table printed as it goes (no --json), or with --json one
// JSON document printed at the end.
class EvalReport {
 public:
  explicit EvalReport(const cli::CommandLine& cl) : json_(cl.Has("json")) {}

  bool json() const { return json_; }
  // Prints a piece of the table to stdout, printf-style; nothing with --json.
  template <typename... Args>
  void Table(const absl::FormatSpec<Args...>& format, const Args&... args) const {
    if (!json_) absl::PrintF(format, args...);
  }
  // A row of the JSON document.
  void AddRow(nlohmann::json row) { rows_.push_back(std::move(row)); }

  // Ends the output and returns the exit code: 0 when `meets`, else 1. With --json prints
  // `run` with the rows under `rows_key` and "meets_bars", or the rows alone when `rows_key`
  // is empty; else nothing.
  int Finish(nlohmann::json run, const std::string& rows_key, bool meets) const;

 private:
  bool json_;
  nlohmann::json rows_ = nlohmann::json::array();
};

}  // namespace linecal::tools

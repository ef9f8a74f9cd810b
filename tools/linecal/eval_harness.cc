#include "tools/linecal/eval_harness.h"

#include <algorithm>
#include <cstdio>

#include "absl/strings/str_cat.h"

namespace linecal::tools {

absl::Status ReadStationAndCar(const cli::CommandLine& cl, EvalInputs* in) {
  absl::StatusOr<StationLayout> station = ReadStationLayout(cl.Get("station"));
  if (!station.ok()) return station.status();
  in->station = *std::move(station);
  absl::StatusOr<CarModel> car = ReadCarModel(cl.Get("car"));
  if (!car.ok()) return car.status();
  in->car = *std::move(car);
  return absl::OkStatus();
}

absl::Status ReadCarsAndSeed(const cli::CommandLine& cl, EvalInputs* in) {
  const absl::StatusOr<int> cars = cl.GetInt("cars", 200);
  if (!cars.ok()) return cars.status();
  if (*cars < 1 || *cars > 100000) {
    return absl::InvalidArgumentError(absl::StrCat("--cars: ", *cars, ": must be in [1, 100000]"));
  }
  const absl::StatusOr<int> seed = cl.GetInt("seed", 1);
  if (!seed.ok()) return seed.status();
  in->cars = *cars;
  in->seed = *seed;
  return absl::OkStatus();
}

absl::StatusOr<EvalInputs> ReadEvalInputs(const cli::CommandLine& cl, int default_frames) {
  EvalInputs in;
  if (absl::Status s = ReadStationAndCar(cl, &in); !s.ok()) return s;
  if (absl::Status s = ReadCarsAndSeed(cl, &in); !s.ok()) return s;
  const absl::StatusOr<int> frames = cl.GetInt("frames", default_frames);
  if (!frames.ok()) return frames.status();
  if (*frames < 1 || *frames > 100) {
    return absl::InvalidArgumentError(absl::StrCat("--frames: ", *frames, ": must be in [1, 100]"));
  }
  if (absl::Status s = CheckTargetsExist(in.car, in.station); !s.ok()) return s;
  in.frames = *frames;
  return in;
}

absl::Status RunTrials(int count, int progress_every, std::string_view label,
                       const std::function<absl::Status(int)>& trial) {
  for (int i = 0; i < count; ++i) {
    if (absl::Status s = trial(i); !s.ok()) return s;
    if ((i + 1) % progress_every == 0) {
      std::fprintf(stderr, "%.*s: %d / %d cars\n", static_cast<int>(label.size()), label.data(),
                   i + 1, count);
    }
  }
  return absl::OkStatus();
}

bool SigmaMeetsBars(const MountingSummary& s) {
  return s.ratio_lo >= kSigmaRatioLow && s.ratio_hi <= kSigmaRatioHigh &&
         s.cover_lo >= kCoverageLow && s.cover_hi <= kCoverageHigh;
}

double MaxAngleP95(const MountingSummary& s) {
  return std::max({s.stats[0].p95_abs_error, s.stats[1].p95_abs_error, s.stats[2].p95_abs_error});
}

double MaxPositionP95(const MountingSummary& s) {
  return std::max({s.stats[3].p95_abs_error, s.stats[4].p95_abs_error, s.stats[5].p95_abs_error});
}

std::string ReasonsText(const std::map<std::string, int>& reasons) {
  std::string text;
  for (const auto& [reason, count] : reasons) {
    absl::StrAppend(&text, text.empty() ? "" : ", ", reason, " ", count);
  }
  return text;
}

void AddMountingColumns(const MountingSummary& s, nlohmann::json* row) {
  static const char* const kComponents[6] = {"yaw", "pitch", "roll", "x", "y", "z"};
  constexpr double kRadToDeg = 180.0 / std::numbers::pi;
  for (int i = 0; i < 6; ++i) {
    const double scale = i < 3 ? kRadToDeg : 1e3;
    const std::string unit = i < 3 ? "_deg" : "_mm";
    (*row)[absl::StrCat(kComponents[i], "_p95_abs_error", unit)] = s.stats[i].p95_abs_error * scale;
    (*row)[absl::StrCat(kComponents[i], "_error_over_sigma")] = s.stats[i].error_over_sigma;
    (*row)[absl::StrCat(kComponents[i], "_coverage95")] = s.stats[i].coverage95;
  }
}

int EvalReport::Finish(nlohmann::json run, const std::string& rows_key, bool meets) const {
  if (json_) {
    if (rows_key.empty()) {
      run = rows_;
    } else {
      run[rows_key] = rows_;
      run["meets_bars"] = meets;
    }
    std::printf("%s\n", run.dump(2).c_str());
  }
  return meets ? cli::kExitOk : cli::kExitNegative;
}

}  // namespace linecal::tools

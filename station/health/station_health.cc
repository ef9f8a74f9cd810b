#include "station/health/station_health.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <optional>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

constexpr double kRadToDeg = 180.0 / std::numbers::pi;

struct Baseline {
  double mean = 0, sigma = 0;
};

// Mean and sample σ of values[0, n); σ 0 when n < min_points.
Baseline BaselineOf(const std::vector<double>& values, size_t n, const StationHealthOptions& o) {
  Baseline b;
  if (n < static_cast<size_t>(o.min_baseline)) return b;
  double sum = 0;
  for (size_t i = 0; i < n; ++i) sum += values[i];
  b.mean = sum / static_cast<double>(n);
  double ss = 0;
  for (size_t i = 0; i < n; ++i) ss += (values[i] - b.mean) * (values[i] - b.mean);
  b.sigma = std::max(std::sqrt(ss / static_cast<double>(n - 1)), o.min_sigma);
  return b;
}

// σ of an EWMA started at its mean, i points in, in σ of the points.
double EwmaSigma(double lambda, int i) {
  return std::sqrt(lambda / (2.0 - lambda) * (1.0 - std::pow(1.0 - lambda, 2.0 * i)));
}

HealthSeries MakeSeries(int s, const std::vector<int64_t>& ids, std::vector<double> values,
                        double tolerance, const StationHealthOptions& o) {
  HealthSeries out;
  out.name = HealthSeriesName(s);
  out.cycle_ids = ids;
  out.values = std::move(values);
  out.tolerance = tolerance;
  const size_t n = out.values.size();
  const size_t baseline_n = n > static_cast<size_t>(o.recent_cars) ? n - o.recent_cars : 0;
  const Baseline b = BaselineOf(out.values, baseline_n, o);
  out.mean = b.mean;
  out.sigma = b.sigma;
  double z = b.sigma > 0 ? b.mean : (n > 0 ? out.values[0] : 0);
  out.ewma.reserve(n);
  out.lower.reserve(b.sigma > 0 ? n : 0);
  out.upper.reserve(b.sigma > 0 ? n : 0);
  // (1 − λ)^{2i} kept as a running product: pow() of an underflowing power is slow.
  double decay = 1;
  for (size_t i = 0; i < n; ++i) {
    z = o.lambda * out.values[i] + (1 - o.lambda) * z;
    out.ewma.push_back(z);
    decay *= (1 - o.lambda) * (1 - o.lambda);
    if (b.sigma > 0) {
      const double half =
          o.chart_sigmas * b.sigma * std::sqrt(o.lambda / (2.0 - o.lambda) * (1.0 - decay));
      out.lower.push_back(b.mean - half);
      out.upper.push_back(b.mean + half);
    }
  }
  return out;
}

std::array<double, kHealthSeries> Tolerances(const SensorModel& m) {
  return {m.tolerance.yaw_rad * kRadToDeg,
          m.tolerance.pitch_rad * kRadToDeg,
          m.tolerance.roll_rad * kRadToDeg,
          m.tolerance.xyz_m.x(),
          m.tolerance.xyz_m.y(),
          m.tolerance.xyz_m.z(),
          0.0};
}

// The alarm of the targets used by exactly `users` (sensor indices of `car`), judged over the
// last recent_cars cycles of the car model in which all of them were solved.
std::optional<TargetAlarm> JudgeTargets(const CarModel& car, const std::vector<size_t>& users,
                                        const std::vector<std::vector<const double*>>& residuals,
                                        const std::vector<int64_t>& ids,
                                        const StationHealthOptions& o) {
  // Cycles in which every user has a residual.
  std::vector<size_t> rows;
  for (size_t c = 0; c < ids.size(); ++c) {
    bool all = true;
    for (size_t u : users) all = all && residuals[u][c] != nullptr;
    if (all) rows.push_back(c);
  }
  const size_t recent = static_cast<size_t>(o.recent_cars);
  if (rows.size() < recent + static_cast<size_t>(o.min_baseline)) return std::nullopt;
  const size_t first_recent = rows.size() - recent;
  std::vector<Baseline> base;
  for (size_t u : users) {
    std::vector<double> v;
    for (size_t r = 0; r < first_recent; ++r) v.push_back(*residuals[u][rows[r]]);
    base.push_back(BaselineOf(v, v.size(), o));
  }
  const double norm = std::sqrt(static_cast<double>(users.size()));
  double z = 0;
  std::vector<double> combined;
  for (size_t r = first_recent; r < rows.size(); ++r) {
    double sum = 0;
    for (size_t k = 0; k < users.size(); ++k) {
      sum += (*residuals[users[k]][rows[r]] - base[k].mean) / base[k].sigma;
    }
    combined.push_back(sum / norm);
    z = o.lambda * combined.back() + (1 - o.lambda) * z;
  }
  // The rise's first cycle: the start of the recent tail with the largest sum, the maximum
  // likelihood change point of a step in the mean (Hinkley 1970).
  size_t rise = first_recent;
  double tail = 0, best = -1;
  for (size_t i = combined.size(); i-- > 0;) {
    tail += combined[i];
    if (tail > best) {
      best = tail;
      rise = first_recent + i;
    }
  }
  const double statistic = z / EwmaSigma(o.lambda, static_cast<int>(recent));
  if (!(statistic > o.alarm_sigmas)) return std::nullopt;
  TargetAlarm alarm;
  alarm.car_model = car.id;
  alarm.since_cycle = ids[rows[rise]];
  alarm.last_cycle = ids[rows.back()];
  alarm.statistic_sigmas = statistic;
  alarm.alarm_sigmas = o.alarm_sigmas;
  for (size_t k = 0; k < users.size(); ++k) {
    ShiftedSensor s;
    s.sensor = car.sensors[users[k]].name;
    s.baseline_residual = base[k].mean;
    double sum = 0;
    for (size_t r = rise; r < rows.size(); ++r) sum += *residuals[users[k]][rows[r]];
    s.recent_residual = sum / static_cast<double>(rows.size() - rise);
    s.shift_sigmas = (s.recent_residual - base[k].mean) / base[k].sigma;
    alarm.sensors.push_back(s);
  }
  return alarm;
}

}  // namespace

const char* HealthSeriesName(int series) {
  static constexpr const char* kNames[kHealthSeries] = {
      "yaw_deg", "pitch_deg", "roll_deg", "x_m", "y_m", "z_m", "residual_rms"};
  return series >= 0 && series < kHealthSeries ? kNames[series] : "";
}

absl::Status StationHealthOptions::Validate() const {
  if (!(lambda > 0 && lambda <= 1)) return absl::InvalidArgumentError("lambda: must be in (0, 1]");
  if (!(chart_sigmas > 0)) return absl::InvalidArgumentError("chart_sigmas: must be > 0");
  if (!(alarm_sigmas > 0)) return absl::InvalidArgumentError("alarm_sigmas: must be > 0");
  if (recent_cars < 1) return absl::InvalidArgumentError("recent_cars: must be >= 1");
  if (min_baseline < 2) return absl::InvalidArgumentError("min_baseline: must be >= 2");
  if (min_sensors < 1) return absl::InvalidArgumentError("min_sensors: must be >= 1");
  if (!(min_sigma > 0)) return absl::InvalidArgumentError("min_sigma: must be > 0");
  return absl::OkStatus();
}

absl::StatusOr<StationHealth> ComputeStationHealth(const std::vector<CarModel>& cars,
                                                   const std::vector<HealthCycle>& cycles,
                                                   const StationHealthOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  for (size_t i = 1; i < cycles.size(); ++i) {
    if (cycles[i].cycle_id <= cycles[i - 1].cycle_id) {
      return absl::InvalidArgumentError(absl::StrCat(
          "cycles: ids must increase, got ", cycles[i - 1].cycle_id, " then ", cycles[i].cycle_id));
    }
  }
  StationHealth health;
  for (const CarModel& car : cars) {
    // This model's cycles, and per sensor its result in each (nullptr: none solved).
    std::vector<int64_t> ids;
    std::vector<std::vector<const HealthResult*>> results(car.sensors.size());
    for (const HealthCycle& c : cycles) {
      if (c.car_model != car.id) continue;
      ids.push_back(c.cycle_id);
      for (auto& r : results) r.push_back(nullptr);
      for (const HealthResult& r : c.results) {
        const SensorModel* m = car.FindSensor(r.sensor);
        if (m != nullptr) results[static_cast<size_t>(m - car.sensors.data())].back() = &r;
      }
    }
    if (ids.empty()) continue;
    std::vector<std::vector<const double*>> residuals(car.sensors.size());
    for (size_t s = 0; s < car.sensors.size(); ++s) {
      const SensorModel& m = car.sensors[s];
      SensorTrend trend{car.id, m.name, SensorKindName(m.kind), m.targets, {}};
      const std::array<double, kHealthSeries> tolerance = Tolerances(m);
      std::vector<int64_t> solved_ids;
      std::array<std::vector<double>, kHealthSeries> values;
      for (size_t c = 0; c < ids.size(); ++c) {
        const HealthResult* r = results[s][c];
        residuals[s].push_back(r == nullptr ? nullptr : &r->values[kResidualSeries]);
        if (r == nullptr) continue;
        solved_ids.push_back(ids[c]);
        for (int k = 0; k < kHealthSeries; ++k) values[k].push_back(r->values[k]);
      }
      for (int k = 0; k < kHealthSeries; ++k) {
        trend.series.push_back(
            MakeSeries(k, solved_ids, std::move(values[k]), tolerance[k], options));
      }
      health.trends.push_back(std::move(trend));
    }
    // Targets grouped by the sensors that use them.
    std::map<std::string, std::vector<size_t>> users_of;
    for (size_t s = 0; s < car.sensors.size(); ++s) {
      for (const std::string& t : car.sensors[s].targets) users_of[t].push_back(s);
    }
    std::map<std::vector<size_t>, std::vector<std::string>> groups;
    for (const auto& [target, users] : users_of) groups[users].push_back(target);
    std::vector<std::pair<std::vector<size_t>, TargetAlarm>> raised;
    for (const auto& [users, targets] : groups) {
      if (users.size() < static_cast<size_t>(options.min_sensors)) continue;
      std::optional<TargetAlarm> alarm = JudgeTargets(car, users, residuals, ids, options);
      if (!alarm) continue;
      alarm->targets = targets;
      raised.emplace_back(users, std::move(*alarm));
    }
    // Targets that share a sensor with a moved one see part of its shift (the front boards'
    // two cameras also use the bumper boards): the strongest alarm among those sharing
    // sensors is the explanation, and only it is named.
    std::sort(raised.begin(), raised.end(), [](const auto& a, const auto& b) {
      return a.second.statistic_sigmas > b.second.statistic_sigmas;
    });
    std::vector<const std::vector<size_t>*> kept;
    for (const auto& [users, alarm] : raised) {
      bool explained = false;
      for (const std::vector<size_t>* k : kept) {
        for (size_t u : users)
          explained = explained || std::find(k->begin(), k->end(), u) != k->end();
      }
      if (explained) continue;
      kept.push_back(&users);
      health.alarms.push_back(alarm);
    }
    for (const auto& [target, users] : users_of) {
      TargetCounts counts{car.id, target, ids, {}, static_cast<int>(users.size())};
      for (size_t c = 0; c < ids.size(); ++c) {
        int solved = 0;
        for (size_t u : users) solved += residuals[u][c] != nullptr ? 1 : 0;
        counts.solved.push_back(solved);
      }
      health.counts.push_back(std::move(counts));
    }
  }
  return health;
}

}  // namespace linecal

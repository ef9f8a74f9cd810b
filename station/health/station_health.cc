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

// The trend of `sensor` of `car` from its solved results in the model's cycles `ids`
// (results[c]: nullptr where it was not solved).
SensorTrend SensorTrendOf(const CarModel& car, const SensorModel& m,
                          const std::vector<const HealthResult*>& results,
                          const std::vector<int64_t>& ids, const StationHealthOptions& options) {
  SensorTrend trend{car.id, m.name, SensorKindName(m.kind), m.targets, {}};
  const std::array<double, kHealthSeries> tolerance = Tolerances(m);
  std::vector<int64_t> solved_ids;
  std::array<std::vector<double>, kHealthSeries> values;
  for (size_t c = 0; c < ids.size(); ++c) {
    const HealthResult* r = results[c];
    if (r == nullptr) continue;
    solved_ids.push_back(ids[c]);
    for (int k = 0; k < kHealthSeries; ++k) values[k].push_back(r->values[k]);
  }
  for (int k = 0; k < kHealthSeries; ++k) {
    trend.series.push_back(MakeSeries(k, solved_ids, std::move(values[k]), tolerance[k], options));
  }
  return trend;
}

// Per sensor of a car model (by index), one board's residual in each of the model's cycles
// (nullopt: none recorded).
using PairResiduals = std::vector<std::vector<std::optional<double>>>;

// The alarm of `target`, used by `users` (sensor indices of `car`) whose residuals of it are
// `residuals[u][c]` in cycle ids[c]: judged over the last recent_cars cycles in which at least
// min_sensors users have a residual of it, each user standardised by its own baseline (its
// residuals in the cycles before those; a user with fewer than min_baseline is left out).
std::optional<TargetAlarm> JudgeTarget(const CarModel& car, const std::string& target,
                                       const std::vector<size_t>& users,
                                       const PairResiduals& residuals,
                                       const std::vector<int64_t>& ids,
                                       const StationHealthOptions& o) {
  const size_t min_sensors = static_cast<size_t>(o.min_sensors);
  std::vector<size_t> rows;
  for (size_t c = 0; c < ids.size(); ++c) {
    size_t present = 0;
    for (size_t u : users) present += residuals[u][c].has_value() ? 1 : 0;
    if (present >= min_sensors) rows.push_back(c);
  }
  const size_t recent = static_cast<size_t>(o.recent_cars);
  if (rows.size() < recent + static_cast<size_t>(o.min_baseline)) return std::nullopt;
  const size_t first_recent = rows.size() - recent;
  std::vector<size_t> judged;
  std::vector<Baseline> base;
  // The mean of 1 / (baseline points) over the judged pairs: the variance, in the statistic's
  // units, of the error of the baseline means, which every recent point shares.
  double mean_error_variance = 0;
  for (size_t u : users) {
    std::vector<double> v;
    for (size_t r = 0; r < first_recent; ++r) {
      if (residuals[u][rows[r]]) v.push_back(*residuals[u][rows[r]]);
    }
    const Baseline b = BaselineOf(v, v.size(), o);
    if (b.sigma == 0) continue;
    judged.push_back(u);
    base.push_back(b);
    mean_error_variance += 1.0 / static_cast<double>(v.size());
  }
  if (judged.size() < min_sensors) return std::nullopt;
  mean_error_variance /= static_cast<double>(judged.size());
  double z = 0;
  std::vector<double> combined;
  for (size_t r = first_recent; r < rows.size(); ++r) {
    double sum = 0;
    int n = 0;
    for (size_t k = 0; k < judged.size(); ++k) {
      const std::optional<double>& x = residuals[judged[k]][rows[r]];
      if (!x) continue;
      sum += (*x - base[k].mean) / base[k].sigma;
      ++n;
    }
    combined.push_back(n > 0 ? sum / std::sqrt(static_cast<double>(n)) : 0.0);
    z = o.lambda * combined.back() + (1 - o.lambda) * z;
  }
  // The EWMA's σ over the recent cars and the baseline means' shared error: with 10 baseline
  // cars the latter is nearly as large (0.1 against 0.11 in variance), and left out it raised
  // false alarms on young baselines (tests/station/health).
  const double ewma_sigma = EwmaSigma(o.lambda, static_cast<int>(recent));
  const double statistic = z / std::sqrt(ewma_sigma * ewma_sigma + mean_error_variance);
  if (!(statistic > o.alarm_sigmas)) return std::nullopt;
  // The rise's first cycle: the start of the recent tail whose sum over the square root of
  // its length is highest, the maximum-likelihood change point of a rise of unknown size in
  // the mean of unit-variance points (Hinkley 1970). The bare sum would also take in the
  // cars before the move whenever their noise happens to sum above zero.
  size_t rise = first_recent;
  double tail = 0, best = -1;
  for (size_t i = combined.size(); i-- > 0;) {
    tail += combined[i];
    const double score = tail / std::sqrt(static_cast<double>(combined.size() - i));
    if (score > best) {
      best = score;
      rise = first_recent + i;
    }
  }
  TargetAlarm alarm;
  alarm.car_model = car.id;
  alarm.targets = {target};
  alarm.since_cycle = ids[rows[rise]];
  alarm.last_cycle = ids[rows.back()];
  alarm.statistic_sigmas = statistic;
  alarm.alarm_sigmas = o.alarm_sigmas;
  for (size_t k = 0; k < judged.size(); ++k) {
    ShiftedSensor s;
    s.sensor = car.sensors[judged[k]].name;
    s.baseline_residual = base[k].mean;
    double sum = 0;
    int n = 0;
    for (size_t r = rise; r < rows.size(); ++r) {
      if (const std::optional<double>& x = residuals[judged[k]][rows[r]]; x) {
        sum += *x;
        ++n;
      }
    }
    s.recent_residual = n > 0 ? sum / n : base[k].mean;
    s.shift_sigmas = (s.recent_residual - base[k].mean) / base[k].sigma;
    alarm.sensors.push_back(s);
  }
  return alarm;
}

// The sensors of `car` (indices) that use each target, by target id.
std::map<std::string, std::vector<size_t>> UsersOf(const CarModel& car) {
  std::map<std::string, std::vector<size_t>> users_of;
  for (size_t s = 0; s < car.sensors.size(); ++s) {
    for (const std::string& t : car.sensors[s].targets) users_of[t].push_back(s);
  }
  return users_of;
}

// Per target of `car`, its board records in `model_cycles` (oldest first), per sensor of the
// car (index) and cycle; nullptr where none. One pass over the records.
using BoardTable = std::map<std::string, std::vector<std::vector<const HealthBoard*>>>;
BoardTable BoardsByTarget(const CarModel& car,
                          const std::vector<const HealthCycle*>& model_cycles) {
  BoardTable table;
  for (const auto& [target, users] : UsersOf(car)) {
    table[target].assign(car.sensors.size(),
                         std::vector<const HealthBoard*>(model_cycles.size(), nullptr));
  }
  for (size_t c = 0; c < model_cycles.size(); ++c) {
    for (const HealthBoard& b : model_cycles[c]->boards) {
      const auto entry = table.find(b.board);
      const SensorModel* m = car.FindSensor(b.sensor);
      if (entry == table.end() || m == nullptr) continue;
      entry->second[static_cast<size_t>(m - car.sensors.data())][c] = &b;
    }
  }
  return table;
}

// The alarms of `car` at its newest cycle (`table`: BoardsByTarget of the cycles `ids`): every
// target judged (JudgeTarget), then, as a
// moved board also shifts the fits of the boards that share its sensors a little (the
// solvers spread it), only the strongest of alarms sharing a sensor is kept.
std::vector<TargetAlarm> CarAlarms(const CarModel& car, const BoardTable& table,
                                   const std::vector<int64_t>& ids,
                                   const StationHealthOptions& options) {
  std::vector<std::pair<std::vector<size_t>, TargetAlarm>> raised;
  for (const auto& [target, users] : UsersOf(car)) {
    if (users.size() < static_cast<size_t>(options.min_sensors)) continue;
    const std::vector<std::vector<const HealthBoard*>>& boards = table.at(target);
    PairResiduals residuals(car.sensors.size());
    for (size_t u = 0; u < car.sensors.size(); ++u) {
      for (const HealthBoard* b : boards[u]) {
        residuals[u].push_back(b != nullptr ? b->residual : std::nullopt);
      }
    }
    std::optional<TargetAlarm> alarm = JudgeTarget(car, target, users, residuals, ids, options);
    if (alarm) raised.emplace_back(users, std::move(*alarm));
  }
  std::sort(raised.begin(), raised.end(), [](const auto& a, const auto& b) {
    return a.second.statistic_sigmas > b.second.statistic_sigmas;
  });
  std::vector<TargetAlarm> kept;
  std::vector<const std::vector<size_t>*> kept_users;
  for (const auto& [users, alarm] : raised) {
    bool explained = false;
    for (const std::vector<size_t>* k : kept_users) {
      for (size_t u : users)
        explained = explained || std::find(k->begin(), k->end(), u) != k->end();
    }
    if (explained) continue;
    kept_users.push_back(&users);
    kept.push_back(alarm);
  }
  return kept;
}

// Per target of `car`, its detections in each of `model_cycles` that has board records
// (`table`: BoardsByTarget of them).
std::vector<TargetCounts> CarCounts(const CarModel& car, const BoardTable& table,
                                    const std::vector<const HealthCycle*>& model_cycles) {
  std::vector<TargetCounts> out;
  for (const auto& [target, users] : UsersOf(car)) {
    TargetCounts counts;
    counts.car_model = car.id;
    counts.target = target;
    counts.sensors = static_cast<int>(users.size());
    const std::vector<std::vector<const HealthBoard*>>& boards = table.at(target);
    for (size_t c = 0; c < model_cycles.size(); ++c) {
      if (model_cycles[c]->boards.empty()) continue;
      int detected = 0, found = 0, frames = 0;
      for (size_t u : users) {
        const HealthBoard* b = boards[u][c];
        if (b == nullptr) continue;
        const int seen = b->frames_found + b->frames_partial;
        detected += seen > 0 ? 1 : 0;
        found += seen;
        frames += b->frames;
      }
      counts.cycle_ids.push_back(model_cycles[c]->cycle_id);
      counts.detected.push_back(detected);
      counts.frames_found.push_back(found);
      counts.frames.push_back(frames);
    }
    out.push_back(std::move(counts));
  }
  return out;
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
    std::vector<const HealthCycle*> model_cycles;
    std::vector<int64_t> ids;
    std::vector<std::vector<const HealthResult*>> results(car.sensors.size());
    for (const HealthCycle& c : cycles) {
      if (c.car_model != car.id) continue;
      model_cycles.push_back(&c);
      ids.push_back(c.cycle_id);
      for (auto& r : results) r.push_back(nullptr);
      for (const HealthResult& r : c.results) {
        const SensorModel* m = car.FindSensor(r.sensor);
        if (m != nullptr) results[static_cast<size_t>(m - car.sensors.data())].back() = &r;
      }
    }
    if (ids.empty()) continue;
    for (size_t s = 0; s < car.sensors.size(); ++s) {
      health.trends.push_back(SensorTrendOf(car, car.sensors[s], results[s], ids, options));
    }
    const BoardTable boards = BoardsByTarget(car, model_cycles);
    for (TargetAlarm& a : CarAlarms(car, boards, ids, options))
      health.alarms.push_back(std::move(a));
    for (TargetCounts& c : CarCounts(car, boards, model_cycles)) {
      health.counts.push_back(std::move(c));
    }
  }
  return health;
}

}  // namespace linecal

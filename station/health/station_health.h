#pragma once
// Station health (docs/console.md, "Trends and station health"): each sensor's results across
// the last cars of one car model as control charts, and the moved-target alarm.
//
// Series: per car model and sensor, the deviation of the mounting from nominal (yaw, pitch,
// roll in degrees, x, y, z in metres) and the residual RMS (the sensor's unit), one point per
// cycle in which the sensor was solved.
//
// Charts (EWMA, Roberts 1959): z_i = λ x_i + (1 − λ) z_{i−1} from the baseline's mean, with
// limits mean ± L σ sqrt(λ / (2 − λ) (1 − (1 − λ)^{2i})); mean and σ from the baseline, the
// series' points before its last `recent_cars`.
//
// Alarm: a moved board or stand changes what every sensor that uses it measures, while the
// cars' own mounting errors are independent from sensor to sensor. Measured on simulated cycles
// (docs/console.md): a board turned 0.3° about its centre moves the mountings found by less
// than 0.01° (the solvers spread it over all boards) but raises the residual of its sensors by
// up to 1.2 σ of the car-to-car spread. So per target, over the sensors of the car model that
// use it (at least `min_sensors`), the residuals are standardised by their baselines and summed
// (divided by the square root of their number: unit variance on a still station); an EWMA of
// that sum over the recent cars above `alarm_sigmas` of its own σ is the alarm. One-sided: a
// moved target can only make the fit worse. Targets used by the same sensors share the
// statistic and alarm together (the alarm names them all).
//
// Pure functions, no I/O; cost O(cycles × sensors × targets of a sensor).

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "station/model/car_model.h"

namespace linecal {

// The series of a sensor: six deviation axes and the residual.
inline constexpr int kHealthSeries = 7;
// "yaw_deg", "pitch_deg", "roll_deg", "x_m", "y_m", "z_m", "residual_rms".
const char* HealthSeriesName(int series);
inline constexpr int kResidualSeries = 6;

// One sensor's result in one cycle; only solved results (a mounting was found) are passed.
struct HealthResult {
  std::string sensor;
  // yaw, pitch, roll deviation (deg), x, y, z deviation (m), residual RMS (the sensor's unit).
  std::array<double, kHealthSeries> values{};
};

struct HealthCycle {
  int64_t cycle_id = 0;
  int64_t started_ns = 0;
  std::string car_model;
  std::vector<HealthResult> results;
};

struct StationHealthOptions {
  // EWMA weight: 0.2 weighs the last ~10 cars, the horizon in which a move must show
  // (20 cars, issue 23) with a well-known ARL table (Lucas and Saccucci 1990).
  double lambda = 0.2;
  // Chart limits in σ of the EWMA: the usual 3.
  double chart_sigmas = 3.0;
  // Alarm limit in σ of the target's EWMA; chosen with tests/station/health (docs/console.md).
  double alarm_sigmas = 3.8;
  // The cars the alarm's EWMA runs over; the points before them are the baseline.
  int recent_cars = 20;
  // Fewest baseline points for a chart or an alarm: fewer give a σ too uncertain to judge by.
  int min_baseline = 10;
  // Sensors of a target that must share the shift ("several sensors"): a rise in one
  // sensor alone cannot be told from that sensor's own trouble.
  int min_sensors = 2;
  // σ below this is taken as this (a series that happens to be constant): 1e-9 of the unit.
  double min_sigma = 1e-9;
  // OK or InvalidArgument naming the field. O(1).
  absl::Status Validate() const;
};

struct HealthSeries {
  std::string name;                // HealthSeriesName
  std::vector<int64_t> cycle_ids;  // oldest first
  std::vector<double> values;
  std::vector<double> ewma;          // from the first point
  double mean = 0, sigma = 0;        // of the baseline; sigma 0 when it is too short
  std::vector<double> lower, upper;  // EWMA limits per point; empty without a baseline
  double tolerance = 0;  // ± the car model's tolerance (deviation axes); 0 for the residual
};

struct SensorTrend {
  std::string car_model;
  std::string sensor;
  std::string kind;  // "camera", "lidar", "radar"
  std::vector<std::string> targets;
  std::vector<HealthSeries> series;  // kHealthSeries, in HealthSeriesName order
};

struct ShiftedSensor {
  std::string sensor;
  double baseline_residual = 0;  // mean of the baseline
  double recent_residual = 0;    // mean since the alarm's first cycle
  double shift_sigmas = 0;       // (recent − baseline) / baseline σ
};

struct TargetAlarm {
  std::string car_model;
  std::vector<std::string> targets;  // used by exactly these sensors (sorted)
  std::vector<ShiftedSensor> sensors;
  // The first cycle of the rise: the start of the recent tail whose standardised residuals
  // sum highest (the change point of a step in the mean); within the last recent_cars.
  int64_t since_cycle = 0;
  int64_t last_cycle = 0;       // the newest cycle judged
  double statistic_sigmas = 0;  // the EWMA in its σ at last_cycle
  double alarm_sigmas = 0;
};

// Per target and cycle: how many of its sensors found a mounting with it (the store keeps
// per-sensor results, not per-board detections).
struct TargetCounts {
  std::string car_model;
  std::string target;
  std::vector<int64_t> cycle_ids;
  std::vector<int> solved;
  int sensors = 0;  // sensors of the car model that use it
};

struct StationHealth {
  std::vector<SensorTrend> trends;
  std::vector<TargetAlarm> alarms;
  std::vector<TargetCounts> counts;
};

// The trends of every sensor of every car model in `cars` seen in `cycles` (oldest first;
// cycles of other car models and results of unknown sensors are skipped), the alarms at the
// newest cycle of each car model, and per-target counts. InvalidArgument for bad options or
// cycles not in increasing id order.
absl::StatusOr<StationHealth> ComputeStationHealth(const std::vector<CarModel>& cars,
                                                   const std::vector<HealthCycle>& cycles,
                                                   const StationHealthOptions& options = {});

}  // namespace linecal

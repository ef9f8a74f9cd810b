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
// than 0.01° (the solvers spread it over all boards) and raises a sensor's residual by at most
// 1.2 σ of the car-to-car spread, but the residual of the turned board itself in each sensor
// that uses it (BoardResidual: its reprojection RMS in a camera, its hole-centre RMS in a
// LiDAR) by several σ. So per target, over the sensors of the car model that use it (at least
// `min_sensors` with a baseline), each sensor's residual of that board is standardised by its
// own baseline (the board-sensor pair's mean and σ) and the cycle's standardised residuals are
// summed (divided by the square root of their number: unit variance on a still station); an
// EWMA of that sum over the recent cars above `alarm_sigmas` of its own σ (the EWMA's and the
// baseline means' error, which all recent cars share) is the alarm, which names the target.
// One-sided: a moved target can only make the fit worse. Of targets whose alarms share a
// sensor only the strongest is kept: a moved board also shifts, a little, the fits of the
// boards its sensors see with it.
//
// Pure functions, no I/O; cost O(cycles × sensors × targets of a sensor).

#include <array>
#include <cstdint>
#include <optional>
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

// One target board as one sensor saw it in one cycle, solved or not.
struct HealthBoard {
  std::string sensor;
  std::string board;
  int frames = 0;          // frames (LiDARs: accumulated scans) it was looked for in
  int frames_found = 0;    // frames with the whole board
  int frames_partial = 0;  // frames with certain features of a partly seen board
  // The board's own residual RMS when the sensor was solved with it (the sensor's unit).
  std::optional<double> residual;
};

struct HealthCycle {
  int64_t cycle_id = 0;
  int64_t started_ns = 0;
  std::string car_model;
  std::vector<HealthResult> results;
  std::vector<HealthBoard> boards;  // empty for a cycle stored without them
};

struct StationHealthOptions {
  // EWMA weight: 0.2 weighs the last ~10 cars, the horizon in which a move must show
  // (20 cars, issue 23) with a well-known ARL table (Lucas and Saccucci 1990).
  double lambda = 0.2;
  // Chart limits in σ of the EWMA: the usual 3.
  double chart_sigmas = 3.0;
  // Alarm limit in σ of the target's EWMA: the highest of 30 simulated still lines of 1,000
  // cars reached 4.6, a board turned 0.3° passes 5.5 within 3-6 cars (tests/station/health,
  // docs/console.md "Moved-target alarm: measured").
  double alarm_sigmas = 5.5;
  // The cars the alarm's EWMA runs over; the points before them are the baseline.
  int recent_cars = 20;
  // Fewest baseline points for a chart or an alarm: fewer give a σ too uncertain to judge by.
  int min_baseline = 10;
  // Sensors with a residual (and a baseline) of a target for it to be judged: one sensor's
  // residual alone cannot tell a moved board from that sensor's own trouble. The sum does not
  // need each of them to rise: a large rise in one can raise the alarm, whose shifts show it.
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

// A sensor's residual of the alarm's target board (HealthBoard::residual).
struct ShiftedSensor {
  std::string sensor;
  double baseline_residual = 0;  // mean of the baseline
  double recent_residual = 0;    // mean since the alarm's first cycle
  double shift_sigmas = 0;       // (recent − baseline) / baseline σ
};

struct TargetAlarm {
  std::string car_model;
  std::vector<std::string> targets;    // the target board that moved (one)
  std::vector<ShiftedSensor> sensors;  // in the car model's order
  // The first cycle of the rise: the start of the recent tail whose standardised residuals
  // sum over the square root of its length is highest (the change point of a step in the
  // mean); within the last recent_cars.
  int64_t since_cycle = 0;
  int64_t last_cycle = 0;       // the newest cycle judged
  double statistic_sigmas = 0;  // the EWMA in its σ at last_cycle
  double alarm_sigmas = 0;
};

// Per target, its detections in each cycle of the car model that has board records
// (HealthCycle::boards): how many of its sensors found it in at least one frame (whole or
// partly), and over those sensors the frames with it (whole or partly) and the frames looked
// in.
struct TargetCounts {
  std::string car_model;
  std::string target;
  std::vector<int64_t> cycle_ids;
  std::vector<int> detected;
  std::vector<int> frames_found;
  std::vector<int> frames;
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

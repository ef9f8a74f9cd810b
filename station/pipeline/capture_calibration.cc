#include "station/pipeline/capture_calibration.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <numbers>
#include <thread>

#include "absl/strings/str_cat.h"
#include "detectors/detect.h"
#include "detectors/round_hole/round_hole_cloud.h"
#include "station/camera/board_view.h"
#include "station/io/candump.h"
#include "station/io/image_io.h"
#include "station/sensors/lidar/pcd.h"
#include "station/sensors/radar/radar_decoder.h"
#include "station/solvers/lidar_calibration.h"
#include "station/solvers/radar_calibration.h"

namespace linecal {
namespace {

constexpr double kDegPerRad = 180.0 / std::numbers::pi;

std::int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// A sensor whose work was stopped (CaptureCalibrationOptions::stop); CalibrateCapture
// returns Cancelled instead of any such result.
SensorCalibration Stopped() {
  SensorCalibration out;
  out.reason = "stopped";
  return out;
}

// The fields the camera and LiDAR solvers' results share. False, with the sensor in error,
// when the solver refused its input.
template <typename Result>
bool TakeResult(const absl::StatusOr<Result>& r, SensorCalibration* out) {
  if (!r.ok()) {
    out->reason = "invalid_input";
    out->message = std::string(r.status().message());
    return false;
  }
  out->verdict = r->verdict;
  out->reason = r->reason;
  out->message = r->message;
  out->solved = r->solved;
  out->mounting = r->mounting;
  out->features_used = r->features_used;
  if (r->solved) {
    for (const BoardResidual& b : r->board_residuals) {
      for (BoardDetectionSummary& summary : out->boards) {
        if (summary.board_id == b.board_id) summary.residual_rms = b.rms;
      }
    }
  }
  return true;
}

SensorCalibration CalibrateCameraSensor(const Capture& capture, const SensorModel& sensor,
                                        const CaptureSensor& recorded,
                                        const CaptureCalibrationOptions& capture_options) {
  const CameraCalibrationOptions& options = capture_options.camera;
  SensorCalibration out;
  for (const std::string& id : sensor.targets) out.boards.emplace_back().board_id = id;
  std::vector<BoardObservation> observations;
  for (size_t frame_index = 0; frame_index < recorded.frames.size(); ++frame_index) {
    if (capture_options.stop.stop_requested()) return Stopped();
    const CaptureFile& frame = recorded.frames[frame_index];
    const absl::StatusOr<Image8> image = ReadCaptureImage(capture, frame);
    if (!image.ok()) {
      out.reason = "data_unreadable";
      out.message = std::string(image.status().message());
      return out;
    }
    std::vector<BoardObservation> found =
        DetectCameraFrame(capture, sensor, image->view(), &out.boards, capture_options.stop);
    if (capture_options.stop.stop_requested()) return Stopped();
    if (frame_index == 0 && capture_options.keep_first_frame_features) {
      out.first_frame_observations = found;
    }
    for (BoardObservation& o : found) observations.push_back(std::move(o));
  }
  if (capture_options.stop.stop_requested()) return Stopped();
  absl::StatusOr<CameraCalibrationResult> r = CalibrateCamera(
      sensor, capture.station, capture.manifest.aligner.T_station_car(), observations, options);
  if (!TakeResult(r, &out)) return out;
  out.residual_rms = r->residual_rms_px;
  if (r->solved) {
    if (r->vanishing_point_valid) out.vanishing_point_px = r->vanishing_point_px;
    out.ground_homography = r->ground_homography;
    out.ranging = r->ranging;
    out.board_method = r->board_method;
    out.vanishing_point_disagreement_px = r->vanishing_point_disagreement_px;
    out.ground_disagreement = r->ground_disagreement;
    out.toolbox_ground_disagreement = r->toolbox_ground_disagreement;
    out.vertical_roll = r->vertical_roll;
  }
  return out;
}

SensorCalibration CalibrateLidarSensor(const Capture& capture, const SensorModel& sensor,
                                       const CaptureSensor& recorded, std::stop_token stop) {
  SensorCalibration out;
  // Every recorded rotation, accumulated: the boards stand still during a cycle.
  std::vector<std::vector<RoundHoleCloudPoint>> frames;
  for (const CaptureFile& f : recorded.frames) {
    if (stop.stop_requested()) return Stopped();
    absl::StatusOr<PcdCloud> cloud = ReadCaptureScan(capture, f);
    if (!cloud.ok()) {
      out.reason = "data_unreadable";
      out.message = std::string(cloud.status().message());
      return out;
    }
    std::vector<RoundHoleCloudPoint>& points = frames.emplace_back();
    points.reserve(cloud->points.size());
    for (const LidarPoint& p : cloud->points) points.push_back({p.x, p.y, p.z, p.ring});
  }
  if (frames.empty()) {
    out.reason = "data_unreadable";
    out.message = absl::StrCat(sensor.name, ": the capture has no PCD scans of this LiDAR");
    return out;
  }
  if (stop.stop_requested()) return Stopped();
  const std::vector<std::span<const RoundHoleCloudPoint>> views(frames.begin(), frames.end());
  return CalibrateLidarFrames(capture.station, capture.manifest.aligner.T_station_car(), sensor,
                              views);
}

SensorCalibration CalibrateRadarSensor(const Capture& capture, const SensorModel& sensor,
                                       const CaptureSensor& recorded, std::stop_token stop) {
  SensorCalibration out;
  const std::optional<RadarModel> model = ParseRadarModel(sensor.model);
  if (!model || !recorded.can_log) {
    out.reason = "data_unreadable";
    out.message =
        absl::StrCat(sensor.name, ": no CAN log or unknown radar model '", sensor.model, "'");
    return out;
  }
  const absl::StatusOr<std::vector<CanFrame>> frames =
      ReadCaptureCanLog(capture, *recorded.can_log);
  if (!frames.ok()) {
    out.reason = "data_unreadable";
    out.message = std::string(frames.status().message());
    return out;
  }
  if (stop.stop_requested()) return Stopped();
  const RadarDecodeResult decoded = DecodeRadarFrames(*frames, *model, RadarConventions{});
  const absl::StatusOr<RadarCalibrationRun> run =
      CalibrateRadar(sensor, capture.station, capture.manifest.aligner.T_station_car(),
                     decoded.cycles, RadarCalibrationOptions{});
  if (!run.ok()) {
    out.reason = "invalid_input";
    out.message = std::string(run.status().message());
    return out;
  }
  const RadarCalibrationResult& r = run->result;
  out.verdict = r.verdict;
  out.reason = r.reason;
  out.features_used = r.reflectors_used;
  out.solved = r.reflectors_used > 0;
  if (out.solved) {
    // Yaw measured; pitch, roll and position reported nominal (docs/interfaces.md), so their
    // deviations are 0 with no uncertainty to report beyond the yaw's. The solver's horizontal
    // offset, estimated where the reflectors tell it (radar_calibration.h), serves the yaw
    // alone: the car model judges a radar by its yaw.
    out.mounting.angles = {r.yaw_rad, r.pitch_rad, r.roll_rad};
    out.mounting.position_m = sensor.T_car_sensor_nominal.translation();
    out.mounting.T_car_sensor = Rigid3d(r.T_car_radar.RotationMatrix(), out.mounting.position_m);
    out.mounting.angles_deviation = {r.yaw_deviation_rad, 0, 0};
    out.mounting.sigma[0] = r.yaw_sigma_rad;
    out.mounting.observed = {true, false, false, false, false, false};
    double sum_sq = 0;
    for (const RadarReflectorResidual& res : r.residuals)
      sum_sq += res.residual_rad * res.residual_rad;
    out.residual_rms =
        r.residuals.empty() ? 0 : std::sqrt(sum_sq / r.residuals.size()) * kDegPerRad;
  }
  out.message = out.verdict == Verdict::kPass
                    ? ""
                    : absl::StrCat(sensor.name, ": ", r.reason, " (yaw deviation ",
                                   r.yaw_deviation_rad * kDegPerRad, " deg, tolerance ",
                                   r.yaw_tolerance_rad * kDegPerRad, " deg)");
  return out;
}

// `station_board` detected in `image`. A camera's boards are looked for first in a perspective
// view of where they are expected (station/camera/board_view.h): in the raw image the lens
// bends the board's lines and shifts the features. Through the fisheye, marker corners
// (docs/solvers.md, "The rear ArUco board through the fisheye") and checker corners alike sat
// 0.027-0.029 px towards the image centre on every capture ("Camera sigma on the full-physics
// evaluation"), which moved the surround cameras' positions by 3 sigma; through the front
// camera's pinhole lens the vertical board's L-corners sat 0.006-0.008 px left of the truth,
// which moved x by half its sigma on every car ("The front camera's vertical board in its
// view"). The raw image serves where the view does not show the whole board, and without a
// camera model. nullopt: the board has no image detector.
std::optional<Detection> DetectInExpectedView(const ImageView8& image,
                                              const std::optional<CameraModel>& camera,
                                              const Rigid3d& T_camera_station,
                                              const StationBoard& station_board) {
  const Board& board = station_board.board;
  if (camera) {
    std::optional<Detection> v =
        DetectInBoardView(*camera, image, T_camera_station * station_board.T_station_board, board);
    if (v && v->found) return v;
  }
  return DetectBoard(image, board);
}

}  // namespace

absl::StatusOr<CycleCalibration> CalibrateCapture(const Capture& capture,
                                                  const CaptureCalibrationOptions& options) {
  if (options.threads < 1 || options.threads > 64) {
    return absl::InvalidArgumentError(
        absl::StrCat("threads = ", options.threads, ": must be in [1, 64]"));
  }
  if (absl::Status s = options.camera.Validate(); !s.ok()) return s;
  const std::int64_t start = NowNs();
  CycleCalibration cycle;
  std::vector<const SensorModel*> sensors;
  for (const SensorModel& s : capture.car.sensors) {
    if (capture.manifest.FindSensor(s.name) != nullptr) sensors.push_back(&s);
  }
  cycle.sensors.resize(sensors.size());
  // Each worker takes the next sensor; every result goes to its own slot.
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t i = next++; i < sensors.size() && !options.stop.stop_requested(); i = next++) {
      const SensorModel& s = *sensors[i];
      const CaptureSensor& recorded = *capture.manifest.FindSensor(s.name);
      const std::int64_t t0 = NowNs();
      SensorCalibration r;
      switch (s.kind) {
        case SensorKind::kCamera:
          r = CalibrateCameraSensor(capture, s, recorded, options);
          break;
        case SensorKind::kRadar:
          r = CalibrateRadarSensor(capture, s, recorded, options.stop);
          break;
        case SensorKind::kLidar:
          r = CalibrateLidarSensor(capture, s, recorded, options.stop);
          break;
      }
      r.name = s.name;
      r.kind = s.kind;
      r.elapsed_ns = NowNs() - t0;
      cycle.sensors[i] = std::move(r);
    }
  };
  const int threads = std::min<int>(options.threads, static_cast<int>(sensors.size()));
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  if (options.stop.stop_requested()) return absl::CancelledError("calibration stopped");

  bool any_error = cycle.sensors.empty(), all_pass = !cycle.sensors.empty();
  for (const SensorCalibration& s : cycle.sensors) {
    any_error |= s.verdict == Verdict::kError;
    all_pass &= s.verdict == Verdict::kPass;
  }
  cycle.verdict = all_pass ? Verdict::kPass : any_error ? Verdict::kError : Verdict::kFail;
  cycle.elapsed_ns = NowNs() - start;
  return cycle;
}

SensorCalibration CalibrateLidarFrames(const StationLayout& station, const Rigid3d& T_station_car,
                                       const SensorModel& sensor,
                                       std::span<const std::span<const RoundHoleCloudPoint>> frames,
                                       std::vector<RoundHoleCloudDetection>* detections) {
  SensorCalibration out;
  if (detections != nullptr) detections->clear();
  // Where the boards should be if the LiDAR sits at its nominal mounting.
  const Rigid3d T_lidar_station = (T_station_car * sensor.T_car_sensor_nominal).Inverse();
  std::vector<LidarBoardObservation> observations;
  for (const std::string& id : sensor.targets) {
    BoardDetectionSummary& summary = out.boards.emplace_back();
    summary.board_id = id;
    summary.frames = static_cast<int>(frames.size());
    const StationBoard* board = station.FindBoard(id);
    if (board == nullptr) {  // ReadCapture checked the targets; kept for safety of the data
      if (detections != nullptr) detections->emplace_back();
      continue;
    }
    const RoundHoleCloudDetection d =
        DetectRoundHoleBoardInCloud(board->board, frames, T_lidar_station * board->T_station_board);
    if (detections != nullptr) detections->push_back(d);
    if (!d.found) {
      summary.last_reason = RoundHoleCloudReasonName(d.reason);
      continue;
    }
    summary.frames_found = static_cast<int>(frames.size());
    observations.push_back(LidarObservationFromDetection(id, d));
  }
  absl::StatusOr<LidarCalibrationResult> r =
      CalibrateLidar(sensor, station, T_station_car, observations);
  if (TakeResult(r, &out)) out.residual_rms = r->residual_rms_m;
  return out;
}

std::vector<BoardObservation> DetectCameraFrame(const Capture& capture, const SensorModel& sensor,
                                                const ImageView8& image,
                                                std::vector<BoardDetectionSummary>* summaries,
                                                std::stop_token stop) {
  // The camera model and the nominal pose of the station in the camera frame, for the board
  // views; without intrinsics CalibrateCamera reports the sensor's error.
  std::optional<CameraModel> camera;
  if (sensor.intrinsics) {
    absl::StatusOr<CameraModel> m = CameraModel::Create(*sensor.intrinsics);
    if (m.ok()) camera = *std::move(m);
  }
  const Rigid3d T_camera_station =
      sensor.T_car_sensor_nominal.Inverse() * capture.manifest.aligner.T_station_car().Inverse();
  std::vector<BoardObservation> observations;
  for (size_t i = 0; i < sensor.targets.size(); ++i) {
    if (stop.stop_requested()) break;
    const StationBoard* board = capture.station.FindBoard(sensor.targets[i]);
    if (board == nullptr) continue;
    BoardDetectionSummary& summary = (*summaries)[i];
    ++summary.frames;
    std::optional<Detection> d = DetectInExpectedView(image, camera, T_camera_station, *board);
    if (!d) {
      summary.last_reason = "no_detector";
      continue;
    }
    // Whole boards, and partial views whose reported features the detector is certain of
    // where the station file allows them for this board.
    summary.partial_allowed = board->allow_partial;
    if (d->found) {
      ++summary.frames_found;
    } else if (d->reason == DetectReason::kPartial && !d->features.empty()) {
      ++summary.frames_partial;
      if (!board->allow_partial) {
        summary.last_reason = DetectReasonName(d->reason);
        continue;
      }
    } else {
      summary.last_reason = DetectReasonName(d->reason);
      continue;
    }
    observations.push_back({board->id, d->features});
  }
  return observations;
}

}  // namespace linecal

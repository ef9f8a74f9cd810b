#pragma once
// One calibration cycle computed from a capture: what `linecal calibrate --capture DIR` prints
// and what the daemon stores for a cycle replayed from, or recorded into, that capture. One
// function for both, so that they give identical results (docs/interfaces.md, "Captures").
//
// Per sensor of the capture (in parallel, one thread per sensor; results do not depend on
// the scheduling):
//   camera  every frame's PNG -> DetectBoard for each of the sensor's target boards (whole
//           boards, and the certain features of partial views) -> CalibrateCamera
//   radar   the CAN log -> DecodeRadarFrames -> CalibrateRadar (yaw only; pitch, roll and
//           position nominal, docs/lidar-radar.md)
//   LiDAR   every PCD scan accumulated -> DetectRoundHoleBoardInCloud for each target board
//           (expected where the nominal mounting puts it) -> CalibrateLidar
// The overall verdict is pass when every sensor passes, else fail when none is in error,
// else error.

#include <cstdint>
#include <optional>
#include <span>
#include <stop_token>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "detectors/round_hole/round_hole_cloud.h"
#include "station/capture/capture.h"
#include "station/solvers/camera_calibration.h"

namespace linecal {

struct BoardDetectionSummary {
  std::string board_id;
  int frames_found = 0;    // frames in which the whole board was identified
  int frames_partial = 0;  // frames with certain features of a partly seen board
  // Whether those partial views were used: the station file's `allow_partial` of the board
  // (StationBoard). When not, a partial frame counts here but its reason stays "partial".
  bool partial_allowed = false;
  std::string last_reason;  // the detector's reason in the last frame without the board
  int frames = 0;           // frames (LiDARs: accumulated scans) the board was looked for in
  // When the sensor was solved with this board: its own residual RMS at the solved mounting
  // (BoardResidual; pixels for cameras, metres for LiDARs).
  std::optional<double> residual_rms;
};

struct SensorCalibration {
  std::string name;
  SensorKind kind = SensorKind::kCamera;
  Verdict verdict = Verdict::kError;
  std::string reason;
  std::string message;
  bool solved = false;
  MountingEstimate mounting;  // when solved
  double residual_rms = 0;    // pixels (cameras), metres (LiDARs), degrees (radars)
  int features_used = 0;  // board features (cameras), hole centres (LiDARs), reflectors (radars)
  std::vector<BoardDetectionSummary> boards;  // cameras and LiDARs, in the targets' order
  // Cameras, when solved: see CameraCalibrationResult.
  std::optional<Eigen::Vector2d> vanishing_point_px;
  std::optional<Eigen::Matrix3d> ground_homography;
  std::vector<RangingCheck> ranging;
  // Cameras, when solved: the seed formulas (CameraCalibrationResult): method (b) with its
  // disagreement from the extrinsic's, and the roll from the vertical board.
  BoardMethodResult board_method;
  double vanishing_point_disagreement_px = 0;
  std::vector<double> ground_disagreement;          // per ranging[i].true_distance_m
  std::vector<double> toolbox_ground_disagreement;  // the same for the toolbox's formula
  VerticalBoardRoll vertical_roll;
  // Cameras, with CaptureCalibrationOptions::keep_first_frame_features: the boards found in
  // the sensor's first frame, for drawing reports.
  std::vector<BoardObservation> first_frame_observations;
  std::int64_t elapsed_ns = 0;  // wall time of this sensor's detection and solve
};

struct CycleCalibration {
  Verdict verdict = Verdict::kError;
  std::vector<SensorCalibration> sensors;  // in the car model's order
  std::int64_t elapsed_ns = 0;
};

struct CaptureCalibrationOptions {
  CameraCalibrationOptions camera;
  // Sensors computed at once (threads); 1 computes them one after the other. [1, 64].
  int threads = 8;
  // Keep each camera's first-frame detections in SensorCalibration (for `calibrate --report`).
  bool keep_first_frame_features = false;
  // Once a stop is requested (a deadline passed, the cycle was cancelled, the daemon stops),
  // every sensor's work ends at its next frame, scan or board and CalibrateCapture returns
  // Cancelled: the work frees its threads instead of running on unseen. A default token
  // never stops.
  std::stop_token stop;
};

// Computes the cycle of `capture` (already read and validated by ReadCapture). Errors:
// InvalidArgument for invalid options; Cancelled once options.stop was requested (checked
// before every frame, scan, board and solve: the call returns within one of those). A sensor
// whose data cannot be read or decoded gets verdict error with reason "data_unreadable" and
// the file in the message; it never stops the other sensors. Cost: the detectors' and
// solvers' (about 0.1-1 s for the reference car).
absl::StatusOr<CycleCalibration> CalibrateCapture(const Capture& capture,
                                                  const CaptureCalibrationOptions& options = {});

// The LiDAR path of a cycle on rotations already in memory (CalibrateCapture reads them from
// the capture's PCD files): each of `sensor`'s target boards detected where the nominal
// mounting and `T_station_car` put it, every board found entering CalibrateLidar as its pose
// with the detector's covariance. `detections`, when given, receives the detection of each
// target in sensor.targets order (for evaluations). Never throws; errors are outcomes.
SensorCalibration CalibrateLidarFrames(const StationLayout& station, const Rigid3d& T_station_car,
                                       const SensorModel& sensor,
                                       std::span<const std::span<const RoundHoleCloudPoint>> frames,
                                       std::vector<RoundHoleCloudDetection>* detections = nullptr);

// The target boards of camera `sensor` in one frame, as a cycle detects them (the cycle page
// draws the same): DetectInBoardView where the nominal mounting and the capture's aligner put
// the board, the raw image's DetectBoard where the view does not show the whole board; whole boards
// and the certain features of partial views, in sensor.targets order. `summaries` (one per target,
// same order) count the frames found and keep the last reason. Returns what was found before a stop
// was requested. Cost: the detectors' (tens to hundreds of ms a board on the reference frames).
std::vector<BoardObservation> DetectCameraFrame(const Capture& capture, const SensorModel& sensor,
                                                const ImageView8& image,
                                                std::vector<BoardDetectionSummary>* summaries,
                                                std::stop_token stop = {});

}  // namespace linecal

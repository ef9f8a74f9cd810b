#include "station/pipeline/cycle_views.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <span>

#include "absl/strings/str_cat.h"
#include "station/camera/camera_model.h"
#include "station/pipeline/capture_calibration.h"
#include "station/sensors/radar/radar_decoder.h"
#include "station/solvers/radar_calibration.h"

namespace linecal {
namespace {

// Metres around the boards (and the sensor) that a LiDAR view keeps: a board found a few
// centimetres off and its surroundings stay in the picture.
constexpr double kLidarViewMarginM = 1.0;

nlohmann::json Xy(double x, double y) { return nlohmann::json::array({x, y}); }
nlohmann::json Xyz(const Eigen::Vector3d& p) {
  return nlohmann::json::array({p.x(), p.y(), p.z()});
}

// The mounting to draw with: the cycle's solved one (16 values, row-major), else the nominal.
Rigid3d MountingOf(const SensorModel& sensor, const std::vector<double>& T_car_sensor) {
  if (T_car_sensor.size() != 16) return sensor.T_car_sensor_nominal;
  Eigen::Matrix4d m;
  for (int i = 0; i < 16; ++i) m(i / 4, i % 4) = T_car_sensor[static_cast<size_t>(i)];
  return Rigid3d::FromMatrix(m);
}

absl::StatusOr<nlohmann::json> CameraView(const Capture& capture, const SensorModel& sensor,
                                          const CaptureSensor& recorded, int frame,
                                          const std::vector<double>& T_car_sensor) {
  if (frame < 0 || static_cast<size_t>(frame) >= recorded.frames.size()) {
    return absl::InvalidArgumentError(absl::StrCat("frame = ", frame, ": ", sensor.name, " has ",
                                                   recorded.frames.size(), " frames"));
  }
  if (!sensor.intrinsics) {
    return absl::FailedPreconditionError(absl::StrCat(sensor.name, ": no intrinsics"));
  }
  absl::StatusOr<CameraModel> camera = CameraModel::Create(*sensor.intrinsics);
  if (!camera.ok()) return camera.status();
  absl::StatusOr<Image8> image =
      ReadCaptureImage(capture, recorded.frames[static_cast<size_t>(frame)]);
  if (!image.ok()) return image.status();
  std::vector<BoardDetectionSummary> summaries;
  for (const std::string& id : sensor.targets) summaries.push_back({id, 0, 0, "", 0, {}});
  const std::vector<BoardObservation> found =
      DetectCameraFrame(capture, sensor, image->view(), &summaries);

  const Rigid3d T_camera_station =
      (capture.manifest.aligner.T_station_car() * MountingOf(sensor, T_car_sensor)).Inverse();
  nlohmann::json boards = nlohmann::json::array();
  int detected_total = 0, reprojected_total = 0;
  for (size_t i = 0; i < sensor.targets.size(); ++i) {
    nlohmann::json detected = nlohmann::json::array(), reprojected = nlohmann::json::array();
    for (const BoardObservation& o : found) {
      if (o.board_id != sensor.targets[i]) continue;
      for (const DetectedFeature& f : o.features)
        detected.push_back({f.id, f.uv_px.x(), f.uv_px.y()});
    }
    if (const StationBoard* board = capture.station.FindBoard(sensor.targets[i])) {
      const Rigid3d T_camera_board = T_camera_station * board->T_station_board;
      for (const BoardFeature& f : board->board.features()) {
        const Eigen::Vector3d p = T_camera_board * Eigen::Vector3d(f.p_board.x(), f.p_board.y(), 0);
        Eigen::Vector2d uv;
        // In front of the lens and on the image: a fisheye projects points behind it too.
        if (p.z() <= 0 || !camera->Project(p, &uv) || !camera->IsInImage(uv)) continue;
        reprojected.push_back({f.id, uv.x(), uv.y()});
      }
    }
    detected_total += static_cast<int>(detected.size());
    reprojected_total += static_cast<int>(reprojected.size());
    boards.push_back({{"id", sensor.targets[i]},
                      {"found", summaries[i].frames_found > 0},
                      {"partial", summaries[i].frames_partial > 0},
                      {"reason", summaries[i].last_reason},
                      {"detected", std::move(detected)},
                      {"reprojected", std::move(reprojected)}});
  }
  return nlohmann::json{{"sensor", sensor.name},
                        {"kind", "camera"},
                        {"frame", frame},
                        {"frames", recorded.frames.size()},
                        {"file", recorded.frames[static_cast<size_t>(frame)].path},
                        {"width", image->width},
                        {"height", image->height},
                        {"mounting", T_car_sensor.size() == 16 ? "solved" : "nominal"},
                        {"detected_features", detected_total},
                        {"reprojected_features", reprojected_total},
                        {"boards", std::move(boards)}};
}

// The page's outline of `board` (its four corners) in the frame that T_frame_board maps to.
nlohmann::json Outline(const Board& board, const Rigid3d& T_frame_board) {
  const Eigen::Vector2d h = 0.5 * board.page_size_m();
  nlohmann::json corners = nlohmann::json::array();
  for (const auto& [sx, sy] :
       std::array<std::pair<double, double>, 4>{{{-1, -1}, {1, -1}, {1, 1}, {-1, 1}}}) {
    corners.push_back(Xyz(T_frame_board * Eigen::Vector3d(sx * h.x(), sy * h.y(), 0)));
  }
  return corners;
}

absl::StatusOr<nlohmann::json> LidarView(const Capture& capture, const SensorModel& sensor,
                                         const CaptureSensor& recorded) {
  std::vector<std::vector<RoundHoleCloudPoint>> frames;
  for (const CaptureFile& f : recorded.frames) {
    absl::StatusOr<PcdCloud> cloud = ReadCaptureScan(capture, f);
    if (!cloud.ok()) return cloud.status();
    std::vector<RoundHoleCloudPoint>& points = frames.emplace_back();
    points.reserve(cloud->points.size());
    for (const LidarPoint& p : cloud->points) points.push_back({p.x, p.y, p.z, p.ring});
  }
  const std::vector<std::span<const RoundHoleCloudPoint>> spans(frames.begin(), frames.end());
  const Rigid3d T_station_car = capture.manifest.aligner.T_station_car();
  std::vector<RoundHoleCloudDetection> detections;
  CalibrateLidarFrames(capture.station, T_station_car, sensor, spans, &detections);

  const Rigid3d T_lidar_station = (T_station_car * sensor.T_car_sensor_nominal).Inverse();
  // The area shown: the sensor and every board, expected or fitted, with a margin.
  double x0 = 0, x1 = 0, y0 = 0, y1 = 0;
  auto extend = [&](const nlohmann::json& corners) {
    for (const nlohmann::json& c : corners) {
      x0 = std::min(x0, c[0].get<double>());
      x1 = std::max(x1, c[0].get<double>());
      y0 = std::min(y0, c[1].get<double>());
      y1 = std::max(y1, c[1].get<double>());
    }
  };
  nlohmann::json boards = nlohmann::json::array();
  for (size_t i = 0; i < sensor.targets.size() && i < detections.size(); ++i) {
    const StationBoard* board = capture.station.FindBoard(sensor.targets[i]);
    if (board == nullptr) continue;
    const RoundHoleCloudDetection& d = detections[i];
    const Rigid3d T_expected = T_lidar_station * board->T_station_board;
    nlohmann::json view{{"id", board->id},
                        {"found", d.found},
                        {"reason", d.found ? "" : RoundHoleCloudReasonName(d.reason)},
                        {"expected_outline", Outline(board->board, T_expected)}};
    extend(view["expected_outline"]);
    nlohmann::json expected_holes = nlohmann::json::array();
    for (const BoardFeature& f : board->board.features()) {
      if (f.kind != FeatureKind::kHoleCentre) continue;
      expected_holes.push_back(Xyz(T_expected * Eigen::Vector3d(f.p_board.x(), f.p_board.y(), 0)));
    }
    view["expected_holes"] = std::move(expected_holes);
    if (d.found) {
      view["outline"] = Outline(board->board, d.T_lidar_board);
      extend(view["outline"]);
      nlohmann::json holes = nlohmann::json::array();
      for (const RoundHoleHole& h : d.holes)
        holes.push_back({{"id", h.id}, {"p", Xyz(h.p_lidar)}, {"rings", h.rings}});
      view["holes"] = std::move(holes);
      view["plane_inliers"] = d.plane_inliers;
      view["plane_rms_m"] = d.plane_rms_m;
    }
    boards.push_back(std::move(view));
  }
  x0 -= kLidarViewMarginM;
  x1 += kLidarViewMarginM;
  y0 -= kLidarViewMarginM;
  y1 += kLidarViewMarginM;
  auto inside = [&](const RoundHoleCloudPoint& p) {
    return p.x >= x0 && p.x <= x1 && p.y >= y0 && p.y <= y1;
  };
  size_t in_area = 0, total = 0;
  for (const auto& f : frames) {
    total += f.size();
    in_area += static_cast<size_t>(std::count_if(f.begin(), f.end(), inside));
  }
  // Every stride-th point of the area, so that the view holds at most kMaxViewPoints.
  const size_t stride = std::max<size_t>(1, (in_area + kMaxViewPoints - 1) / kMaxViewPoints);
  nlohmann::json points = nlohmann::json::array();
  size_t seen = 0;
  for (const auto& f : frames) {
    for (const RoundHoleCloudPoint& p : f) {
      if (inside(p) && seen++ % stride == 0) points.push_back(Xy(p.x, p.y));
    }
  }
  return nlohmann::json{{"sensor", sensor.name},
                        {"kind", "lidar"},
                        {"frames", recorded.frames.size()},
                        {"points_total", total},
                        {"points_in_area", in_area},
                        {"area", {x0, x1, y0, y1}},
                        {"points", std::move(points)},
                        {"boards", std::move(boards)}};
}

absl::StatusOr<nlohmann::json> RadarView(const Capture& capture, const SensorModel& sensor,
                                         const CaptureSensor& recorded) {
  const std::optional<RadarModel> model = ParseRadarModel(sensor.model);
  if (!model || !recorded.can_log) {
    return absl::FailedPreconditionError(
        absl::StrCat(sensor.name, ": no CAN log or unknown radar model '", sensor.model, "'"));
  }
  absl::StatusOr<std::vector<CanFrame>> frames = ReadCaptureCanLog(capture, *recorded.can_log);
  if (!frames.ok()) return frames.status();
  const RadarDecodeResult decoded = DecodeRadarFrames(*frames, *model, RadarConventions{});
  absl::StatusOr<RadarCalibrationRun> run =
      CalibrateRadar(sensor, capture.station, capture.manifest.aligner.T_station_car(),
                     decoded.cycles, RadarCalibrationOptions{});
  if (!run.ok()) return run.status();
  const std::vector<RadarCycle> used = CalibrationCycles(decoded.cycles, sensor);
  size_t total = 0;
  for (const RadarCycle& c : used) total += c.detections.size();
  const size_t stride = std::max<size_t>(1, (total + kMaxViewPoints - 1) / kMaxViewPoints);
  nlohmann::json detections = nlohmann::json::array();
  size_t seen = 0;
  for (const RadarCycle& c : used) {
    for (const RadarDetection& d : c.detections) {
      if (seen++ % stride == 0) detections.push_back(Xy(d.x_m(), d.y_m()));
    }
  }
  nlohmann::json reflectors = nlohmann::json::array();
  for (size_t i = 0; i < run->expected.size() && i < run->association.reflectors.size(); ++i) {
    const ExpectedReflector& e = run->expected[i];
    const ReflectorObservation& o = run->association.reflectors[i];
    nlohmann::json r{
        {"id", e.reflector_id},
        {"in_view", e.in_view},
        {"status", ReflectorStatusName(o.status)},
        {"expected", Xy(e.range_m * std::cos(e.azimuth_rad), e.range_m * std::sin(e.azimuth_rad))},
        {"n_used", o.n_used}};
    if (o.status == ReflectorStatus::kFound) {
      r["found"] = Xy(o.range_m * std::cos(o.azimuth_rad), o.range_m * std::sin(o.azimuth_rad));
    }
    for (const RadarReflectorResidual& res : run->result.residuals) {
      if (res.reflector_id != e.reflector_id) continue;
      r["solved"] = Xy(e.range_m * std::cos(res.azimuth_predicted_rad),
                       e.range_m * std::sin(res.azimuth_predicted_rad));
    }
    reflectors.push_back(std::move(r));
  }
  return nlohmann::json{{"sensor", sensor.name},
                        {"kind", "radar"},
                        {"cycles", used.size()},
                        {"detections_total", total},
                        {"detections", std::move(detections)},
                        {"reflectors", std::move(reflectors)}};
}

}  // namespace

std::vector<CaptureFileEntry> CaptureFileList(const Capture& capture) {
  std::vector<CaptureFileEntry> files = {
      {"manifest.json", "", "manifest"}, {"station.json", "", "station"}, {"car.json", "", "car"}};
  for (const CaptureSensor& s : capture.manifest.sensors) {
    const char* role = s.kind == SensorKind::kCamera ? "frame" : "scan";
    for (const CaptureFile& f : s.frames) files.push_back({f.path, s.name, role});
    if (s.packets) files.push_back({s.packets->path, s.name, "packets"});
    if (s.can_log) files.push_back({s.can_log->path, s.name, "can_log"});
  }
  return files;
}

absl::StatusOr<nlohmann::json> SensorViewJson(const Capture& capture, const std::string& sensor,
                                              int frame, const std::vector<double>& T_car_sensor) {
  const CaptureSensor* recorded = capture.manifest.FindSensor(sensor);
  const SensorModel* model = capture.car.FindSensor(sensor);
  if (recorded == nullptr || model == nullptr) {
    return absl::NotFoundError(
        absl::StrCat("sensor: '", sensor.substr(0, 64), "' is not in the capture"));
  }
  switch (model->kind) {
    case SensorKind::kCamera:
      return CameraView(capture, *model, *recorded, frame, T_car_sensor);
    case SensorKind::kLidar:
      return LidarView(capture, *model, *recorded);
    case SensorKind::kRadar:
      return RadarView(capture, *model, *recorded);
  }
  return absl::InternalError("unknown sensor kind");
}

}  // namespace linecal

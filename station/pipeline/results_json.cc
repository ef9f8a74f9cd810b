#include "station/pipeline/results_json.h"

#include <cmath>
#include <numbers>

#include "station/model/pose_json.h"

namespace linecal {
namespace {

constexpr double kDegPerRad = 180.0 / std::numbers::pi;

// Measured values, deviations from nominal and 1-sigma; components the sensor cannot
// observe keep their nominal value, and their deviation and sigma are null.
nlohmann::json MountingJson(const MountingEstimate& m) {
  const double values[6] = {m.angles.yaw * kDegPerRad,  m.angles.pitch * kDegPerRad,
                            m.angles.roll * kDegPerRad, m.position_m.x(),
                            m.position_m.y(),           m.position_m.z()};
  const double deviations[6] = {
      m.angles_deviation.yaw * kDegPerRad,  m.angles_deviation.pitch * kDegPerRad,
      m.angles_deviation.roll * kDegPerRad, m.position_deviation_m.x(),
      m.position_deviation_m.y(),           m.position_deviation_m.z()};
  const char* names[6] = {"yaw_deg", "pitch_deg", "roll_deg", "x_m", "y_m", "z_m"};
  nlohmann::json measured, deviation, sigma;
  for (int i = 0; i < 6; ++i) {
    measured[names[i]] = values[i];
    deviation[names[i]] = m.observed[i] ? nlohmann::json(deviations[i]) : nlohmann::json(nullptr);
    sigma[names[i]] = m.observed[i] ? nlohmann::json(i < 3 ? m.sigma[i] * kDegPerRad : m.sigma[i])
                                    : nlohmann::json(nullptr);
  }
  return {{"T_car_sensor", MatrixToJson(m.T_car_sensor.Matrix())},
          {"mounting", measured},
          {"deviation", deviation},
          {"sigma", sigma}};
}

nlohmann::json Matrix3Json(const Eigen::Matrix3d& m) {
  nlohmann::json h = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) h.push_back(m(r, c));
  }
  return h;
}

nlohmann::json FiniteOrNull(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

// "board_method" and "roll_from_vertical_board" of a solved camera (docs/solvers.md).
nlohmann::json SeedFormulasJson(const SensorCalibration& s) {
  const BoardMethodResult& b = s.board_method;
  nlohmann::json board = {{"valid", b.valid}, {"reason", b.reason}, {"message", b.message}};
  if (b.valid) {
    nlohmann::json points_px = nlohmann::json::array(), points_car = nlohmann::json::array(),
                   points_toolbox = nlohmann::json::array();
    for (size_t i = 0; i < b.ground_points_px.size(); ++i) {
      points_px.push_back({b.ground_points_px[i].x(), b.ground_points_px[i].y()});
      points_car.push_back({b.ground_points_car_m[i].x(), b.ground_points_car_m[i].y()});
      points_toolbox.push_back(
          {b.toolbox_ground_points_car_m[i].x(), b.toolbox_ground_points_car_m[i].y()});
    }
    board["vanishing_point_px"] = {b.vanishing_point_px.x(), b.vanishing_point_px.y()};
    board["homography_rms_px"] = b.homography_rms_px;
    board["ground_points_px"] = points_px;
    board["ground_points_car_m"] = points_car;
    board["ground_homography"] = Matrix3Json(b.ground_homography);
    board["toolbox_ground_points_car_m"] = points_toolbox;
    board["toolbox_ground_homography"] = Matrix3Json(b.toolbox_ground_homography);
    if (s.vanishing_point_px)
      board["vanishing_point_disagreement_px"] = s.vanishing_point_disagreement_px;
    nlohmann::json ranging = nlohmann::json::array();
    for (size_t i = 0; i < s.ground_disagreement.size() && i < s.ranging.size(); ++i) {
      ranging.push_back({{"distance_m", s.ranging[i].true_distance_m},
                         {"fraction", FiniteOrNull(s.ground_disagreement[i])},
                         {"toolbox_fraction", FiniteOrNull(s.toolbox_ground_disagreement[i])}});
    }
    board["ranging_disagreement"] = ranging;
  }
  const VerticalBoardRoll& v = s.vertical_roll;
  nlohmann::json roll = {{"valid", v.valid}, {"reason", v.reason}, {"message", v.message}};
  if (v.valid) {
    roll["roll_deg"] = v.roll_rad * kDegPerRad;
    roll["pose_roll_deg"] = s.mounting.angles.roll * kDegPerRad;
    roll["difference_deg"] = (v.roll_rad - s.mounting.angles.roll) * kDegPerRad;
    roll["lines_used"] = v.lines_used;
  }
  return {{"board_method", board}, {"roll_from_vertical_board", roll}};
}

}  // namespace

nlohmann::json CycleCalibrationToJson(const Capture& capture, const CycleCalibration& cycle) {
  nlohmann::json sensors = nlohmann::json::array();
  for (const SensorCalibration& s : cycle.sensors) {
    nlohmann::json j = {{"name", s.name},
                        {"kind", SensorKindName(s.kind)},
                        {"verdict", VerdictName(s.verdict)},
                        {"reason", s.reason},
                        {"message", s.message},
                        {"features_used", s.features_used},
                        {"residual_rms", s.residual_rms},
                        {"elapsed_ms", s.elapsed_ns * 1e-6}};
    if (s.solved) j.update(MountingJson(s.mounting));
    if (s.kind != SensorKind::kRadar) {
      nlohmann::json boards = nlohmann::json::array();
      for (const BoardDetectionSummary& b : s.boards) {
        boards.push_back({{"board", b.board_id},
                          {"frames_found", b.frames_found},
                          {"frames_partial", b.frames_partial},
                          {"partial_allowed", b.partial_allowed},
                          {"reason", b.last_reason}});
      }
      j["boards"] = boards;
    }
    if (s.kind == SensorKind::kCamera) {
      if (s.vanishing_point_px)
        j["vanishing_point_px"] = {s.vanishing_point_px->x(), s.vanishing_point_px->y()};
      if (s.ground_homography) j["ground_homography"] = Matrix3Json(*s.ground_homography);
      nlohmann::json ranging = nlohmann::json::array();
      for (const RangingCheck& c : s.ranging) {
        ranging.push_back({{"true_distance_m", c.true_distance_m},
                           {"measured_distance_m", FiniteOrNull(c.measured_distance_m)}});
      }
      if (!s.ranging.empty()) j["ranging"] = ranging;
      if (s.solved) j.update(SeedFormulasJson(s));
    }
    sensors.push_back(std::move(j));
  }
  return {{"vin", capture.manifest.vin},
          {"car_model", capture.manifest.car_model},
          {"verdict", VerdictName(cycle.verdict)},
          {"elapsed_ms", cycle.elapsed_ns * 1e-6},
          {"sensors", sensors}};
}

}  // namespace linecal

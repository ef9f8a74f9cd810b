#include "station/planner/planner.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <optional>
#include <random>
#include <set>
#include <tuple>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "detectors/round_hole/round_hole_cloud.h"
#include "station/camera/camera_model.h"
#include "station/model/pose_json.h"
#include "station/sensors/lidar/lidar_format.h"
#include "station/sensors/radar/field_of_view.h"
#include "station/sim/lidar_sim.h"
#include "station/solvers/camera_calibration.h"
#include "station/solvers/lidar_calibration.h"
#include "station/solvers/radar_calibration.h"
#include "station/solvers/reflector_association.h"

namespace linecal {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;
// LiDAR ranking and valid regions use CalibrateLidar at this hole-centre sigma instead of a
// simulated scan (the detector's bar at 16 rings, lidar_calibration.h).
constexpr double kProxyCentreSigmaM = 0.005;
// The range a LiDAR board must be within: the simulator's window and far beyond a station.
constexpr double kLidarMinRangeM = 0.3;
constexpr double kLidarMaxRangeM = 120.0;

void AddReason(std::vector<std::string>* reasons, const std::string& code) {
  if (std::find(reasons->begin(), reasons->end(), code) == reasons->end()) reasons->push_back(code);
}

// too_few_features is reported only when the targets themselves are fine (the solve
// failed); when a target failed a check, that check is the reason.
void Finish(SensorAssessment* a) {
  if (a->reasons.size() > 1) {
    std::erase(a->reasons, std::string("too_few_features"));
  }
  a->calibratable = a->reasons.empty();
}

Eigen::Vector3d FeaturePoint(const StationBoard& b, const Eigen::Vector2d& p_board) {
  return b.T_station_board * Eigen::Vector3d(p_board.x(), p_board.y(), 0.0);
}

std::array<Eigen::Vector3d, 4> PageCorners(const StationBoard& b) {
  const Eigen::Vector2d h = 0.5 * b.board.page_size_m();
  return {FeaturePoint(b, {-h.x(), -h.y()}), FeaturePoint(b, {h.x(), -h.y()}),
          FeaturePoint(b, {h.x(), h.y()}), FeaturePoint(b, {-h.x(), h.y()})};
}

// True when the segment a-b passes through the rectangle of size `size` centred in the x-y
// plane of `T_station_rect`. Endpoints on the rectangle do not count.
bool SegmentHitsRectangle(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                          const Rigid3d& T_station_rect, const Eigen::Vector2d& size) {
  const Rigid3d T_rect_station = T_station_rect.Inverse();
  const Eigen::Vector3d pa = T_rect_station * a, pb = T_rect_station * b;
  if ((pa.z() > 0) == (pb.z() > 0) || pa.z() == pb.z()) return false;
  const double s = pa.z() / (pa.z() - pb.z());
  // The end points themselves (a feature on this very page) do not count.
  if (s < 1e-6 || s > 1 - 1e-6) return false;
  const Eigen::Vector3d hit = pa + s * (pb - pa);
  return std::abs(hit.x()) < 0.5 * size.x() && std::abs(hit.y()) < 0.5 * size.y();
}

// What hides a point from a sensor: a board's page or a surface (a wall, a screen) of the layout.
struct Occluding {
  std::string id;
  bool surface = false;
};

// The first board other than `self`, then the first surface, between the sensor and p.
std::optional<Occluding> Occluder(const Eigen::Vector3d& sensor, const Eigen::Vector3d& p,
                                  const StationLayout& layout, const std::string& self) {
  for (const StationBoard& other : layout.boards) {
    if (other.id != self && SegmentHitsBoard(sensor, p, other)) return Occluding{other.id, false};
  }
  for (const StationSurface& surface : layout.surfaces) {
    if (SegmentHitsRectangle(sensor, p, surface.T_station_surface, surface.size_m))
      return Occluding{surface.id, true};
  }
  return std::nullopt;
}

// Page samples per side for the hidden share of a board (HiddenPage): a 24 x 24 grid puts a
// sample every 4% of the page, finer than the narrowest strip an occluding board's edge cuts off
// that matters to the detectors (a marker is a fifth of the round-hole board's side).
constexpr int kHiddenPageSamples = 24;

// How much of a board's page a sensor at `eye` cannot see behind other boards and surfaces: of
// the page samples `in_view` accepts, the share hidden, and the occluder hiding most of them.
struct HiddenPage {
  double share = 0;
  std::optional<Occluding> by;
};
template <typename InView>
HiddenPage HiddenPageOf(const Eigen::Vector3d& eye, const StationBoard& b,
                        const StationLayout& layout, const InView& in_view) {
  const Eigen::Vector2d page = b.board.page_size_m();
  std::map<std::string, std::pair<int, Occluding>> hidden_by;  // id -> samples, occluder
  int seen = 0;
  int hidden = 0;
  for (int iy = 0; iy < kHiddenPageSamples; ++iy) {
    for (int ix = 0; ix < kHiddenPageSamples; ++ix) {
      const Eigen::Vector2d q(page.x() * ((ix + 0.5) / kHiddenPageSamples - 0.5),
                              page.y() * ((iy + 0.5) / kHiddenPageSamples - 0.5));
      const Eigen::Vector3d p = FeaturePoint(b, q);
      if (!in_view(p)) continue;
      ++seen;
      const std::optional<Occluding> o = Occluder(eye, p, layout, b.id);
      if (!o) continue;
      ++hidden;
      auto [it, inserted] = hidden_by.try_emplace(o->id, 0, *o);
      ++it->second.first;
    }
  }
  HiddenPage out;
  if (seen == 0 || hidden == 0) return out;
  out.share = static_cast<double>(hidden) / seen;
  int most = 0;
  for (const auto& [id, entry] : hidden_by) {
    if (entry.first > most) {
      most = entry.first;
      out.by = entry.second;
    }
  }
  return out;
}

// Floor checks of a footprint (or a point, as a one-vertex footprint) spanning heights
// [z_min, z_max].
void CheckFloor(const FloorLimits* floor, const FloorPolygon& footprint, double z_min, double z_max,
                TargetAssessment* t) {
  if (floor == nullptr) return;
  for (const KeepOutZone& zone : floor->keep_outs) {
    const bool hit = footprint.size() == 1 ? PointInPolygon(footprint[0], zone.polygon)
                                           : PolygonsOverlap(footprint, zone.polygon);
    if (hit) {
      AddReason(&t->reasons, "in_keep_out");
      t->detail += absl::StrCat(" in keep-out '", zone.id, "';");
    }
  }
  bool outside = false;
  for (const Eigen::Vector2d& p : footprint)
    outside = outside || !PointInPolygon(p, floor->usable_area);
  for (const FloorWall& w : floor->walls) {
    for (size_t i = 0; i + 1 < footprint.size() || (i == 0 && footprint.size() == 1); ++i) {
      const Eigen::Vector2d& a = footprint[i];
      const Eigen::Vector2d& b = footprint.size() == 1 ? footprint[0] : footprint[i + 1];
      outside = outside || SegmentsIntersect(a, b, w.from, w.to);
    }
  }
  if (outside) AddReason(&t->reasons, "outside_usable_area");
  if (z_min < floor->min_height_m - 1e-9 || z_max > floor->max_height_m + 1e-9) {
    AddReason(&t->reasons, "outside_height_limits");
    t->detail += absl::StrFormat(" spans z %.2f..%.2f m;", z_min, z_max);
  }
}

void CheckBoardFloor(const FloorLimits* floor, const StationBoard& b, TargetAssessment* t) {
  double z_min = std::numeric_limits<double>::infinity(), z_max = -z_min;
  for (const Eigen::Vector3d& c : PageCorners(b)) {
    z_min = std::min(z_min, c.z());
    z_max = std::max(z_max, c.z());
  }
  CheckFloor(floor, BoardFootprint(b), z_min, z_max, t);
}

double RatioOf(const SensorModel& sensor, const Eigen::Matrix<double, 6, 1>& sigma,
               const std::array<bool, 6>& observed, double fraction) {
  const double tol[6] = {sensor.tolerance.yaw_rad,   sensor.tolerance.pitch_rad,
                         sensor.tolerance.roll_rad,  sensor.tolerance.xyz_m.x(),
                         sensor.tolerance.xyz_m.y(), sensor.tolerance.xyz_m.z()};
  double ratio = 0;
  for (int i = 0; i < 6; ++i) {
    if (observed[i] && tol[i] > 0) ratio = std::max(ratio, sigma[i] / (fraction * tol[i]));
  }
  return ratio;
}

// The board a camera or LiDAR names as target `id`; null (with the reason) when there is
// none.
const StationBoard* TargetBoard(const StationLayout& layout, const std::string& id,
                                TargetAssessment* t) {
  t->target = id;
  const StationBoard* b = layout.FindBoard(id);
  if (b == nullptr)
    AddReason(&t->reasons, layout.FindReflector(id) ? "wrong_target_type" : "unknown_target");
  return b;
}

// The predicted sigma of a solver's mounting estimate and its verdict against the bar.
void TakeMounting(bool solved, const MountingEstimate& m, const SensorModel& sensor,
                  const PlannerOptions& o, SensorAssessment* a) {
  if (!solved) {
    AddReason(&a->reasons, "too_few_features");
    return;
  }
  a->sigma_valid = true;
  a->sigma = m.sigma;
  a->observed = m.observed;
  a->uncertainty_ratio = RatioOf(sensor, a->sigma, a->observed, o.max_sigma_fraction_of_tolerance);
  if (a->uncertainty_ratio > 1) AddReason(&a->reasons, "uncertainty_above_tolerance");
}

absl::StatusOr<std::vector<double>> BeamElevations(const SensorModel& sensor) {
  absl::StatusOr<LidarBeamTable> beams = LidarBeamTableOf(sensor);
  if (!beams.ok())
    return absl::InvalidArgumentError(absl::StrCat(sensor.name, ": ", beams.status().message()));
  std::vector<double> e;
  for (const LidarBeam& b : beams->beams) e.push_back(b.elevation_rad);
  return e;
}

// The occlusion reason of a target feature hidden behind `occluder` (none when empty).
void NoteOccluder(const std::optional<Occluding>& occluder, TargetAssessment* t) {
  if (!occluder) return;
  AddReason(&t->reasons, occluder->surface ? "occluded_by_surface" : "occluded_by_board");
  t->detail += absl::StrCat(" hidden behind '", occluder->id, "';");
}

// The share of a board's page hidden (HiddenPageOf), kept in the assessment and told in its
// detail: with a feature hidden as well (NoteOccluder) it is why the target fails; without,
// a part of the page the detectors leave out (the board is found from what shows).
void NoteHiddenPage(const HiddenPage& hidden, bool feature_hidden, TargetAssessment* t) {
  if (!hidden.by) return;
  t->hidden_share = hidden.share;
  t->hidden_by = hidden.by->id;
  t->detail +=
      absl::StrFormat(" %.0f%% of the page hidden, most behind '%s'%s;", 100 * hidden.share,
                      hidden.by->id, feature_hidden ? "" : ", no feature");
}

// A sensor's reasons: its targets', each once, in order.
void CollectTargetReasons(SensorAssessment* a) {
  for (const TargetAssessment& t : a->targets) {
    for (const std::string& r : t.reasons) AddReason(&a->reasons, r);
  }
}

// A round-hole board's exact hole centres and normal in the LiDAR frame, at `sigma_m`.
LidarBoardObservation ExactHoles(const StationBoard& b, const Rigid3d& T_lidar_station,
                                 double sigma_m) {
  LidarBoardObservation obs;
  obs.board_id = b.id;
  for (const BoardFeature& f : b.board.features()) {
    if (f.kind == FeatureKind::kHoleCentre)
      obs.holes.push_back({f.id, T_lidar_station * FeaturePoint(b, f.p_board)});
  }
  obs.normal_lidar = T_lidar_station.RotationMatrix() * b.T_station_board.RotationMatrix().col(2);
  obs.centre_sigma_m = sigma_m;
  return obs;
}

// --- cameras --------------------------------------------------------------------------

absl::StatusOr<SensorAssessment> AssessCamera(const SensorModel& sensor,
                                              const StationLayout& layout, const FloorLimits* floor,
                                              const PlannerOptions& o, bool predict) {
  if (!sensor.intrinsics)
    return absl::InvalidArgumentError(absl::StrCat(sensor.name, ": camera without intrinsics"));
  absl::StatusOr<CameraModel> camera = CameraModel::Create(*sensor.intrinsics);
  if (!camera.ok()) return camera.status();
  SensorAssessment a;
  a.sensor = sensor.name;
  a.kind = sensor.kind;
  const Rigid3d T_camera_station = sensor.T_car_sensor_nominal.Inverse();
  const Eigen::Vector3d eye = sensor.T_car_sensor_nominal.translation();
  const double w = sensor.intrinsics->width, h = sensor.intrinsics->height, m = o.image_margin_px;
  std::vector<BoardObservation> observations;
  for (const std::string& id : sensor.targets) {
    TargetAssessment& t = a.targets.emplace_back();
    const StationBoard* b = TargetBoard(layout, id, &t);
    if (b == nullptr) continue;
    const Rigid3d T_camera_board = T_camera_station * b->T_station_board;
    bool inside = BoardFacesCamera(T_camera_board);
    BoardObservation obs;
    obs.board_id = id;
    std::optional<Occluding> occluder;
    for (const BoardFeature& f : b->board.features()) {
      if (f.kind == FeatureKind::kHoleCentre) continue;  // LiDAR features, no image
      Eigen::Vector2d uv;
      const Eigen::Vector3d p = FeaturePoint(*b, f.p_board);
      if (!camera->Project(T_camera_station * p, &uv) || uv.x() < m || uv.y() < m ||
          uv.x() > w - 1 - m || uv.y() > h - 1 - m) {
        inside = false;
        continue;
      }
      if (!occluder) occluder = Occluder(eye, p, layout, id);
      obs.features.push_back({f.id, uv, f.p_board, f.marker});
    }
    t.features = static_cast<int>(obs.features.size());
    if (!inside) AddReason(&t.reasons, "board_outside_fov");
    t.smallest_feature_px = SmallestCellPx(*camera, T_camera_board, b->board);
    if (t.smallest_feature_px < o.min_feature_px) {
      AddReason(&t.reasons, "features_too_small");
      t.detail += absl::StrFormat(" smallest cell %.1f px < %.1f px;", t.smallest_feature_px,
                                  o.min_feature_px);
    }
    NoteOccluder(occluder, &t);
    NoteHiddenPage(HiddenPageOf(eye, *b, layout,
                                [&](const Eigen::Vector3d& p) {
                                  Eigen::Vector2d uv;
                                  return camera->Project(T_camera_station * p, &uv) &&
                                         uv.x() >= 0 && uv.y() >= 0 && uv.x() <= w - 1 &&
                                         uv.y() <= h - 1;
                                }),
                   occluder.has_value(), &t);
    CheckBoardFloor(floor, *b, &t);
    if (t.reasons.empty()) {
      for (int k = 0; k < o.camera_frames; ++k) observations.push_back(obs);
    }
  }
  CollectTargetReasons(&a);
  if (predict) {
    CameraCalibrationOptions co;
    co.pnp.feature_sigma_px = sensor.intrinsics &&
                                      sensor.intrinsics->type == CameraModelType::kFisheye &&
                                      o.fisheye_corner_noise_px > 0
                                  ? o.fisheye_corner_noise_px
                                  : o.corner_noise_px;
    co.max_sigma_fraction_of_tolerance = o.max_sigma_fraction_of_tolerance;
    absl::StatusOr<CameraCalibrationResult> r =
        observations.empty() ? absl::StatusOr<CameraCalibrationResult>(CameraCalibrationResult{})
                             : CalibrateCamera(sensor, layout, Rigid3d(), observations, co);
    if (!r.ok()) return r.status();
    TakeMounting(r->solved, r->mounting, sensor, o, &a);
  }
  Finish(&a);
  return a;
}

// --- LiDARs ---------------------------------------------------------------------------

double HoleRadiusM(const Board& board) {
  for (const BoardShape& s : board.shapes()) {
    if (s.paint == Paint::kHole) return s.radius_m();
  }
  return 0;
}

// Checks LiDAR target `id` of `layout` for the LiDAR at its nominal mounting T_station_lidar
// (beams at `elevations`) into *t: type, field of view, rings through each hole, sight of
// the holes' rims and the page, the floor. The board when it is usable (no reason), else
// nullptr.
const StationBoard* AssessLidarTarget(const std::string& id, const StationLayout& layout,
                                      const FloorLimits* floor, const PlannerOptions& o,
                                      const std::vector<double>& elevations,
                                      const Rigid3d& T_station_lidar, TargetAssessment* t) {
  const Rigid3d T_lidar_station = T_station_lidar.Inverse();
  const Eigen::Vector3d eye = T_station_lidar.translation();
  const StationBoard* b = TargetBoard(layout, id, t);
  if (b == nullptr) return nullptr;
  if (b->board.type() != BoardType::kRoundHole) {
    AddReason(&t->reasons, "wrong_target_type");
    return nullptr;
  }
  const Eigen::Vector3d normal = b->T_station_board.RotationMatrix().col(2);
  const Eigen::Vector3d to_eye = eye - b->T_station_board.translation();
  const double range = to_eye.norm();
  if (normal.dot(to_eye) <= 0 || range < kLidarMinRangeM || range > kLidarMaxRangeM) {
    AddReason(&t->reasons, "board_outside_fov");
  }
  const double radius = HoleRadiusM(b->board);
  const Eigen::Vector3d normal_lidar = T_lidar_station.RotationMatrix() * normal;
  t->fewest_rings = std::numeric_limits<int>::max();
  std::optional<Occluding> occluder;
  for (const BoardFeature& f : b->board.features()) {
    if (f.kind != FeatureKind::kHoleCentre) continue;
    ++t->features;
    const Eigen::Vector3d c = FeaturePoint(*b, f.p_board);
    t->fewest_rings = std::min(
        t->fewest_rings, RingsThroughHole(elevations, T_lidar_station * c, normal_lidar, radius));
    // The hole's rim, where the rings' edges are measured, must be in sight.
    for (int k = 0; k < 8 && !occluder; ++k) {
      const double phi = 2 * kPi * k / 8;
      const Eigen::Vector2d rim =
          f.p_board + radius * Eigen::Vector2d(std::cos(phi), std::sin(phi));
      occluder = Occluder(eye, FeaturePoint(*b, rim), layout, id);
    }
  }
  if (t->features == 0) t->fewest_rings = 0;
  if (t->fewest_rings < o.min_rings_per_hole) {
    AddReason(&t->reasons, "too_few_rings");
    t->detail += absl::StrFormat(" %d ring(s) through the worst hole < %d;", t->fewest_rings,
                                 o.min_rings_per_hole);
  }
  NoteOccluder(occluder, t);
  NoteHiddenPage(HiddenPageOf(eye, *b, layout, [](const Eigen::Vector3d&) { return true; }),
                 occluder.has_value(), t);
  CheckBoardFloor(floor, *b, t);
  return t->reasons.empty() ? b : nullptr;
}

// Per usable board, the detector's sigmas and board-pose covariance summed over the
// simulated mountings that found it, and the detector's reason at the nominal mounting.
struct DetectorSpread {
  std::vector<double> centre_var, normal_var;
  std::vector<Eigen::Matrix<double, 6, 6>> pose_covariance;  // board frame
  std::vector<int> found;
  std::vector<RoundHoleCloudReason> nominal_reason;
};

// The detector's own hole-centre sigma on simulated rotations (fixed seed). Where the rings
// cross the holes depends on the true mounting, and with it the detector's sigma (by up to
// 1.6x between cars for two rings per hole): the prediction is its RMS over the nominal
// mounting and pitch or roll half a tolerance either way. Five simulated rotations, each
// searched for every usable board.
absl::StatusOr<DetectorSpread> SimulateDetectorSpread(
    const SensorModel& sensor, const StationLayout& layout,
    const std::vector<const StationBoard*>& usable) {
  const Rigid3d& T_station_lidar = sensor.T_car_sensor_nominal;
  const Rigid3d T_lidar_station = T_station_lidar.Inverse();
  absl::StatusOr<LidarBeamTable> beams = LidarBeamTableOf(sensor);
  if (!beams.ok()) return beams.status();
  const YawPitchRoll nominal =
      MountingAngles(T_station_lidar.RotationMatrix(), LidarBaseRotation());
  const double dp = 0.5 * sensor.tolerance.pitch_rad, dr = 0.5 * sensor.tolerance.roll_rad;
  const double offsets[5][2] = {{0, 0}, {dp, 0}, {-dp, 0}, {0, dr}, {0, -dr}};
  DetectorSpread s;
  s.centre_var.assign(usable.size(), 0);
  s.normal_var.assign(usable.size(), 0);
  s.pose_covariance.assign(usable.size(), Eigen::Matrix<double, 6, 6>::Zero());
  s.found.assign(usable.size(), 0);
  s.nominal_reason.assign(usable.size(), RoundHoleCloudReason::kBadInput);
  for (int k = 0; k < 5; ++k) {
    YawPitchRoll ypr = nominal;
    ypr.pitch += offsets[k][0];
    ypr.roll += offsets[k][1];
    const Rigid3d T_station_true(MountingRotation(ypr, LidarBaseRotation()),
                                 T_station_lidar.translation());
    absl::StatusOr<LidarSimResult> sim =
        SimulateLidar(*beams, T_station_true, layout, LidarSimOptions{}, 0, 1);
    if (!sim.ok()) return sim.status();
    std::vector<std::vector<RoundHoleCloudPoint>> frames;
    for (const LidarScan& scan : sim->scans) {
      std::vector<RoundHoleCloudPoint>& pts = frames.emplace_back();
      for (const LidarPoint& p : scan.points) pts.push_back({p.x, p.y, p.z, p.ring});
    }
    const std::vector<std::span<const RoundHoleCloudPoint>> views(frames.begin(), frames.end());
    for (size_t i = 0; i < usable.size(); ++i) {
      const RoundHoleCloudDetection d = DetectRoundHoleBoardInCloud(
          usable[i]->board, views, T_lidar_station * usable[i]->T_station_board);
      if (k == 0) s.nominal_reason[i] = d.reason;
      if (!d.found) continue;
      const LidarBoardObservation o = LidarObservationFromDetection(usable[i]->id, d);
      s.centre_var[i] += o.centre_sigma_m * o.centre_sigma_m;
      s.normal_var[i] += o.normal_sigma_rad * o.normal_sigma_rad;
      s.pose_covariance[i] += o.pose_covariance;
      ++s.found[i];
    }
  }
  return s;
}

// The exact observations of the usable boards with the detector's mean sigmas and pose
// covariance (the prediction, not the measurement); a board the detector missed at the
// nominal mounting or at all gets "board_not_detected" in a's targets instead.
std::vector<LidarBoardObservation> PredictedObservations(
    const std::vector<const StationBoard*>& usable, const DetectorSpread& s,
    const Rigid3d& T_lidar_station, SensorAssessment* a) {
  std::vector<LidarBoardObservation> observations;
  for (size_t i = 0; i < usable.size(); ++i) {
    const StationBoard* b = usable[i];
    if (s.nominal_reason[i] != RoundHoleCloudReason::kNone || s.found[i] == 0) {
      for (TargetAssessment& t : a->targets) {
        if (t.target != b->id) continue;
        AddReason(&t.reasons, "board_not_detected");
        t.detail += absl::StrCat(" detector: ", RoundHoleCloudReasonName(s.nominal_reason[i]), ";");
      }
      continue;
    }
    LidarBoardObservation obs =
        ExactHoles(*b, T_lidar_station, std::sqrt(s.centre_var[i] / s.found[i]));
    obs.normal_sigma_rad = std::sqrt(s.normal_var[i] / s.found[i]);
    obs.T_lidar_board = T_lidar_station * b->T_station_board;
    obs.pose_covariance = s.pose_covariance[i] / s.found[i];
    observations.push_back(obs);
  }
  return observations;
}

// The mounting CalibrateLidar would give from `observations` (the car at the station's
// origin), taken into *a; "too_few_features" with fewer than three holes.
absl::Status PredictLidarMounting(const SensorModel& sensor, const StationLayout& layout,
                                  const std::vector<LidarBoardObservation>& observations,
                                  const PlannerOptions& o, SensorAssessment* a) {
  LidarCalibrationOptions lo;
  lo.max_sigma_fraction_of_tolerance = o.max_sigma_fraction_of_tolerance;
  int holes = 0;
  for (const LidarBoardObservation& ob : observations) holes += static_cast<int>(ob.holes.size());
  if (holes >= 3) {
    absl::StatusOr<LidarCalibrationResult> r =
        CalibrateLidar(sensor, layout, Rigid3d(), observations, lo);
    if (!r.ok()) return r.status();
    TakeMounting(r->solved, r->mounting, sensor, o, a);
  } else {
    AddReason(&a->reasons, "too_few_features");
  }
  return absl::OkStatus();
}

absl::StatusOr<SensorAssessment> AssessLidar(const SensorModel& sensor, const StationLayout& layout,
                                             const FloorLimits* floor, const PlannerOptions& o,
                                             bool predict, bool simulate) {
  absl::StatusOr<std::vector<double>> elevations = BeamElevations(sensor);
  if (!elevations.ok()) return elevations.status();
  SensorAssessment a;
  a.sensor = sensor.name;
  a.kind = sensor.kind;
  const Rigid3d& T_station_lidar = sensor.T_car_sensor_nominal;
  const Rigid3d T_lidar_station = T_station_lidar.Inverse();
  std::vector<const StationBoard*> usable;
  for (const std::string& id : sensor.targets) {
    TargetAssessment& t = a.targets.emplace_back();
    const StationBoard* b =
        AssessLidarTarget(id, layout, floor, o, *elevations, T_station_lidar, &t);
    if (b != nullptr) usable.push_back(b);
  }
  std::vector<LidarBoardObservation> observations;
  if (predict && simulate && !usable.empty()) {
    absl::StatusOr<DetectorSpread> spread = SimulateDetectorSpread(sensor, layout, usable);
    if (!spread.ok()) return spread.status();
    observations = PredictedObservations(usable, *spread, T_lidar_station, &a);
  } else if (predict) {
    for (const StationBoard* b : usable)
      observations.push_back(ExactHoles(*b, T_lidar_station, kProxyCentreSigmaM));
  }
  CollectTargetReasons(&a);
  if (predict) {
    if (absl::Status s = PredictLidarMounting(sensor, layout, observations, o, &a); !s.ok())
      return s;
  }
  Finish(&a);
  return a;
}

// --- radars ---------------------------------------------------------------------------

absl::StatusOr<SensorAssessment> AssessRadar(const SensorModel& sensor, const StationLayout& layout,
                                             const FloorLimits* floor, const PlannerOptions& o,
                                             bool predict) {
  const std::optional<RadarFieldOfView> fov = RadarFieldOfViewOf(sensor.model);
  if (!fov)
    return absl::InvalidArgumentError(
        absl::StrCat(sensor.name, ": unknown radar model '", sensor.model, "'"));
  SensorAssessment a;
  a.sensor = sensor.name;
  a.kind = sensor.kind;
  a.observed = {true, false, false, false, false, false};
  const Rigid3d T_radar_station = sensor.T_car_sensor_nominal.Inverse();
  const Eigen::Vector3d eye = sensor.T_car_sensor_nominal.translation();
  StationLayout usable_layout;  // the reflectors that pass, for the prediction
  SensorModel usable_sensor = sensor;
  usable_sensor.targets.clear();
  for (const std::string& id : sensor.targets) {
    TargetAssessment& t = a.targets.emplace_back();
    t.target = id;
    const CornerReflector* r = layout.FindReflector(id);
    if (r == nullptr) {
      AddReason(&t.reasons, layout.FindBoard(id) ? "wrong_target_type" : "unknown_target");
      continue;
    }
    const Eigen::Vector3d p = T_radar_station * r->p_station;
    const double azimuth = std::atan2(p.y(), p.x());
    if (std::abs(azimuth) > fov->half_fov_rad || p.norm() > fov->max_range_m || p.x() <= 0) {
      AddReason(&t.reasons, "reflector_outside_fov");
      t.detail += absl::StrFormat(" azimuth %.1f deg, range %.1f m;", azimuth / kDeg, p.norm());
    }
    NoteOccluder(Occluder(eye, r->p_station, layout, ""), &t);
    CheckFloor(floor, {r->p_station.head<2>()}, r->p_station.z(), r->p_station.z(), &t);
    t.features = 1;
    if (t.reasons.empty()) {
      usable_layout.reflectors.push_back(*r);
      usable_sensor.targets.push_back(id);
    }
  }
  CollectTargetReasons(&a);
  if (predict) {
    absl::StatusOr<std::vector<ExpectedReflector>> expected =
        ExpectedReflectors(usable_sensor, usable_layout, Rigid3d());
    if (!expected.ok()) return expected.status();
    absl::StatusOr<ReflectorAssociationOptions> ao = ReflectorAssociationOptions::ForSensor(sensor);
    if (!ao.ok()) return ao.status();
    // Detections as the radar reports them: the sensor's noise, then its resolution. A
    // position grid (ARS408) makes the σ depend on where the reflectors land in it (a reflector
    // on a cell edge flips between cells, one in the middle never moves), so the prediction is
    // the RMS σ over lateral shifts of the grid by eighths of a cell: what a car sees on
    // average. Fixed seed: the same plan gives the same prediction.
    const RadarResolution& res = ao->resolution;
    const int phases = res.position_step_m > 0 ? 8 : 1;
    std::mt19937_64 rng(1);
    std::normal_distribution<double> normal;
    const auto quantise = [](double v, double step, double origin) {
      return step > 0 ? origin + step * std::round((v - origin) / step) : v;
    };
    RadarCalibrationOptions ro;
    ro.max_sigma_fraction_of_tolerance = o.max_sigma_fraction_of_tolerance;
    RadarCalibrationResult r;
    double sum_sigma2 = 0;
    for (int phase = 0; phase < phases; ++phase) {
      const double y_origin = res.position_step_m * phase / phases;
      std::vector<RadarCycle> cycles(o.radar_cycles);
      for (RadarCycle& c : cycles) {
        for (size_t k = 0; k < expected->size(); ++k) {
          const double range = (*expected)[k].range_m + ao->detection_range_sigma_m * normal(rng);
          const double azimuth =
              (*expected)[k].azimuth_rad + ao->detection_azimuth_sigma_rad * normal(rng);
          const double x =
              quantise(range * std::cos(azimuth), res.position_step_m, res.position_x_origin_m);
          const double y = quantise(range * std::sin(azimuth), res.position_step_m, y_origin);
          RadarDetection d;
          d.id = static_cast<int>(k);
          d.range_m = quantise(std::hypot(x, y), res.range_step_m, 0);
          d.azimuth_rad = quantise(std::atan2(y, x), res.azimuth_step_rad, 0);
          d.rcs_dbsm = usable_layout.reflectors[k].rcs_dbsm;
          c.detections.push_back(d);
        }
      }
      const ReflectorAssociation association = AssociateReflectors(cycles, *expected, *ao);
      r = CalibrateRadarYaw(sensor, *expected, association, ro);
      sum_sigma2 += r.yaw_sigma_rad * r.yaw_sigma_rad;
    }
    r.yaw_sigma_rad = std::sqrt(sum_sigma2 / phases);
    if (r.reflectors_used >= ro.min_reflectors) {
      a.sigma_valid = true;
      a.sigma[0] = r.yaw_sigma_rad;
      a.uncertainty_ratio = RatioOf(sensor, a.sigma, a.observed, o.max_sigma_fraction_of_tolerance);
      if (a.uncertainty_ratio > 1) AddReason(&a.reasons, "uncertainty_above_tolerance");
    } else {
      AddReason(&a.reasons, "too_few_features");
    }
  }
  Finish(&a);
  return a;
}

absl::StatusOr<SensorAssessment> Assess(const SensorModel& sensor, const StationLayout& layout,
                                        const FloorLimits* floor, const PlannerOptions& o,
                                        bool predict, bool simulate) {
  switch (sensor.kind) {
    case SensorKind::kCamera:
      return AssessCamera(sensor, layout, floor, o, predict);
    case SensorKind::kLidar:
      return AssessLidar(sensor, layout, floor, o, predict, simulate);
    case SensorKind::kRadar:
      return AssessRadar(sensor, layout, floor, o, predict);
  }
  return absl::InvalidArgumentError("unknown sensor kind");
}

// --- planning -------------------------------------------------------------------------

// The yaw (degrees, board convention) of an upright board at p whose print faces `eye`.
double FacingYawDeg(const Eigen::Vector3d& p, const Eigen::Vector3d& eye) {
  const Eigen::Vector3d d = eye - p;
  return std::atan2(-d.y(), -d.x()) / kDeg;
}

StationBoard MakeBoard(const std::string& id, const BoardParams& params, const Eigen::Vector3d& xyz,
                       const YawPitchRoll& ypr) {
  StationBoard b;
  b.id = id;
  b.params = params;
  b.board = *Board::Create(params);
  b.T_station_board = Rigid3d(MountingRotation(ypr, BoardBaseRotation()), xyz);
  return b;
}

// The sensor's horizontal heading in the station (radians): its looking direction's azimuth.
double HeadingOf(const SensorModel& sensor) {
  const Eigen::Matrix3d R = sensor.T_car_sensor_nominal.RotationMatrix();
  Eigen::Vector3d forward;
  switch (sensor.kind) {
    case SensorKind::kCamera:
      forward = R.col(2);
      break;  // optical axis
    case SensorKind::kLidar:
      forward = R.col(1);
      break;  // azimuth 0 (vendor +y)
    case SensorKind::kRadar:
      forward = R.col(0);
      break;  // boresight
  }
  return std::atan2(forward.y(), forward.x());
}

double PitchDownOf(const SensorModel& sensor) {
  const Eigen::Vector3d f = sensor.T_car_sensor_nominal.RotationMatrix().col(2);
  return std::atan2(-f.z(), std::hypot(f.x(), f.y()));
}

bool HasSensor(const std::vector<SensorModel>& placed, const std::string& name) {
  return std::any_of(placed.begin(), placed.end(),
                     [&](const SensorModel& s) { return s.name == name; });
}

// True when adding the candidate targets to `layout` leaves every sensor already placed
// as calibratable, geometrically, as it was.
absl::StatusOr<bool> KeepsOthers(const std::vector<SensorModel>& placed,
                                 const StationLayout& layout, const FloorLimits& floor,
                                 const PlannerOptions& o) {
  for (const SensorModel& s : placed) {
    absl::StatusOr<SensorAssessment> a = Assess(s, layout, &floor, o, false, false);
    if (!a.ok()) return a.status();
    if (!a->calibratable) return false;
  }
  return true;
}

struct Candidate {
  std::vector<StationBoard> boards;
  std::vector<CornerReflector> reflectors;
};

// The best candidate: calibratable with `existing` targets + the candidate's, not
// disturbing the others, lowest predicted uncertainty ratio (LiDARs: ranked by the proxy,
// the simulated detector decides among the best few). When none is, the least bad one
// (fewest reasons, then lowest ratio), so that the plan says why.
absl::StatusOr<std::optional<Candidate>> BestCandidate(
    const SensorModel& sensor, const std::vector<Candidate>& candidates,
    const std::vector<std::string>& existing, const std::vector<SensorModel>& placed,
    const StationLayout& layout, const FloorLimits& floor, const PlannerOptions& o) {
  const auto trial_of = [&](const Candidate& c, StationLayout* trial, SensorModel* s) {
    *trial = layout;
    *s = sensor;
    s->targets = existing;
    for (const StationBoard& b : c.boards) {
      trial->boards.push_back(b);
      s->targets.push_back(b.id);
    }
    for (const CornerReflector& r : c.reflectors) {
      trial->reflectors.push_back(r);
      s->targets.push_back(r.id);
    }
  };
  std::vector<std::pair<double, size_t>> ranked;
  std::optional<std::pair<std::tuple<int, size_t, double>, size_t>> least_bad;
  for (size_t i = 0; i < candidates.size(); ++i) {
    StationLayout trial;
    SensorModel s;
    trial_of(candidates[i], &trial, &s);
    absl::StatusOr<SensorAssessment> a = Assess(s, trial, &floor, o, true, false);
    if (!a.ok()) return a.status();
    // The others are assessed only for candidates that work for this sensor (the costly
    // part); the rest count as spoiling them.
    bool keeps = false;
    if (a->calibratable) {
      absl::StatusOr<bool> k = KeepsOthers(placed, trial, floor, o);
      if (!k.ok()) return k.status();
      keeps = *k;
    }
    // Never spoil a sensor already planned if it can be helped.
    const std::tuple<int, size_t, double> badness = {keeps ? 0 : 1, a->reasons.size(),
                                                     a->uncertainty_ratio};
    if (!least_bad || badness < least_bad->first) least_bad = {{badness, i}};
    if (a->calibratable && keeps) ranked.push_back({a->uncertainty_ratio, i});
  }
  std::sort(ranked.begin(), ranked.end());
  for (size_t k = 0; k < ranked.size() && k < 6; ++k) {
    const Candidate& c = candidates[ranked[k].second];
    if (sensor.kind != SensorKind::kLidar) return std::optional<Candidate>(c);
    StationLayout trial;
    SensorModel s;
    trial_of(c, &trial, &s);
    absl::StatusOr<SensorAssessment> a = Assess(s, trial, &floor, o, true, true);
    if (!a.ok()) return a.status();
    if (a->calibratable) return std::optional<Candidate>(c);
  }
  if (least_bad) return std::optional<Candidate>(candidates[least_bad->second]);
  return std::optional<Candidate>();
}

std::vector<Candidate> LidarCandidates(const SensorModel& sensor, const FloorLimits& floor) {
  std::vector<Candidate> out;
  const Eigen::Vector3d eye = sensor.T_car_sensor_nominal.translation();
  const double heading = HeadingOf(sensor);
  for (double scale : {1.0, 1.5, 2.0}) {
    BoardParams p;
    p.type = BoardType::kRoundHole;
    p.scale = scale;
    const double half = 0.55 * scale;
    for (double d = 3.0; d <= 12.0; d += 1.0) {
      for (double theta_deg : {10.0, 15.0, 20.0, 30.0}) {
        // The board centre at the LiDAR's height, within the height limits.
        const double z =
            std::clamp(eye.z(), floor.min_height_m + half + 0.1, floor.max_height_m - half);
        Candidate c;
        for (int side : {+1, -1}) {
          const double az = heading + side * theta_deg * kDeg;
          const Eigen::Vector3d xyz = eye + d * Eigen::Vector3d(std::cos(az), std::sin(az), 0) +
                                      Eigen::Vector3d(0, 0, z - eye.z());
          c.boards.push_back(
              MakeBoard(absl::StrCat(sensor.name, side > 0 ? "_board_left" : "_board_right"), p,
                        xyz, {FacingYawDeg(xyz, eye) * kDeg, 0, 0}));
        }
        out.push_back(std::move(c));
      }
    }
  }
  return out;
}

std::vector<Candidate> CameraCandidates(const SensorModel& sensor, const FloorLimits& floor) {
  std::vector<Candidate> out;
  const Eigen::Vector3d eye = sensor.T_car_sensor_nominal.translation();
  const double heading = HeadingOf(sensor);
  const double pitch_down = PitchDownOf(sensor);
  const std::string id = sensor.name + "_board";
  for (BoardType type : {BoardType::kChessboard, BoardType::kCircle, BoardType::kVertical,
                         BoardType::kAruco, BoardType::kApriltag}) {
    for (double scale : {1.0, 2.0}) {
      // The chessboard is 2.6 m wide already.
      if (type == BoardType::kChessboard && scale > 1) continue;
      BoardParams p;
      p.type = type;
      p.scale = scale;
      p.apriltag_border_bits = 1;  // the layout stock libapriltag decodes (docs/boards.md)
      const Board board = *Board::Create(p);
      const double half_h = 0.5 * board.page_size_m().y();
      for (double d = 1.0; d <= 12.0; d += 0.5) {
        for (double off_deg : {0.0, -10.0, 10.0}) {
          const double az = heading + off_deg * kDeg;
          const Eigen::Vector3d dir(std::cos(az), std::sin(az), 0);
          // Upright, centred on the optical axis's height at that distance.
          const double z_axis = eye.z() - d * std::tan(pitch_down);
          const double z =
              std::clamp(z_axis, floor.min_height_m + half_h + 0.1, floor.max_height_m - half_h);
          const Eigen::Vector3d xyz = eye + d * dir + Eigen::Vector3d(0, 0, z - eye.z());
          out.push_back({{MakeBoard(id, p, xyz, {FacingYawDeg(xyz, eye) * kDeg, 0, 0})}, {}});
          // Lying on the floor, its top away from the camera, for cameras looking down.
          if (pitch_down > 10 * kDeg) {
            const Eigen::Vector3d on_floor(eye.x() + d * dir.x(), eye.y() + d * dir.y(), 0.002);
            out.push_back({{MakeBoard(id, p, on_floor, {az, 90 * kDeg, 0})}, {}});
          }
        }
      }
    }
  }
  return out;
}

std::vector<Candidate> RadarCandidates(const SensorModel& sensor) {
  std::vector<Candidate> out;
  const std::optional<RadarFieldOfView> fov = RadarFieldOfViewOf(sensor.model);
  if (!fov) return out;
  const Eigen::Vector3d eye = sensor.T_car_sensor_nominal.translation();
  const double heading = HeadingOf(sensor);
  for (double r = 3.0; r <= std::min(20.0, fov->max_range_m); r += 1.0) {
    for (double spread : {0.1, 0.2, 0.35, 0.5, 0.7}) {
      // Three reflectors spread about a direction, that direction shifted across the view
      // so that they can pass beside other targets.
      for (double shift : {0.0, -0.25, 0.25, -0.5, 0.5}) {
        if (std::abs(shift) + spread > 0.9) continue;
        Candidate c;
        int k = 0;
        for (double f : {-1.0, 0.0, 1.0}) {
          const double az = heading + (shift + f * spread) * fov->half_fov_rad;
          CornerReflector refl;
          refl.id = absl::StrCat(sensor.name, "_refl_", k++);
          refl.p_station = eye + r * Eigen::Vector3d(std::cos(az), std::sin(az), 0);
          refl.rcs_dbsm = 20;
          c.reflectors.push_back(refl);
        }
        out.push_back(std::move(c));
      }
    }
  }
  return out;
}

// Pinhole cameras first (their boards need the middle of the view), then LiDARs, fisheye
// cameras, radars (whose lines of sight must pass every board).
int PlanOrder(const SensorModel& s) {
  if (s.kind == SensorKind::kCamera) return s.model == "pinhole" ? 0 : 2;
  return s.kind == SensorKind::kLidar ? 1 : 3;
}

}  // namespace

absl::Status PlannerOptions::Validate() const {
  const auto bad = [](const char* field, double v, const char* range) {
    return absl::InvalidArgumentError(absl::StrCat(field, " = ", v, ": must be in ", range));
  };
  if (!(min_feature_px > 0 && min_feature_px <= 1000))
    return bad("min_feature_px", min_feature_px, "(0, 1000]");
  if (!(corner_noise_px > 0 && corner_noise_px <= 10))
    return bad("corner_noise_px", corner_noise_px, "(0, 10]");
  if (!(fisheye_corner_noise_px >= 0 && fisheye_corner_noise_px <= 10)) {
    return bad("fisheye_corner_noise_px", fisheye_corner_noise_px, "[0, 10]");
  }
  if (camera_frames < 1 || camera_frames > 100)
    return bad("camera_frames", camera_frames, "1..100");
  if (!(image_margin_px >= 0 && image_margin_px <= 500))
    return bad("image_margin_px", image_margin_px, "[0, 500]");
  if (!(min_fill_share > 0 && min_fill_share <= 1))
    return bad("min_fill_share", min_fill_share, "(0, 1]");
  if (!(max_fill_share >= min_fill_share && max_fill_share <= 1)) {
    return bad("max_fill_share", max_fill_share, "[min_fill_share, 1]");
  }
  if (min_rings_per_hole < 1 || min_rings_per_hole > 64)
    return bad("min_rings_per_hole", min_rings_per_hole, "1..64");
  if (radar_cycles < 10 || radar_cycles > 10000)
    return bad("radar_cycles", radar_cycles, "10..10000");
  if (!(max_sigma_fraction_of_tolerance > 0 && max_sigma_fraction_of_tolerance <= 10)) {
    return bad("max_sigma_fraction_of_tolerance", max_sigma_fraction_of_tolerance, "(0, 10]");
  }
  return absl::OkStatus();
}

absl::StatusOr<SensorAssessment> AssessSensor(const SensorModel& sensor,
                                              const StationLayout& layout, const FloorLimits* floor,
                                              const PlannerOptions& options, bool predict_sigma) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  return Assess(sensor, layout, floor, options, predict_sigma, true);
}

absl::StatusOr<std::vector<SensorAssessment>> AssessLayout(const CarModel& car,
                                                           const StationLayout& layout,
                                                           const FloorLimits* floor,
                                                           const PlannerOptions& options) {
  std::vector<SensorAssessment> out;
  for (const SensorModel& s : car.sensors) {
    absl::StatusOr<SensorAssessment> a = AssessSensor(s, layout, floor, options);
    if (!a.ok()) return a.status();
    out.push_back(*std::move(a));
  }
  return out;
}

absl::StatusOr<StationPlan> PlanLayout(const CarModel& car, const FloorLimits& floor,
                                       const PlannerOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  StationPlan plan;
  plan.car = car;
  plan.layout.name = "plan-" + car.id;
  plan.layout.floor_reflectivity = 0.25;
  for (const FloorWall& w : floor.walls) {
    // Walls for the simulator: upright rectangles facing into the station, to the ceiling.
    StationSurface s;
    s.id = w.id;
    const Eigen::Vector2d mid = 0.5 * (w.from + w.to);
    const Eigen::Vector2d along = w.to - w.from;
    s.size_m = {along.norm(), floor.max_height_m + 1.0};
    double yaw = std::atan2(along.y(), along.x()) - kPi / 2;  // normal to the segment
    if (Eigen::Vector2d(std::cos(yaw), std::sin(yaw)).dot(mid) < 0)
      yaw += kPi;  // print side faces the origin
    s.T_station_surface = Rigid3d(MountingRotation({yaw, 0, 0}, BoardBaseRotation()),
                                  Eigen::Vector3d(mid.x(), mid.y(), 0.5 * s.size_m.y()));
    s.reflectivity = 0.5;
    plan.layout.surfaces.push_back(s);
  }
  std::vector<size_t> order(car.sensors.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return PlanOrder(car.sensors[a]) < PlanOrder(car.sensors[b]);
  });
  std::vector<SensorModel> placed;
  for (size_t i : order) {
    SensorModel sensor = car.sensors[i];
    // The targets already placed that this sensor can use (geometrically).
    std::vector<std::string> existing;
    if (sensor.kind != SensorKind::kRadar) {
      for (const StationBoard& b : plan.layout.boards) {
        SensorModel probe = sensor;
        probe.targets = {b.id};
        absl::StatusOr<SensorAssessment> a =
            Assess(probe, plan.layout, &floor, options, false, false);
        if (!a.ok()) return a.status();
        if (a->calibratable) existing.push_back(b.id);
      }
    }
    sensor.targets = existing;
    bool done = false;
    if (!existing.empty()) {
      absl::StatusOr<SensorAssessment> a = Assess(sensor, plan.layout, &floor, options, true, true);
      if (!a.ok()) return a.status();
      done = a->calibratable;
    }
    if (!done) {
      const std::vector<Candidate> candidates =
          sensor.kind == SensorKind::kLidar    ? LidarCandidates(sensor, floor)
          : sensor.kind == SensorKind::kCamera ? CameraCandidates(sensor, floor)
                                               : RadarCandidates(sensor);
      std::vector<Candidate> filtered;
      if (sensor.kind == SensorKind::kCamera) {
        // Fill share: the new board's image bounding box within the configured share.
        absl::StatusOr<CameraModel> camera = CameraModel::Create(*sensor.intrinsics);
        if (!camera.ok()) return camera.status();
        const Rigid3d T_camera_station = sensor.T_car_sensor_nominal.Inverse();
        const double area = double(sensor.intrinsics->width) * sensor.intrinsics->height;
        for (const Candidate& c : candidates) {
          Eigen::AlignedBox2d box;
          for (const Eigen::Vector3d& p : PageCorners(c.boards[0])) {
            Eigen::Vector2d uv;
            if (camera->Project(T_camera_station * p, &uv)) box.extend(uv);
          }
          const double share = box.isEmpty() ? 0 : box.volume() / area;
          if (share >= options.min_fill_share && share <= options.max_fill_share)
            filtered.push_back(c);
        }
      } else {
        filtered = candidates;
      }
      absl::StatusOr<std::optional<Candidate>> best =
          BestCandidate(sensor, filtered, existing, placed, plan.layout, floor, options);
      if (!best.ok()) return best.status();
      if (best->has_value()) {
        for (const StationBoard& b : (*best)->boards) {
          plan.layout.boards.push_back(b);
          sensor.targets.push_back(b.id);
        }
        for (const CornerReflector& r : (*best)->reflectors) {
          plan.layout.reflectors.push_back(r);
          sensor.targets.push_back(r.id);
        }
      }
    }
    plan.car.sensors[i].targets = sensor.targets;
    if (!HasSensor(placed, sensor.name)) placed.push_back(sensor);
  }
  absl::StatusOr<std::vector<SensorAssessment>> assessed =
      AssessLayout(plan.car, plan.layout, &floor, options);
  if (!assessed.ok()) return assessed.status();
  plan.sensors = *std::move(assessed);
  if (options.regions) {
    for (const SensorModel& s : plan.car.sensors) {
      for (const std::string& t : s.targets) {
        absl::StatusOr<ValidRegion> r = ValidRegionOf(s, t, plan.layout, &floor, options);
        if (!r.ok()) return r.status();
        plan.regions.push_back(*std::move(r));
      }
    }
  }
  return plan;
}

absl::StatusOr<ValidRegion> ValidRegionOf(const SensorModel& sensor, const std::string& target,
                                          const StationLayout& layout, const FloorLimits* floor,
                                          const PlannerOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  const StationBoard* board = layout.FindBoard(target);
  const CornerReflector* reflector = layout.FindReflector(target);
  if (board == nullptr && reflector == nullptr)
    return absl::NotFoundError(absl::StrCat("no target '", target, "'"));
  const Eigen::Vector3d eye = sensor.T_car_sensor_nominal.translation();
  const Eigen::Vector3d planned =
      board ? board->T_station_board.translation() : reflector->p_station;
  const bool on_floor = board && std::abs(board->T_station_board.RotationMatrix().col(2).z()) > 0.9;
  const Eigen::Vector2d ray = (planned - eye).head<2>();
  const double distance = ray.norm();
  const double azimuth = std::atan2(ray.y(), ray.x());
  const YawPitchRoll planned_ypr =
      board ? YawPitchRollFromRotation(board->T_station_board.RotationMatrix() *
                                       BoardBaseRotation().transpose())
            : YawPitchRoll{};
  // Is the target at (centre, heading offset from facing the sensor) usable?
  const auto works = [&](const Eigen::Vector3d& centre,
                         double heading_offset_rad) -> absl::StatusOr<bool> {
    StationLayout trial = layout;
    if (board) {
      StationBoard& b = *std::find_if(trial.boards.begin(), trial.boards.end(),
                                      [&](const StationBoard& x) { return x.id == target; });
      YawPitchRoll ypr = planned_ypr;
      if (!on_floor) ypr.yaw = FacingYawDeg(centre, eye) * kDeg + heading_offset_rad;
      b.T_station_board = Rigid3d(MountingRotation(ypr, BoardBaseRotation()), centre);
    } else {
      std::find_if(trial.reflectors.begin(), trial.reflectors.end(), [&](const CornerReflector& x) {
        return x.id == target;
      })->p_station = centre;
    }
    absl::StatusOr<SensorAssessment> geo = Assess(sensor, trial, floor, options, false, false);
    if (!geo.ok()) return geo.status();
    if (!geo->calibratable) return false;
    absl::StatusOr<SensorAssessment> a = Assess(sensor, trial, floor, options, true, false);
    if (!a.ok()) return a.status();
    return a->calibratable;
  };
  const auto at = [&](double az, double d, double z) {
    return Eigen::Vector3d(eye.x() + d * std::cos(az), eye.y() + d * std::sin(az), z);
  };
  // The contiguous interval of `step`s around 0 along a parameter where `f` works.
  const auto interval = [&](auto f, double step, int max_steps, double* lo,
                            double* hi) -> absl::Status {
    *lo = *hi = 0;
    for (int dir : {-1, +1}) {
      for (int k = 1; k <= max_steps; ++k) {
        absl::StatusOr<bool> ok = f(dir * k * step);
        if (!ok.ok()) return ok.status();
        if (!*ok) break;
        (dir < 0 ? *lo : *hi) = dir * k * step;
      }
    }
    return absl::OkStatus();
  };
  ValidRegion r;
  r.sensor = sensor.name;
  r.target = target;
  double lo, hi;
  if (auto s = interval([&](double v) { return works(at(azimuth, distance + v, planned.z()), 0); },
                        0.25, 60, &lo, &hi);
      !s.ok()) {
    return s;
  }
  r.distance_min_m = distance + lo;
  r.distance_max_m = distance + hi;
  const Eigen::Vector3d left(-std::sin(azimuth), std::cos(azimuth), 0);
  if (auto s = interval([&](double v) { return works(planned + v * left, 0); }, 0.1, 80, &lo, &hi);
      !s.ok())
    return s;
  r.lateral_min_m = lo;
  r.lateral_max_m = hi;
  if (on_floor) {
    r.height_min_m = r.height_max_m = planned.z();
  } else {
    if (auto s = interval([&](double v) { return works(planned + Eigen::Vector3d(0, 0, v), 0); },
                          0.05, 60, &lo, &hi);
        !s.ok()) {
      return s;
    }
    r.height_min_m = planned.z() + lo;
    r.height_max_m = planned.z() + hi;
  }
  if (board && !on_floor) {
    if (auto s = interval([&](double v) { return works(planned, v * kDeg); }, 2.0, 45, &lo, &hi);
        !s.ok())
      return s;
    r.heading_min_deg = lo;
    r.heading_max_deg = hi;
  }
  // The polygon: per direction within ±45° of the planned one, the contiguous run of
  // working distances around the planned distance (or the first run met going out).
  std::vector<Eigen::Vector2d> near, far;
  for (double off = -45; off <= 45 + 1e-9; off += 5) {
    const double az = azimuth + off * kDeg;
    double first = -1, last = -1;
    for (double d = 0.5; d <= 20.0 + 1e-9; d += 0.5) {
      absl::StatusOr<bool> ok = works(at(az, d, planned.z()), 0);
      if (!ok.ok()) return ok.status();
      if (*ok) {
        if (first < 0) first = d;
        last = d;
      } else if (first >= 0 && (d > distance || std::abs(off) > 1e-9)) {
        break;
      }
    }
    if (first < 0) continue;
    near.push_back(at(az, first - 0.25, 0).head<2>());
    far.push_back(at(az, last + 0.25, 0).head<2>());
  }
  r.polygon = near;
  r.polygon.insert(r.polygon.end(), far.rbegin(), far.rend());
  return r;
}

double SmallestCellPx(const CameraModel& camera, const Rigid3d& T_camera_board,
                      const Board& board) {
  const double cell = SmallestCellM(board);
  double smallest = std::numeric_limits<double>::infinity();
  for (const BoardFeature& f : board.features()) {
    if (f.kind == FeatureKind::kHoleCentre) continue;
    const Eigen::Vector3d p(f.p_board.x(), f.p_board.y(), 0);
    Eigen::Vector2d uv, ux, uy;
    // A feature the lens cannot image has no size (board_outside_fov says so).
    if (!camera.Project(T_camera_board * p, &uv) ||
        !camera.Project(T_camera_board * (p + Eigen::Vector3d(cell, 0, 0)), &ux) ||
        !camera.Project(T_camera_board * (p + Eigen::Vector3d(0, cell, 0)), &uy)) {
      continue;
    }
    smallest = std::min({smallest, (ux - uv).norm(), (uy - uv).norm()});
  }
  return smallest;
}

bool SegmentHitsBoard(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                      const StationBoard& board) {
  return SegmentHitsRectangle(a, b, board.T_station_board, board.board.page_size_m());
}

FloorPolygon BoardFootprint(const StationBoard& board) {
  FloorPolygon corners;
  for (const Eigen::Vector3d& c : PageCorners(board)) corners.push_back(c.head<2>());
  // An upright board projects to a segment: its two ends.
  if ((corners[0] - corners[3]).norm() < 1e-6 && (corners[1] - corners[2]).norm() < 1e-6)
    return {corners[0], corners[1]};
  return corners;
}

int RingsThroughHole(const std::vector<double>& beam_elevations_rad,
                     const Eigen::Vector3d& centre_lidar, const Eigen::Vector3d& normal_lidar,
                     double radius_m) {
  // In-plane axes of the hole.
  Eigen::Vector3d u = normal_lidar.cross(Eigen::Vector3d::UnitZ());
  if (u.norm() < 1e-9) u = Eigen::Vector3d::UnitX();
  u.normalize();
  const Eigen::Vector3d v = normal_lidar.cross(u).normalized();
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (int k = 0; k < 72; ++k) {
    const double phi = 2 * kPi * k / 72;
    const Eigen::Vector3d p = centre_lidar + radius_m * (std::cos(phi) * u + std::sin(phi) * v);
    const double e = std::atan2(p.z(), std::hypot(p.x(), p.y()));
    lo = std::min(lo, e);
    hi = std::max(hi, e);
  }
  std::set<long> rings;  // beams of the same elevation (to 1e-6 rad) are one ring
  for (double e : beam_elevations_rad) {
    if (e > lo && e < hi) rings.insert(std::lround(e * 1e6));
  }
  return static_cast<int>(rings.size());
}

}  // namespace linecal

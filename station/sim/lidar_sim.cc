#include "station/sim/lidar_sim.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <random>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

constexpr double kCentidegToRad = std::numbers::pi / 18000.0;
constexpr int kCentidegPerTurn = 36000;

absl::Status CheckRange(const char* field, double v, double lo, double hi) {
  if (!(v >= lo && v <= hi)) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, " = ", v, ": must be in [", lo, ", ", hi, "]"));
  }
  return absl::OkStatus();
}

// A board prepared for ray casting.
struct BoardTarget {
  const StationBoard* board;
  Rigid3d T_board_station;
  Eigen::Vector3d n_station;  // the printed face's normal
  double d;                   // plane: n · p = d
  bool has_stand = false;
  Eigen::Vector2d stand_xy = Eigen::Vector2d::Zero();  // the post's axis, station x-y
  double stand_top_z = 0;
};

struct SurfaceTarget {
  Rigid3d T_surface_station;
  Eigen::Vector3d n_station;
  double d;
  Eigen::Vector2d half_size;
  double reflectivity;
};

struct Hit {
  double range = std::numeric_limits<double>::infinity();
  double reflectivity = 0;
};

class Scene {
 public:
  Scene(const StationLayout& layout, const LidarSimOptions& o) : layout_(layout), o_(o) {
    for (const StationBoard& b : layout.boards) {
      BoardTarget t{&b, b.T_station_board.Inverse(),
                    b.T_station_board.rotation() * Eigen::Vector3d::UnitZ(), 0};
      t.d = t.n_station.dot(b.T_station_board.translation());
      // Upright boards (normal within 60 degrees of horizontal) stand on a post; boards lying
      // on the floor need none.
      constexpr double kUprightMaxNormalZ = 0.5;
      if (std::abs(t.n_station.z()) < kUprightMaxNormalZ) {
        double lowest = std::numeric_limits<double>::infinity();
        const Eigen::Vector2d half = 0.5 * b.board.page_size_m();
        for (int sx : {-1, 1}) {
          for (int sy : {-1, 1}) {
            lowest = std::min(
                lowest, (b.T_station_board * Eigen::Vector3d(sx * half.x(), sy * half.y(), 0)).z());
          }
        }
        if (lowest > 0) {
          t.has_stand = true;
          // The post stands behind the print, touching the board's back.
          const Eigen::Vector3d axis =
              b.T_station_board.translation() - o.stand_radius_m * t.n_station;
          t.stand_xy = axis.head<2>();
          t.stand_top_z = lowest;
        }
      }
      boards_.push_back(t);
    }
    for (const StationSurface& s : layout.surfaces) {
      SurfaceTarget t{s.T_station_surface.Inverse(),
                      s.T_station_surface.rotation() * Eigen::Vector3d::UnitZ(), 0, 0.5 * s.size_m,
                      s.reflectivity};
      t.d = t.n_station.dot(s.T_station_surface.translation());
      surfaces_.push_back(t);
    }
  }

  Hit Cast(const Eigen::Vector3d& o, const Eigen::Vector3d& dir) const {
    Hit best;
    for (const BoardTarget& b : boards_) {
      const double denom = b.n_station.dot(dir);
      if (std::abs(denom) < 1e-12) continue;  // parallel to the board: no crossing
      const double t = (b.d - b.n_station.dot(o)) / denom;
      if (t <= 0 || t >= best.range) continue;
      const Eigen::Vector3d p_board = b.T_board_station * (o + t * dir);
      const Paint paint = b.board->board.PaintAt(p_board.head<2>());
      if (paint == Paint::kHole || paint == Paint::kOffBoard) continue;
      // denom < 0: the ray meets the printed face.
      best.range = t;
      best.reflectivity =
          denom < 0 ? (paint == Paint::kBlack ? o_.black_reflectivity : o_.white_reflectivity)
                    : o_.board_back_reflectivity;
    }
    for (const BoardTarget& b : boards_) {
      if (!b.has_stand) continue;
      // Ray against the vertical cylinder |xy - stand_xy| = r, 0 <= z <= stand_top_z.
      const Eigen::Vector2d oc = o.head<2>() - b.stand_xy;
      const Eigen::Vector2d dxy = dir.head<2>();
      const double a = dxy.squaredNorm();
      if (a < 1e-12) continue;
      const double bq = oc.dot(dxy);
      const double c = oc.squaredNorm() - o_.stand_radius_m * o_.stand_radius_m;
      const double disc = bq * bq - a * c;
      if (disc < 0) continue;
      const double t = (-bq - std::sqrt(disc)) / a;
      if (t <= 0 || t >= best.range) continue;
      const double z = o.z() + t * dir.z();
      if (z < 0 || z > b.stand_top_z) continue;
      best.range = t;
      best.reflectivity = o_.stand_reflectivity;
    }
    for (const SurfaceTarget& s : surfaces_) {
      const double denom = s.n_station.dot(dir);
      if (std::abs(denom) < 1e-12) continue;
      const double t = (s.d - s.n_station.dot(o)) / denom;
      if (t <= 0 || t >= best.range) continue;
      const Eigen::Vector3d p = s.T_surface_station * (o + t * dir);
      if (std::abs(p.x()) > s.half_size.x() || std::abs(p.y()) > s.half_size.y()) continue;
      best.range = t;
      best.reflectivity = s.reflectivity;
    }
    if (dir.z() < 0) {
      const double t = -o.z() / dir.z();
      if (t > 0 && t < best.range) {
        best.range = t;
        best.reflectivity = layout_.floor_reflectivity;
      }
    }
    return best;
  }

 private:
  const StationLayout& layout_;
  const LidarSimOptions& o_;
  std::vector<BoardTarget> boards_;
  std::vector<SurfaceTarget> surfaces_;
};

// Every rotation's azimuth phase in whole centidegrees within one step: 0 unless
// `free_running`, else uniform from a generator of its own, so that the default draws of the
// range noise (and every existing output) stay as they were.
std::vector<int> RotationPhasesCentideg(int rotations, int step, bool free_running,
                                        std::uint64_t seed) {
  std::vector<int> phases(rotations, 0);
  if (!free_running) return phases;
  constexpr std::uint64_t kPhaseStream = 0x9e3779b97f4a7c15ULL;
  std::mt19937_64 rng(seed ^ kPhaseStream);
  std::uniform_int_distribution<int> phase(0, step - 1);
  for (int& p : phases) p = phase(rng);
  return phases;
}

}  // namespace

absl::Status LidarSimOptions::Validate() const {
  if (rotations < 1 || rotations > 100) {
    return absl::InvalidArgumentError(
        absl::StrCat("rotations = ", rotations, ": must be in [1, 100]"));
  }
  if (auto s = CheckRange("range_sigma_m", range_sigma_m, 0, 1); !s.ok()) return s;
  if (!(dropout_probability >= 0 && dropout_probability < 1)) {
    return absl::InvalidArgumentError(
        absl::StrCat("dropout_probability = ", dropout_probability, ": must be in [0, 1)"));
  }
  if (auto s = CheckRange("min_range_m", min_range_m, 0, 10); !s.ok()) return s;
  if (auto s = CheckRange("max_range_m", max_range_m, min_range_m, 500); !s.ok()) return s;
  for (const auto& [name, v] : {std::pair{"white_reflectivity", white_reflectivity},
                                std::pair{"black_reflectivity", black_reflectivity},
                                std::pair{"board_back_reflectivity", board_back_reflectivity},
                                std::pair{"stand_reflectivity", stand_reflectivity}}) {
    if (auto s = CheckRange(name, v, 0, 1); !s.ok()) return s;
  }
  return CheckRange("stand_radius_m", stand_radius_m, 0.001, 0.5);
}

int SimulatedColumnStepCentideg(LidarModel model) {
  return model == LidarModel::kPandarXt32 ? 18 : 20;
}

absl::StatusOr<LidarSimResult> SimulateLidar(const LidarBeamTable& beams,
                                             const Rigid3d& T_station_lidar,
                                             const StationLayout& layout,
                                             const LidarSimOptions& options,
                                             std::int64_t start_time_ns, std::uint64_t seed) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (absl::Status s = ValidateBeamTable(beams); !s.ok()) return s;
  const LidarModelInfo& info = GetLidarModelInfo(beams.model);
  const int step = SimulatedColumnStepCentideg(beams.model);
  const int columns_per_rotation = kCentidegPerTurn / step;
  const double step_rad = step * kCentidegToRad;
  const int channels = info.channels;

  const int per_packet = ColumnsPerPacket(beams.model, 1);
  const int lead_packets =
      static_cast<int>(std::ceil(kLidarLeadDeg / (step_rad / kCentidegToRad / 100.0) / per_packet));
  const int lead = lead_packets * per_packet;

  LidarSimResult result;
  result.encode.model = beams.model;
  result.encode.return_mode = LidarReturnMode::kStrongest;
  result.encode.first_column_time_ns = start_time_ns - lead * info.column_period_ns;
  // The motor speed these column periods and steps make (VLP-16: 603 rpm, Hesai: 600 rpm).
  constexpr double kNsPerMinute = 60e9;
  result.encode.motor_rpm = static_cast<std::uint16_t>(std::lround(
      kNsPerMinute / (static_cast<double>(columns_per_rotation) * info.column_period_ns)));

  const Scene scene(layout, options);
  std::mt19937_64 rng(seed);
  // Unit normal scaled by sigma: the standard library requires sigma > 0, and 0 is a valid
  // option (noise-free scans).
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const Eigen::Vector3d o = T_station_lidar.translation();
  const Eigen::Matrix3d R = T_station_lidar.RotationMatrix();
  result.scans.resize(options.rotations);
  for (int r = 0; r < options.rotations; ++r) {
    result.scans[r].rotation = r + 1;
    result.scans[r].points.reserve(static_cast<size_t>(columns_per_rotation) * channels);
  }
  const int total_columns = options.rotations * columns_per_rotation + 2 * lead;
  result.columns.resize(total_columns);
  const std::vector<int> phases =
      RotationPhasesCentideg(options.rotations, step, options.free_running, seed);
  for (int k = 0; k < total_columns; ++k) {
    // Column index relative to azimuth 0 of the first rotation, and the column's azimuth in
    // centidegrees (unwrapped) with its rotation's phase.
    const std::int64_t c = k - lead;
    const std::int64_t column_time = start_time_ns + c * info.column_period_ns;
    const auto phase_rotation =
        std::clamp<std::int64_t>(c / columns_per_rotation, 0, options.rotations - 1);
    const std::int64_t c_centideg = c * step + phases[phase_rotation];
    LidarColumn& col = result.columns[k];
    const std::int64_t az_centideg =
        (c_centideg % kCentidegPerTurn + kCentidegPerTurn) % kCentidegPerTurn;
    col.azimuth_centideg = static_cast<std::uint16_t>(az_centideg);
    col.echoes.resize(channels);
    // Unwrapped; the phase added apart keeps the phase-locked azimuths bit for bit.
    const double column_az = static_cast<double>(c) * step_rad +
                             static_cast<double>(phases[phase_rotation]) * kCentidegToRad;
    for (int ch = 0; ch < channels; ++ch) {
      const LidarBeam& beam = beams.beams[ch];
      const double az = BeamAzimuthRad(beam, column_az, step_rad);
      const Eigen::Vector3d dir_lidar = LidarPointFromPolar(1.0, az, beam.elevation_rad);
      const Hit hit = scene.Cast(o, R * dir_lidar);
      if (!std::isfinite(hit.range)) continue;
      if (options.dropout_probability > 0 && uniform(rng) < options.dropout_probability) continue;
      double range = hit.range + options.range_sigma_m * normal(rng);
      if (range < options.min_range_m || range > options.max_range_m) continue;
      // The packet carries whole distance units; the point must be what the decoder sees.
      range = std::round(range / info.distance_unit_m) * info.distance_unit_m;
      constexpr double kReflectivityScale = 255.0;
      const auto intensity =
          static_cast<std::uint8_t>(std::lround(hit.reflectivity * kReflectivityScale));
      col.echoes[ch] = LidarEcho{range, intensity};
      // The rotation the point's own azimuth falls in, decided in centidegrees as the decoders
      // do (a beam exactly at 360 degrees starts the next rotation); lead-in and lead-out points
      // of other rotations go to the packets only.
      const double az_centideg_total = static_cast<double>(c_centideg) +
                                       beam.azimuth_offset_rad / kCentidegToRad +
                                       beam.firing_fraction * step;
      const auto rotation =
          static_cast<std::int64_t>(std::floor(az_centideg_total / kCentidegPerTurn));
      if (rotation < 0 || rotation >= options.rotations) continue;
      const Eigen::Vector3d p = LidarPointFromPolar(range, az, beam.elevation_rad);
      LidarPoint pt;
      pt.x = static_cast<float>(p.x());
      pt.y = static_cast<float>(p.y());
      pt.z = static_cast<float>(p.z());
      pt.intensity = intensity;
      pt.ring = beam.ring;
      pt.time_ns = column_time + ChannelTimeOffsetNs(beams.model, ch);
      result.scans[rotation].points.push_back(pt);
    }
  }
  for (LidarScan& scan : result.scans) {
    scan.stamp_ns = scan.points.empty() ? 0 : scan.points.front().time_ns;
    for (const LidarPoint& p : scan.points) scan.stamp_ns = std::min(scan.stamp_ns, p.time_ns);
  }
  return result;
}

}  // namespace linecal

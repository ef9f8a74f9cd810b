#include "station/model/aligner.h"

#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
// Plausibility bounds (see ReadAligner in the header).
constexpr double kMaxOffsetM = 1.0;
constexpr double kMaxThrustDeg = 10.0;

}  // namespace

Rigid3d AlignerMeasurement::T_station_car() const {
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(thrust_angle_rad, Eigen::Vector3d::UnitZ())),
                 Eigen::Vector3d(longitudinal_offset_m, lateral_offset_m, 0.0));
}

absl::StatusOr<AlignerMeasurement> ReadAligner(const JsonField& parent, const std::string& key) {
  absl::StatusOr<JsonField> f = parent.Object(key);
  if (!f.ok()) return f.status();
  if (auto s = f->AllowOnlyKeys({"longitudinal_offset_m", "lateral_offset_m", "thrust_angle_deg"});
      !s.ok()) {
    return s;
  }
  AlignerMeasurement a;
  for (const auto& [name, slot] : {std::pair{"longitudinal_offset_m", &a.longitudinal_offset_m},
                                   std::pair{"lateral_offset_m", &a.lateral_offset_m}}) {
    absl::StatusOr<double> v = f->Number(name);
    if (!v.ok()) return v.status();
    if (std::abs(*v) > kMaxOffsetM) {
      return f->Error(name, absl::StrCat("must be within +-", kMaxOffsetM, " m, got ", *v));
    }
    *slot = *v;
  }
  absl::StatusOr<double> thrust = f->Number("thrust_angle_deg");
  if (!thrust.ok()) return thrust.status();
  if (std::abs(*thrust) > kMaxThrustDeg) {
    return f->Error("thrust_angle_deg",
                    absl::StrCat("must be within +-", kMaxThrustDeg, " degrees, got ", *thrust));
  }
  a.thrust_angle_rad = *thrust * kDegToRad;
  return a;
}

nlohmann::json AlignerToJson(const AlignerMeasurement& a) {
  return {{"longitudinal_offset_m", a.longitudinal_offset_m},
          {"lateral_offset_m", a.lateral_offset_m},
          {"thrust_angle_deg", a.thrust_angle_rad / kDegToRad}};
}

}  // namespace linecal

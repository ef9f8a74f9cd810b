#include "station/model/pose_json.h"

#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

}  // namespace

Eigen::Matrix3d BoardBaseRotation() {
  Eigen::Matrix3d r;
  // Columns: the board's x, y, z axes in the station frame.
  r << 0, 0, -1,  //
      -1, 0, 0,   //
      0, 1, 0;
  return r;
}

absl::StatusOr<Rigid3d> ReadPose(const JsonField& parent, const std::string& key,
                                 const Eigen::Matrix3d& r_base) {
  absl::StatusOr<JsonField> pose = parent.Object(key);
  if (!pose.ok()) return pose.status();
  if (pose->Has("matrix")) {
    if (auto s = pose->AllowOnlyKeys({"matrix", "xyz_m", "ypr_deg"}); !s.ok()) return s;
    absl::StatusOr<std::vector<double>> m = pose->Numbers("matrix", 16);
    if (!m.ok()) return m.status();
    Eigen::Matrix4d t;
    for (int i = 0; i < 16; ++i) t(i / 4, i % 4) = (*m)[i];
    const Eigen::Matrix3d r = t.topLeftCorner<3, 3>();
    // Hand-typed matrices carry about 7 digits; 1e-6 accepts those and rejects anything that
    // is not a rotation.
    constexpr double kOrthoTolerance = 1e-6;
    if ((r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > kOrthoTolerance ||
        r.determinant() < 0) {
      return pose->Error("matrix", "rotation part is not a rotation (orthonormal, determinant +1)");
    }
    if ((t.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > kOrthoTolerance) {
      return pose->Error("matrix", "last row must be 0 0 0 1");
    }
    return Rigid3d::FromMatrix(t);
  }
  if (auto s = pose->AllowOnlyKeys({"xyz_m", "ypr_deg"}); !s.ok()) return s;
  absl::StatusOr<std::vector<double>> xyz = pose->Numbers("xyz_m", 3);
  if (!xyz.ok()) return xyz.status();
  absl::StatusOr<std::vector<double>> ypr = pose->Numbers("ypr_deg", 3);
  if (!ypr.ok()) return ypr.status();
  for (int i = 0; i < 3; ++i) {
    // Mounting angles beyond a full turn are typing errors, not poses.
    if (std::abs((*ypr)[i]) > 360.0) {
      return pose->Error(absl::StrCat("ypr_deg[", i, "]"),
                         absl::StrCat("must be within +-360, got ", (*ypr)[i]));
    }
  }
  const YawPitchRoll a{(*ypr)[0] * kDegToRad, (*ypr)[1] * kDegToRad, (*ypr)[2] * kDegToRad};
  return Rigid3d(MountingRotation(a, r_base), Eigen::Vector3d((*xyz)[0], (*xyz)[1], (*xyz)[2]));
}

nlohmann::json MatrixToJson(const Eigen::Matrix4d& m) {
  nlohmann::json a = nlohmann::json::array();
  for (int i = 0; i < 16; ++i) a.push_back(m(i / 4, i % 4));
  return a;
}

nlohmann::json PoseToJson(const Rigid3d& pose, const Eigen::Matrix3d& r_base) {
  const YawPitchRoll a = MountingAngles(pose.RotationMatrix(), r_base);
  const Eigen::Vector3d& t = pose.translation();
  return nlohmann::json{{"xyz_m", {t.x(), t.y(), t.z()}},
                        {"ypr_deg", {a.yaw / kDegToRad, a.pitch / kDegToRad, a.roll / kDegToRad}},
                        {"matrix", MatrixToJson(pose.Matrix())}};
}

}  // namespace linecal

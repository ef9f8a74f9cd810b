#include "tools/linecal/calibration_report.h"

#include <cmath>
#include <iterator>
#include <limits>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "station/solvers/seed_formulas.h"

namespace linecal::tools {
namespace {

constexpr double kDegPerRad = 180.0 / std::numbers::pi;
// Ground grid: distances ahead of the camera and the lateral extent, metres.
const double kGridDistancesM[] = {2, 3, 5, 10, 20, 50};
constexpr double kGridHalfWidthM = 5.0;
constexpr int kSamplesPerLine = 200;

cv::Scalar Colour(const RgbColour& c) { return cv::Scalar(c[0], c[1], c[2]); }  // the buffer is RGB

// Draws the connected runs of `points` (NaN breaks a run) as polylines.
void DrawCurve(cv::Mat* mat, const std::vector<Eigen::Vector2d>& points, const RgbColour& colour,
               int thickness) {
  std::vector<cv::Point> run;
  auto flush = [&] {
    if (run.size() >= 2) cv::polylines(*mat, run, false, Colour(colour), thickness, cv::LINE_8);
    run.clear();
  };
  for (const Eigen::Vector2d& p : points) {
    if (!(p.cwiseAbs().maxCoeff() < 1e5)) {
      flush();
      continue;
    }
    run.emplace_back(static_cast<int>(std::lround(p.x())), static_cast<int>(std::lround(p.y())));
  }
  flush();
}

// The distorted image of a camera-frame direction, or NaN when the lens does not see it.
Eigen::Vector2d ImageOf(const CameraModel& camera, const Eigen::Vector3d& d_camera) {
  Eigen::Vector2d uv;
  if (d_camera.z() > 0 && camera.Project(d_camera, &uv)) return uv;
  return Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
}

}  // namespace

RgbImage DrawCalibrationReport(const ImageView8& image, const Capture& capture,
                               const SensorModel& sensor, const SensorCalibration& result) {
  RgbImage img = GreyToRgb(image);
  cv::Mat mat(img.height, img.width, CV_8UC3, img.rgb.data());
  const absl::StatusOr<CameraModel> camera = CameraModel::Create(*sensor.intrinsics);
  if (result.solved && camera.ok()) {
    const Rigid3d T_car_camera = result.mounting.T_car_sensor;
    const Rigid3d T_camera_car = T_car_camera.Inverse();
    const Eigen::Matrix3d R_camera_car = T_camera_car.RotationMatrix();
    // The camera's horizontal view direction and its left, in the car frame.
    const Eigen::Vector3d axis = T_car_camera.RotationMatrix().col(2);
    const Eigen::Vector3d ahead = Eigen::Vector3d(axis.x(), axis.y(), 0).normalized();
    const Eigen::Vector3d left = Eigen::Vector3d::UnitZ().cross(ahead);

    if (result.ground_homography) {
      // Ground points -> undistorted image by the homography -> rays -> the lens.
      const Eigen::Matrix3d K_inv = PinholeMatrix(*sensor.intrinsics).inverse();
      const Eigen::Vector3d c = T_car_camera.translation();
      auto ground_curve = [&](const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
        std::vector<Eigen::Vector2d> points;
        for (int i = 0; i <= kSamplesPerLine; ++i) {
          const Eigen::Vector3d g = from + (to - from) * (static_cast<double>(i) / kSamplesPerLine);
          if ((T_camera_car * g).z() <= 0) {  // behind the camera: the homography would fold it in
            points.push_back(Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN()));
            continue;
          }
          const Eigen::Vector3d pixel =
              *result.ground_homography * Eigen::Vector3d(g.x(), g.y(), 1.0);
          points.push_back(ImageOf(*camera, K_inv * (pixel / pixel.z())));
        }
        DrawCurve(&mat, points, kGroundGridColour, 1);
      };
      const Eigen::Vector3d foot(c.x(), c.y(), 0);
      const double nearest = kGridDistancesM[0],
                   farthest = kGridDistancesM[std::size(kGridDistancesM) - 1];
      for (double d : kGridDistancesM) {
        ground_curve(foot + d * ahead - kGridHalfWidthM * left,
                     foot + d * ahead + kGridHalfWidthM * left);
      }
      for (double y = -kGridHalfWidthM; y <= kGridHalfWidthM; y += 1.0) {
        ground_curve(foot + nearest * ahead + y * left, foot + farthest * ahead + y * left);
      }
    }

    // The horizon: every horizontal direction within 89 deg of the view direction.
    std::vector<Eigen::Vector2d> horizon;
    for (double deg = -89; deg <= 89; deg += 0.25) {
      const double a = deg / kDegPerRad;
      horizon.push_back(
          ImageOf(*camera, R_camera_car * (std::cos(a) * ahead + std::sin(a) * left)));
    }
    DrawCurve(&mat, horizon, kHorizonColour, 2);
    const int along = CarAxisAlong(T_camera_car);
    if (along != 0) {
      const Eigen::Vector2d vp = ImageOf(*camera, R_camera_car.col(0) * along);
      if (vp.cwiseAbs().maxCoeff() < 1e5) {
        cv::circle(
            mat,
            cv::Point(static_cast<int>(std::lround(vp.x())), static_cast<int>(std::lround(vp.y()))),
            kVanishingPointRingPx, Colour(kHorizonColour), 1, cv::LINE_8);
      }
    }

    // Every target board feature where the solved pose puts it.
    const Rigid3d T_camera_station =
        (capture.manifest.aligner.T_station_car() * T_car_camera).Inverse();
    for (const std::string& id : sensor.targets) {
      const StationBoard* board = capture.station.FindBoard(id);
      if (board == nullptr) continue;
      const Rigid3d T_camera_board = T_camera_station * board->T_station_board;
      for (const BoardFeature& f : board->board.features()) {
        const Eigen::Vector2d uv =
            ImageOf(*camera, T_camera_board * Eigen::Vector3d(f.p_board.x(), f.p_board.y(), 0));
        if (!camera->IsInImage(uv)) continue;
        cv::circle(
            mat,
            cv::Point(static_cast<int>(std::lround(uv.x())), static_cast<int>(std::lround(uv.y()))),
            kModelRingPx, Colour(kModelColour), 1, cv::LINE_8);
      }
    }
  }
  for (const BoardObservation& o : result.first_frame_observations)
    DrawFeatures(&img, o.features, kFoundColour);

  // The legend, top left.
  std::vector<std::string> lines;
  lines.push_back(
      absl::StrFormat("%s: %s %s", result.name, VerdictName(result.verdict), result.reason));
  if (result.solved) {
    const MountingEstimate& m = result.mounting;
    lines.push_back(absl::StrFormat(
        "yaw %+.3f pitch %+.3f roll %+.3f deg (deviation %+.3f %+.3f %+.3f)",
        m.angles.yaw * kDegPerRad, m.angles.pitch * kDegPerRad, m.angles.roll * kDegPerRad,
        m.angles_deviation.yaw * kDegPerRad, m.angles_deviation.pitch * kDegPerRad,
        m.angles_deviation.roll * kDegPerRad));
    lines.push_back(result.board_method.valid && result.vanishing_point_px
                        ? absl::StrFormat("board method: vanishing point %.3f px from the pose's",
                                          result.vanishing_point_disagreement_px)
                        : "board method: " + result.board_method.reason);
    lines.push_back(result.vertical_roll.valid
                        ? absl::StrFormat("roll from the vertical board %+.3f deg",
                                          result.vertical_roll.roll_rad * kDegPerRad)
                        : "roll from the vertical board: " + result.vertical_roll.reason);
  }
  lines.push_back("green: detected  magenta: model  cyan: horizon  yellow: ground grid");
  constexpr int kLineHeightPx = 22;
  cv::rectangle(mat, cv::Point(0, 0),
                cv::Point(760, 10 + kLineHeightPx * static_cast<int>(lines.size())),
                cv::Scalar(0, 0, 0), cv::FILLED);
  for (size_t i = 0; i < lines.size(); ++i) {
    cv::putText(mat, lines[i], cv::Point(8, 24 + kLineHeightPx * static_cast<int>(i)),
                cv::FONT_HERSHEY_SIMPLEX, 0.55, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  }
  return img;
}

}  // namespace linecal::tools

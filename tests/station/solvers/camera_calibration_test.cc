// Camera-to-car closed loop on the reference station and car (deploy/): a true mounting
// (nominal + an error), the aligner's offset, the exact projections of every visible board
// feature (the simulator's ground truth) plus noise -> CalibrateCamera -> the mounting is
// recovered within its reported sigma, and the verdict follows the tolerance.
#include "station/solvers/camera_calibration.h"

#include <cmath>
#include <numbers>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "station/model/aligner.h"
#include "station/sim/camera_render.h"

namespace linecal {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";

class CameraCalibrationTest : public ::testing::Test {
 protected:
  void SetUp() override {
    station_ = *ReadStationLayout(kDeploy + "/stations/reference.json");
    car_ = *ReadCarModel(kDeploy + "/cars/reference.json");
    aligner_.longitudinal_offset_m = 0.021;
    aligner_.lateral_offset_m = -0.013;
    aligner_.thrust_angle_rad = 0.12 * kDeg;
  }

  // The sensor's true pose: nominal angles + `error`, nominal position + `offset_m`.
  Rigid3d TrueMounting(const SensorModel& s, const YawPitchRoll& error, const Eigen::Vector3d& offset_m) const {
    const Eigen::Matrix3d r_base = SensorBaseRotation(s.kind);
    const YawPitchRoll n = MountingAngles(s.T_car_sensor_nominal.RotationMatrix(), r_base);
    return Rigid3d(MountingRotation({n.yaw + error.yaw, n.pitch + error.pitch, n.roll + error.roll}, r_base),
                   s.T_car_sensor_nominal.translation() + offset_m);
  }

  // Every visible feature of the sensor's target boards, with Gaussian noise, one frame.
  std::vector<BoardObservation> Observe(const SensorModel& s, const Rigid3d& T_car_camera, double sigma_px,
                                        std::mt19937_64& rng) const {
    const CameraModel camera = *CameraModel::Create(*s.intrinsics);
    const Rigid3d T_station_camera = aligner_.T_station_car() * T_car_camera;
    std::normal_distribution<double> noise(0.0, 1.0);
    std::vector<BoardObservation> out;
    for (const RenderedFeature& f : VisibleCameraFeatures(camera, T_station_camera, station_, {}, 2.0)) {
      if (std::find(s.targets.begin(), s.targets.end(), f.board_id) == s.targets.end()) continue;
      if (out.empty() || out.back().board_id != f.board_id) out.push_back({f.board_id, {}});
      const Board& board = station_.FindBoard(f.board_id)->board;
      DetectedFeature d;
      d.id = f.feature_id;
      d.p_board = board.features()[f.feature_id].p_board;
      const double du = sigma_px * noise(rng);
      const double dv = sigma_px * noise(rng);
      d.uv_px = f.uv_px + Eigen::Vector2d(du, dv);
      out.back().features.push_back(d);
    }
    return out;
  }

  StationLayout station_;
  CarModel car_;
  AlignerMeasurement aligner_;
};

TEST_F(CameraCalibrationTest, FrontCameraIsRecoveredWithinItsSigmaAndPasses) {
  const SensorModel& s = *car_.FindSensor("front_camera");
  const YawPitchRoll error{0.3 * kDeg, -0.4 * kDeg, 0.2 * kDeg};
  const Eigen::Vector3d offset(0.008, -0.006, 0.004);
  const Rigid3d truth = TrueMounting(s, error, offset);
  std::mt19937_64 rng(21);
  std::vector<BoardObservation> obs = Observe(s, truth, 0.2, rng);
  ASSERT_GE(obs.size(), 3u) << "the front camera should see the chessboard, circle and vertical boards";
  // A second frame: the same boards, fresh noise (frames are combined in one problem).
  for (BoardObservation& o : Observe(s, truth, 0.2, rng)) obs.push_back(std::move(o));

  absl::StatusOr<CameraCalibrationResult> r = CalibrateCamera(s, station_, aligner_.T_station_car(), obs);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->verdict, SensorVerdict::kPass) << r->reason << ": " << r->message;
  EXPECT_TRUE(r->reason.empty());
  ASSERT_TRUE(r->solved);
  const MountingEstimate& m = r->mounting;
  const double dev_true[6] = {error.yaw, error.pitch, error.roll, offset.x(), offset.y(), offset.z()};
  const double dev[6] = {m.angles_deviation.yaw, m.angles_deviation.pitch, m.angles_deviation.roll,
                         m.position_deviation_m.x(), m.position_deviation_m.y(), m.position_deviation_m.z()};
  for (int i = 0; i < 6; ++i) {
    EXPECT_GT(m.sigma[i], 0) << i;
    EXPECT_NEAR(dev[i], dev_true[i], 4 * m.sigma[i]) << "component " << i;
  }
  // The acceptance bars with a margin: 0.02 deg and 10 mm at the 95th percentile.
  EXPECT_LT(m.sigma.head<3>().maxCoeff(), 0.01 * kDeg);
  EXPECT_LT(m.sigma.tail<3>().maxCoeff(), 0.005);
  // Residual RMS of 2-D residual lengths with noise 0.2 px per axis: about 0.2 * sqrt(2).
  EXPECT_NEAR(r->residual_rms_px, 0.2 * std::sqrt(2.0), 0.05);
  EXPECT_EQ(r->features_used, static_cast<int>([&] {
              size_t n = 0;
              for (const BoardObservation& o : obs) n += o.features.size();
              return n;
            }()));

  // The vanishing point is the image of +x_car through K (undistorted image): compare with
  // the true extrinsic's, and the ground homography maps the car's ground to it too.
  const CameraIntrinsics& k = *s.intrinsics;
  const Eigen::Vector3d fwd = truth.Inverse().RotationMatrix().col(0);
  const Eigen::Vector2d vp_true(k.fx * fwd.x() / fwd.z() + k.cx, k.fy * fwd.y() / fwd.z() + k.cy);
  ASSERT_TRUE(r->vanishing_point_valid);
  EXPECT_LT((r->vanishing_point_px - vp_true).norm(), 0.3);  // acceptance: 0.3 px
  const Eigen::Vector3d far = r->ground_homography * Eigen::Vector3d(1e7, 0, 1);
  EXPECT_LT((far.hnormalized() - r->vanishing_point_px).norm(), 0.01);
  // Ranging: the flat-ground formula at 5..50 m within 0.5% of the distance.
  ASSERT_EQ(r->ranging.size(), 4u);
  for (const RangingCheck& c : r->ranging) {
    EXPECT_NEAR(c.measured_distance_m, c.true_distance_m, 0.005 * c.true_distance_m) << c.true_distance_m;
  }
}

// Monte Carlo over fresh noise: the reported 1-sigma of yaw, pitch, roll and x, y, z in the
// car frame (propagated from the PnP covariance through the inverse pose and the mounting
// angles) against the spread of 200 solves: within +-20% (acceptance.md).
TEST_F(CameraCalibrationTest, MountingSigmaMatchesTheMonteCarloSpread) {
  const SensorModel& s = *car_.FindSensor("front_camera");
  const YawPitchRoll error{0.3 * kDeg, -0.4 * kDeg, 0.2 * kDeg};
  const Eigen::Vector3d offset(0.008, -0.006, 0.004);
  const Rigid3d truth = TrueMounting(s, error, offset);
  const double dev_true[6] = {error.yaw, error.pitch, error.roll, offset.x(), offset.y(), offset.z()};
  CameraCalibrationOptions options;
  options.pnp.feature_sigma_px = 0.2;  // known noise: the spread is then the covariance's
  std::mt19937_64 rng(99);
  constexpr int kTrials = 200;
  Eigen::Matrix<double, 6, 1> sum_sq = Eigen::Matrix<double, 6, 1>::Zero(), sum_sigma = sum_sq;
  for (int t = 0; t < kTrials; ++t) {
    absl::StatusOr<CameraCalibrationResult> r =
        CalibrateCamera(s, station_, aligner_.T_station_car(), Observe(s, truth, 0.2, rng), options);
    ASSERT_TRUE(r.ok() && r->solved);
    const MountingEstimate& m = r->mounting;
    const double dev[6] = {m.angles_deviation.yaw, m.angles_deviation.pitch, m.angles_deviation.roll,
                           m.position_deviation_m.x(), m.position_deviation_m.y(), m.position_deviation_m.z()};
    for (int i = 0; i < 6; ++i) sum_sq[i] += (dev[i] - dev_true[i]) * (dev[i] - dev_true[i]);
    sum_sigma += m.sigma;
  }
  for (int i = 0; i < 6; ++i) {
    const double spread = std::sqrt(sum_sq[i] / kTrials);
    const double sigma = sum_sigma[i] / kTrials;
    // 200 trials measure a spread to +-5% (1 sigma); the bar is +-20%.
    EXPECT_NEAR(spread / sigma, 1.0, 0.2) << "component " << i << ": spread " << spread << ", sigma " << sigma;
  }
}

TEST_F(CameraCalibrationTest, YawBeyondToleranceFailsWithTheReason) {
  const SensorModel& s = *car_.FindSensor("front_camera");
  const Rigid3d truth = TrueMounting(s, {1.6 * kDeg, 0, 0}, Eigen::Vector3d::Zero());  // tolerance 1 deg
  std::mt19937_64 rng(3);
  absl::StatusOr<CameraCalibrationResult> r =
      CalibrateCamera(s, station_, aligner_.T_station_car(), Observe(s, truth, 0.2, rng));
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->verdict, SensorVerdict::kFail);
  EXPECT_EQ(r->reason, "yaw_out_of_tolerance");
  EXPECT_NE(r->message.find("yaw +1.6"), std::string::npos) << r->message;
  EXPECT_NEAR(r->mounting.angles_deviation.yaw, 1.6 * kDeg, 0.01 * kDeg);
}

TEST_F(CameraCalibrationTest, FisheyeSurroundCameraOnTheFloorGrid) {
  const SensorModel& s = *car_.FindSensor("surround_left");
  const YawPitchRoll error{-0.5 * kDeg, 0.7 * kDeg, 0.4 * kDeg};
  const Rigid3d truth = TrueMounting(s, error, Eigen::Vector3d(0.01, 0.005, -0.01));
  std::mt19937_64 rng(5);
  absl::StatusOr<CameraCalibrationResult> r =
      CalibrateCamera(s, station_, aligner_.T_station_car(), Observe(s, truth, 0.2, rng));
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->verdict, SensorVerdict::kPass) << r->reason << ": " << r->message;
  EXPECT_NEAR(r->mounting.angles_deviation.yaw, error.yaw, 4 * r->mounting.sigma[0]);
  EXPECT_NEAR(r->mounting.angles_deviation.pitch, error.pitch, 4 * r->mounting.sigma[1]);
  EXPECT_NEAR(r->mounting.angles_deviation.roll, error.roll, 4 * r->mounting.sigma[2]);
}

TEST_F(CameraCalibrationTest, ErrorsAndUntrustworthyInputs) {
  const SensorModel& s = *car_.FindSensor("front_camera");
  const Rigid3d truth = TrueMounting(s, {}, Eigen::Vector3d::Zero());
  std::mt19937_64 rng(8);
  std::vector<BoardObservation> obs = Observe(s, truth, 0.2, rng);

  // Nothing found.
  std::vector<BoardObservation> none = {{"front_chessboard", {}}};
  absl::StatusOr<CameraCalibrationResult> r = CalibrateCamera(s, station_, aligner_.T_station_car(), none);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->verdict, SensorVerdict::kError);
  EXPECT_EQ(r->reason, "board_not_found");

  // Too few features.
  std::vector<BoardObservation> few = {{obs[0].board_id, {obs[0].features.begin(), obs[0].features.begin() + 5}}};
  EXPECT_EQ(CalibrateCamera(s, station_, aligner_.T_station_car(), few)->reason, "too_few_features");

  // A board the station does not have.
  std::vector<BoardObservation> unknown = {{"no_such_board", obs[0].features}};
  const absl::Status bad = CalibrateCamera(s, station_, aligner_.T_station_car(), unknown).status();
  EXPECT_EQ(bad.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(bad.message().find("no_such_board"), std::string::npos);

  // The features of one board attributed to another (mis-identified board): no consistent
  // pose, so the residual test refuses it.
  std::vector<BoardObservation> swapped = obs;
  ASSERT_GE(swapped.size(), 2u);
  std::swap(swapped[0].board_id, swapped[1].board_id);
  absl::StatusOr<CameraCalibrationResult> wrong = CalibrateCamera(s, station_, aligner_.T_station_car(), swapped);
  ASSERT_TRUE(wrong.ok());
  EXPECT_EQ(wrong->verdict, SensorVerdict::kError);
  EXPECT_TRUE(wrong->reason == "residual_too_high" || wrong->reason == "board_seen_from_behind" ||
              wrong->reason == "did_not_converge")
      << wrong->reason;

  // A noisy detector (5 px) makes the pose too uncertain to judge.
  std::mt19937_64 rng2(9);
  CameraCalibrationOptions loose;
  loose.max_residual_rms_px = 100;
  absl::StatusOr<CameraCalibrationResult> noisy =
      CalibrateCamera(s, station_, aligner_.T_station_car(), Observe(s, truth, 5.0, rng2), loose);
  ASSERT_TRUE(noisy.ok());
  EXPECT_EQ(noisy->reason, "uncertainty_too_high") << noisy->message;

  CameraCalibrationOptions invalid;
  invalid.min_features = 2;
  EXPECT_NE(CalibrateCamera(s, station_, aligner_.T_station_car(), obs, invalid).status().message().find("min_features"),
            std::string::npos);
  EXPECT_EQ(CalibrateCamera(*car_.FindSensor("front_radar"), station_, aligner_.T_station_car(), obs).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace linecal

// Closed-loop tests of the round-hole board detector in point clouds: the station simulator
// scans a round-hole board with the reference car's VLP-16 and Pandar64 beam patterns at 3-8 m
// and several headings, with range noise 1-3 cm, and the detector must recover the five hole
// centres and the normal within docs/acceptance.md's bars from ten rotations; it must give the
// right reason for a board outside the region, an empty or cluttered region, a board too far
// for its rings to cross the holes, and bad input.
#include "detectors/round_hole/round_hole_cloud.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "tests/detectors/round_hole/round_hole_scene.h"

namespace linecal {
namespace {

// The expected pose: the truth off by the station's mounting tolerance (3 cm, 0.5 degree).
Rigid3d Prior(const Rigid3d& truth, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::Vector3d axis = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
  const Eigen::Vector3d shift = 0.03 * Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.5 * kDegToRad, axis)), shift) * truth;
}

RoundHoleCloudDetection Detect(const Scene& scene, const Rigid3d& prior,
                               double* ms_per_frame = nullptr) {
  return TimedPerFrame(scene, ms_per_frame, [&](auto views) {
    return DetectRoundHoleBoardInCloud(scene.board, views, prior);
  });
}

TEST(RoundHoleCloudTest, HoleCentresAndNormalWithinTheBars) {
  // Bars: docs/acceptance.md "Detectors (point clouds)".
  constexpr double kNormalBarRad = 0.1 * kDegToRad;
  const Case cases[] = {
      {"roof_lidar", 3.0, 0.0, 0.0, 0.01, 0.01},
      {"roof_lidar", 3.0, 40.0, 30.0, 0.03, 0.01},
      {"roof_lidar", 5.0, 20.0, 25.0, 0.02, 0.01},
      {"roof_lidar", 5.0, -60.0, -10.0, 0.03, 0.01},
      {"roof_lidar", 8.0, -30.0, -35.0, 0.03, 0.01},
      {"roof_lidar", 8.0, 15.0, 15.0, 0.01, 0.01},
      {"bumper_lidar", 3.0, 10.0, 30.0, 0.03, 0.02},
      {"bumper_lidar", 3.0, -20.0, 0.0, 0.01, 0.02},
      {"bumper_lidar", 5.0, -15.0, -20.0, 0.01, 0.02},
      {"bumper_lidar", 5.0, 30.0, 20.0, 0.02, 0.02},
      {"bumper_lidar", 8.0, 0.0, 10.0, 0.02, 0.02},
      {"bumper_lidar", 8.0, -40.0, -25.0, 0.01, 0.02},
  };
  for (const Case& c : cases) {
    const Scene scene =
        Simulate(Beams(c.sensor), c.distance_m, c.bearing_deg, c.heading_deg, c.sigma_m, 10);
    double ms = 0.0;
    const RoundHoleCloudDetection d = Detect(scene, Prior(scene.T_lidar_board, 3), &ms);
    const std::string what = std::string(c.sensor) + " at " + std::to_string(c.distance_m) +
                             " m, heading " + std::to_string(c.heading_deg) + ", sigma " +
                             std::to_string(c.sigma_m);
    ASSERT_TRUE(d.found) << what << ": " << RoundHoleCloudReasonName(d.reason);
    ASSERT_EQ(d.holes.size(), 5u);
    const double worst = WorstHoleError(scene, d);
    const double normal_error = std::acos(std::clamp(
        d.T_lidar_board.RotationMatrix().col(2).dot(scene.T_lidar_board.RotationMatrix().col(2)),
        -1.0, 1.0));
    // The normal's bar holds only where the points can carry it: its 1-sigma (the range
    // noise over the points' spread and number, about 0.06 degree for a VLP-16 at 3 m and
    // 3 cm, 0.1-0.2 degree at 8 m) must be a third of the bar. Elsewhere the error must agree
    // with the reported sigma (within 4 sigma), and the case is printed as beyond the bar.
    const bool bar_reachable = 3.0 * d.normal_sigma_rad <= kNormalBarRad;
    std::printf(
        "%-12s %3.0f m heading %4.0f sigma %2.0f cm: worst hole %4.1f mm, "
        "normal %.3f deg (1-sigma %.3f)%s, %2d rings through holes, %5.2f ms/frame\n",
        c.sensor, c.distance_m, c.heading_deg, 100 * c.sigma_m, 1e3 * worst,
        normal_error / kDegToRad, d.normal_sigma_rad / kDegToRad,
        bar_reachable ? "" : " [bar beyond the data]", d.rings_through_holes, ms);
    EXPECT_LT(worst, c.bar_m) << what;
    EXPECT_LT(normal_error, bar_reachable ? kNormalBarRad : 4.0 * d.normal_sigma_rad) << what;
  }
}

// A post between the LiDAR and the board (another board's stand, as on the reference
// station for the bumper LiDAR) hides a strip of the board in every ring, next to a hole: its
// gap must not be taken for the hole's. VLP-16, board 0.5 m above it at 4.2 m.
TEST(RoundHoleCloudTest, AnOccludingPostIsNotAHole) {
  for (double post_x : {-0.2, -0.12, 0.1}) {
    StationLayout layout;
    layout.name = "occluded";
    layout.boards.push_back(RoundHoleAt(FacingPose(4.2, 0.0, 10.0, 0.5)));
    // A 6 cm post standing 1.5 m in front of the board, post_x to its side (station -y is
    // the board's +x for a board facing the LiDAR along +x).
    StationSurface post;
    post.id = "post";
    Eigen::Matrix3d R;
    R << 0, 0, -1, -1, 0, 0, 0, 1, 0;  // x along -y, y up, z towards the LiDAR (-x)
    post.T_station_surface = Rigid3d(R, Eigen::Vector3d(2.7, -post_x * 2.7 / 4.2, 1.0));
    post.size_m = Eigen::Vector2d(0.06, 2.0);
    layout.surfaces.push_back(post);
    const Scene scene = SimulateLayout(Beams("bumper_lidar"), layout, 0.02, 10);
    const RoundHoleCloudDetection d = Detect(scene, Prior(scene.T_lidar_board, 5));
    ASSERT_TRUE(d.found) << post_x << ": " << RoundHoleCloudReasonName(d.reason);
    const double worst = WorstHoleError(scene, d);
    const Rigid3d delta = d.T_lidar_board.Inverse() * scene.T_lidar_board;
    std::printf("post at board x %.2f: worst hole %.1f mm, board y error %.1f mm (1-sigma %.1f)\n",
                post_x, 1e3 * worst, 1e3 * delta.translation().y(),
                1e3 * std::sqrt(d.pose_covariance(4, 4)));
    EXPECT_LT(worst, 0.02) << post_x;  // docs/acceptance.md, 16 rings
    EXPECT_LT(std::abs(delta.translation().y()), 4.0 * std::sqrt(d.pose_covariance(4, 4)))
        << post_x;
  }
}

// A panel in front of the board whose edge, seen from the LiDAR, lies one to two azimuth steps
// beyond the board's +x side: whether each ring's end shows an occluder return within reach
// depends on where that rotation's azimuth grid falls, and judging a rotation's end edges by
// its own returns kept only those whose last point fell far from the side. The board's x then
// came out 0.22 sigma inside on average (standard error 0.05; 400 boards, VLP-16 at 4 m, three
// free-running rotations each); judged by the other rotations it is 0.10, without the panel
// -0.01.
TEST(RoundHoleCloudTest, AnOccluderBesideTheSideLeavesItsEdgesUnbiased) {
  const LidarBeamTable beams = Beams("bumper_lidar");
  constexpr double kDistanceM = 4.0;
  constexpr double kPanelM = 2.5;  // the panel's distance from the LiDAR
  const double step_m = kDistanceM * SimulatedColumnStepCentideg(beams.model) * 0.01 * kDegToRad;
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<double> gap_steps(1.0, 2.0);
  std::vector<double> z;
  for (int run = 0; run < 400; ++run) {
    StationLayout layout;
    layout.name = "beside_the_side";
    layout.boards.push_back(RoundHoleAt(FacingPose(kDistanceM, 0.0, 0.0, 0.3)));
    // The board's +x side is at station y = -half_page.x; the panel's edge at the gap beyond
    // it, scaled to the panel's distance along the rays.
    const double half_x = 0.5 * layout.boards[0].board.page_size_m().x();
    const double edge_y = -(half_x + gap_steps(rng) * step_m) * kPanelM / kDistanceM;
    layout.surfaces.push_back(Panel("panel", Eigen::Vector3d(kPanelM, edge_y - 0.25, kHeightM),
                                    std::numbers::pi, Eigen::Vector2d(0.5, 3.0)));
    const Scene scene = SimulateLayout(beams, layout, 0.02, 3, 700 + run, true);
    const RoundHoleCloudDetection d = Detect(scene, Prior(scene.T_lidar_board, run));
    ASSERT_TRUE(d.found) << run << ": " << RoundHoleCloudReasonName(d.reason);
    const Rigid3d delta = d.T_lidar_board.Inverse() * scene.T_lidar_board;
    z.push_back(delta.translation().x() / std::sqrt(d.pose_covariance(3, 3)));
  }
  double mean = 0.0;
  for (double v : z) mean += v / z.size();
  double var = 0.0;
  for (double v : z) var += (v - mean) * (v - mean) / (z.size() - 1);
  const double standard_error = std::sqrt(var / z.size());
  std::printf("panel beside the +x side: mean x error / sigma %+.2f (standard error %.2f)\n", mean,
              standard_error);
  EXPECT_LT(std::abs(mean), 3.0 * standard_error);
}

TEST(RoundHoleCloudTest, BoardOutsideTheRegion) {
  const Scene scene = Simulate(Beams("bumper_lidar"), 5.0, 0.0, 0.0, 0.02, 1);
  // Expected 3 m to the side of where it is.
  const Rigid3d prior = Rigid3d::Translation(Eigen::Vector3d(3.0, 0.0, 0.0)) * scene.T_lidar_board;
  const RoundHoleCloudDetection d = Detect(scene, prior);
  EXPECT_FALSE(d.found);
  EXPECT_EQ(d.reason, RoundHoleCloudReason::kBoardNotInRoi);
}

TEST(RoundHoleCloudTest, NoPlaneInAnEmptyOrClutteredRegion) {
  Scene scene = Simulate(Beams("roof_lidar"), 5.0, 0.0, 0.0, 0.02, 1);
  // Clutter: points scattered through the whole region's volume, on every ring, instead of the
  // board.
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<RoundHoleCloudPoint> clutter;
  for (int i = 0; i < 3000; ++i) {
    const Eigen::Vector3d p =
        scene.T_lidar_board * Eigen::Vector3d(0.8 * u(rng), 0.8 * u(rng), 0.3 * u(rng));
    clutter.push_back({static_cast<float>(p.x()), static_cast<float>(p.y()),
                       static_cast<float>(p.z()), static_cast<std::uint16_t>(i % 64)});
  }
  const Board board = scene.board;
  const Rigid3d truth = scene.T_lidar_board;
  scene.frames = {clutter};
  RoundHoleCloudDetection d = Detect(scene, truth);
  EXPECT_FALSE(d.found);
  EXPECT_EQ(d.reason, RoundHoleCloudReason::kNoPlane);
  // A plane, but turned 30 degrees from the expected one (beyond max_tilt_rad).
  const Scene turned = Simulate(Beams("roof_lidar"), 5.0, 0.0, 30.0, 0.02, 1);
  const Scene facing = Simulate(Beams("roof_lidar"), 5.0, 0.0, 0.0, 0.02, 1);
  d = Detect(turned, facing.T_lidar_board);
  EXPECT_FALSE(d.found);
  EXPECT_EQ(d.reason, RoundHoleCloudReason::kNoPlane);
}

TEST(RoundHoleCloudTest, TooFewRingsThroughHolesWhenFar) {
  // At 25 m the VLP-16's rings at +-1 degree pass 0.44 m above and below the centre: both
  // on the page (0.55 m), both clear of the holes (which end at 0.42 m).
  const Scene scene = Simulate(Beams("bumper_lidar"), 25.0, 0.0, 0.0, 0.01, 2);
  const RoundHoleCloudDetection d = Detect(scene, scene.T_lidar_board);
  EXPECT_FALSE(d.found);
  EXPECT_EQ(d.reason, RoundHoleCloudReason::kTooFewRingsThroughHoles)
      << RoundHoleCloudReasonName(d.reason);
  // A quarter-size board (0.275 m) at 8 m, under the 0.28 m between rings: one ring at most.
  const Scene small = Simulate(Beams("bumper_lidar"), 8.0, 0.0, 0.0, 0.01, 10, 0.25);
  const RoundHoleCloudDetection s = Detect(small, small.T_lidar_board);
  EXPECT_FALSE(s.found);
  EXPECT_EQ(s.reason, RoundHoleCloudReason::kTooFewRingsThroughHoles)
      << RoundHoleCloudReasonName(s.reason);
}

TEST(RoundHoleCloudTest, BadInputGivesAReason) {
  const Scene scene = Simulate(Beams("roof_lidar"), 5.0, 0.0, 0.0, 0.02, 1);
  // No frames, and an empty frame.
  EXPECT_EQ(DetectRoundHoleBoardInCloud(scene.board, {}, scene.T_lidar_board).reason,
            RoundHoleCloudReason::kBoardNotInRoi);
  const std::vector<RoundHoleCloudPoint> empty;
  const std::span<const RoundHoleCloudPoint> empty_view(empty);
  EXPECT_EQ(DetectRoundHoleBoardInCloud(scene.board, {&empty_view, 1}, scene.T_lidar_board).reason,
            RoundHoleCloudReason::kBoardNotInRoi);
  // NaN points are skipped: all NaN is an empty region; NaN among the points changes nothing.
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::vector<RoundHoleCloudPoint> nans(1000, RoundHoleCloudPoint{nan, nan, nan, 3});
  const std::span<const RoundHoleCloudPoint> nan_view(nans);
  EXPECT_EQ(DetectRoundHoleBoardInCloud(scene.board, {&nan_view, 1}, scene.T_lidar_board).reason,
            RoundHoleCloudReason::kBoardNotInRoi);
  Scene mixed = scene;
  mixed.frames[0].insert(mixed.frames[0].begin() + mixed.frames[0].size() / 2, nans.begin(),
                         nans.end());
  EXPECT_TRUE(Detect(mixed, scene.T_lidar_board).found);
  // Another board type, a NaN prior, invalid options.
  const Board aruco = *Board::Create({.type = BoardType::kAruco});
  std::vector<std::span<const RoundHoleCloudPoint>> views(scene.frames.begin(), scene.frames.end());
  EXPECT_EQ(DetectRoundHoleBoardInCloud(aruco, views, scene.T_lidar_board).reason,
            RoundHoleCloudReason::kBadInput);
  const Rigid3d nan_prior = Rigid3d::Translation(Eigen::Vector3d(nan, 0, 0));
  EXPECT_EQ(DetectRoundHoleBoardInCloud(scene.board, views, nan_prior).reason,
            RoundHoleCloudReason::kBadInput);
  RoundHoleCloudOptions bad;
  bad.roi_margin_m = -1;
  EXPECT_FALSE(bad.Valid());
  EXPECT_EQ(DetectRoundHoleBoardInCloud(scene.board, views, scene.T_lidar_board, bad).reason,
            RoundHoleCloudReason::kBadInput);
  EXPECT_STREQ(RoundHoleCloudReasonName(RoundHoleCloudReason::kTooFewRingsThroughHoles),
               "too_few_rings_through_holes");
}

}  // namespace
}  // namespace linecal

namespace linecal {
namespace {

// Monte Carlo of the reported pose covariance (reduced; `linecal eval lidar` runs the
// LiDAR-to-car version over many cars): boards at random positions around 5.5 m (VLP-16) or
// 6 m (Pandar64), headings within 25 degrees, sigma 2 cm, 2 rotations. Per pose component
// the RMS of error / reported 1-sigma should be 1 (docs/acceptance.md: within +-20%). With 40
// runs one component's RMS scatters by about 11% (1-sigma), so position and tilt components
// are held to 0.75..1.25 and the six pooled (240 values, 4.6%) to 0.8..1.2. The in-plane
// rotation theta_z was held to 0.6..1.5 while it missed the bar (over 150 runs 1.31, then 1.18,
// for the VLP-16, 0.73, then 0.86, for the Pandar64); since the profile variance counts
// phase-locked rotations once, the VLP-16's is 1.06 over 150 runs (1.03 over 1,000), and it is
// held to the same bar as the others (docs/lidar-radar.md "The detector's covariance").
TEST(RoundHoleCloudTest, ReportedCovarianceMatchesTheMonteCarloSpread) {
  // LINECAL_ROUND_HOLE_MC_RUNS=150 gives docs/lidar-radar.md's figures (the same boards first).
  const char* runs_env = std::getenv("LINECAL_ROUND_HOLE_MC_RUNS");
  const int kRuns = runs_env != nullptr ? std::max(1, std::atoi(runs_env)) : 40;
  for (const char* sensor : {"bumper_lidar", "roof_lidar"}) {
    const LidarBeamTable beams = Beams(sensor);
    std::mt19937_64 rng(17);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    Eigen::Matrix<double, 6, 1> sum_z2 = Eigen::Matrix<double, 6, 1>::Zero();
    int runs = 0;
    for (int run = 0; run < kRuns; ++run) {
      const double distance = (std::string(sensor) == "bumper_lidar" ? 5.5 : 6.0) + 1.0 * u(rng);
      StationLayout layout;
      layout.name = "mc";
      layout.boards.push_back(
          RoundHoleAt(FacingPose(distance, 30.0 * u(rng), 25.0 * u(rng), 0.15 * u(rng))));
      const Scene scene = SimulateLayout(beams, layout, 0.02, 2, 100 + run);
      const RoundHoleCloudDetection d = Detect(scene, Prior(scene.T_lidar_board, run));
      ASSERT_TRUE(d.found) << sensor << " run " << run << ": "
                           << RoundHoleCloudReasonName(d.reason);
      // The error in the board frame: T_true = T_est * (R(theta), t).
      const Rigid3d delta = d.T_lidar_board.Inverse() * scene.T_lidar_board;
      const Eigen::AngleAxisd aa(delta.RotationMatrix());
      Eigen::Matrix<double, 6, 1> e;
      e << aa.angle() * aa.axis(), delta.translation();
      for (int k = 0; k < 6; ++k) sum_z2(k) += e(k) * e(k) / d.pose_covariance(k, k);
      ++runs;
    }
    const Eigen::Matrix<double, 6, 1> ratio = (sum_z2 / runs).cwiseSqrt();
    const double pooled = std::sqrt(sum_z2.sum() / (6.0 * runs));
    std::printf(
        "%-12s error / sigma over %d runs: theta_x %.2f theta_y %.2f theta_z %.2f "
        "t_x %.2f t_y %.2f t_z %.2f, pooled %.2f\n",
        sensor, runs, ratio(0), ratio(1), ratio(2), ratio(3), ratio(4), ratio(5), pooled);
    for (int k = 0; k < 6; ++k) {
      EXPECT_GT(ratio(k), 0.75) << sensor << " component " << k;
      EXPECT_LT(ratio(k), 1.25) << sensor << " component " << k;
    }
    EXPECT_GT(pooled, 0.8) << sensor;
    EXPECT_LT(pooled, 1.2) << sensor;
  }
}

// Rotations that fired at the same azimuths repeat one rotation's quantisation errors: the same
// rotation twice says no more about the board's in-plane pose than once. The profile variance
// of a board resting on four rings or fewer took every edge as an independent error and halved
// (VLP-16 theta_z error / sigma 1.15 over 1,000 boards of two phase-locked rotations, 1.02 of
// one; docs/lidar-radar.md "The detector's covariance"). The plane's fit does take the doubled
// points at their word (its covariance halves, and with it its share of the in-plane one).
TEST(RoundHoleCloudTest, ARepeatedRotationAddsNoInPlaneInformation) {
  const LidarBeamTable beams = Beams("bumper_lidar");
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int profiled = 0;
  for (int run = 0; run < 12; ++run) {
    const double distance = 5.5 + u(rng), lift = 0.15 * u(rng), heading = 25.0 * u(rng);
    StationLayout layout;
    layout.name = "repeated";
    layout.boards.push_back(RoundHoleAt(FacingPose(distance, 30.0 * u(rng), heading, lift)));
    Scene scene = SimulateLayout(beams, layout, 0.02, 1, 100 + run);
    const RoundHoleCloudDetection once = Detect(scene, Prior(scene.T_lidar_board, run));
    scene.frames.push_back(scene.frames.front());
    const RoundHoleCloudDetection twice = Detect(scene, Prior(scene.T_lidar_board, run));
    ASSERT_TRUE(once.found && twice.found) << run;
    profiled += once.rings_through_holes <= 4 ? 1 : 0;
    for (int k : {2, 4}) {  // theta_z, t_y: the components the profiles widen
      const double ratio = twice.pose_covariance(k, k) / once.pose_covariance(k, k);
      std::printf("run %2d, %d rings through holes: component %d variance twice / once %.3f\n", run,
                  once.rings_through_holes, k, ratio);
      EXPECT_GT(ratio, 0.8) << "run " << run << " component " << k;
      EXPECT_LT(ratio, 1.05) << "run " << run << " component " << k;
    }
  }
  EXPECT_GE(profiled, 6);  // the case at stake: boards the profiles widen
}

// The stand's post, seen behind the page's lower edge by a ring that also clips the page's
// lower corner, continues that ring's run of points with edges the model does not explain,
// the same in every rotation: their pull on the board's y does not average down over a
// free-running motor's rotations as the quantisation does. Their excess summed per rotation
// (and scaled by the rotations' correlation, about 1 / N here) gave RMS t_y error / sigma 2.9
// over these six scans of 10 rotations; summed per crossing across rotations, 1.5.
TEST(RoundHoleCloudTest, TheStandsPullRepeatsInEveryRotation) {
  const LidarBeamTable beams = Beams("bumper_lidar");
  StationLayout layout;
  layout.name = "post";
  layout.boards.push_back(RoundHoleAt(FacingPose(2.887, 18.77, -24.38, 0.099)));
  double sum_z2 = 0.0;
  constexpr int kScans = 6;
  for (int scan = 0; scan < kScans; ++scan) {
    const Scene scene = SimulateLayout(beams, layout, 0.02, 10, 125 + 100000 * scan, true);
    const RoundHoleCloudDetection d = Detect(scene, Prior(scene.T_lidar_board, 25));
    ASSERT_TRUE(d.found) << scan;
    const double ty = (d.T_lidar_board.Inverse() * scene.T_lidar_board).translation().y();
    const double sigma = std::sqrt(d.pose_covariance(4, 4));
    std::printf("scan %d: t_y error %.2f mm, 1-sigma %.2f mm\n", scan, 1e3 * ty, 1e3 * sigma);
    sum_z2 += ty * ty / (sigma * sigma);
  }
  const double rms = std::sqrt(sum_z2 / kScans);
  std::printf("t_y RMS error / sigma %.2f\n", rms);
  EXPECT_LT(rms, 2.0);
}

// A free-running motor: every rotation fires at its own azimuth phase, so the frames'
// quantisation errors are (nearly) independent and average down. The covariance must say so:
// it correlates every pair of edges across frames through the frames' phase difference
// (QuantisationB). Clustering phases within 0.05 of a step counted the simulator's 20 distinct
// phases (a centidegree apart) as repeats and the in-plane sigma came out too large: RMS
// error / sigma of t_x, t_y, theta_z pooled was 0.66 (VLP-16) and 0.83 (Pandar64) here; 0.98
// and 1.12 with same-frame pairs scaled by the phases' correlation; 0.98 and 1.08 with all
// pairs; 0.93 and 1.06 now that the edges' excess repeats across rotations (ExcessB).
TEST(RoundHoleCloudTest, CovarianceOfAFreeRunningMotor) {
  struct Run {
    const char* sensor;
    int boards;
    int rotations;
  };
  for (const Run& r : {Run{"bumper_lidar", 20, 20}, Run{"roof_lidar", 12, 6}}) {
    const LidarBeamTable beams = Beams(r.sensor);
    std::mt19937_64 rng(29);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    double sum_z2 = 0.0;
    int terms = 0;
    for (int run = 0; run < r.boards; ++run) {
      const double distance = (std::string(r.sensor) == "bumper_lidar" ? 4.0 : 6.0) + u(rng);
      StationLayout layout;
      layout.name = "free_running";
      layout.boards.push_back(
          RoundHoleAt(FacingPose(distance, 30.0 * u(rng), 25.0 * u(rng), 0.15 * u(rng))));
      const Scene scene = SimulateLayout(beams, layout, 0.02, r.rotations, 500 + run, true);
      const RoundHoleCloudDetection d = Detect(scene, Prior(scene.T_lidar_board, run));
      ASSERT_TRUE(d.found) << r.sensor << " run " << run << ": "
                           << RoundHoleCloudReasonName(d.reason);
      const Rigid3d delta = d.T_lidar_board.Inverse() * scene.T_lidar_board;
      const Eigen::AngleAxisd aa(delta.RotationMatrix());
      Eigen::Matrix<double, 6, 1> e;
      e << aa.angle() * aa.axis(), delta.translation();
      for (int k : {2, 3, 4}) {  // theta_z, t_x, t_y: the in-plane fit's quantisation
        sum_z2 += e(k) * e(k) / d.pose_covariance(k, k);
        ++terms;
      }
    }
    const double ratio = std::sqrt(sum_z2 / terms);
    std::printf("%-12s free-running, %d boards x %d rotations: in-plane error / sigma %.2f\n",
                r.sensor, r.boards, r.rotations, ratio);
    EXPECT_GT(ratio, 0.8) << r.sensor;
    EXPECT_LT(ratio, 1.25) << r.sensor;
  }
}

}  // namespace
}  // namespace linecal

// Boards seen by the surround fisheye cameras, found in their perspective views: rendered by
// the simulator (exact ground truth), detected in the view, mapped back to raw pixels.
#include "station/camera/board_view.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <string>

#include "detectors/detect.h"
#include "station/capture/capture.h"
#include "station/io/image_io.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/sim/simulator.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

struct Truth {
  std::map<std::pair<std::string, int>, Eigen::Vector2d> uv;  // (board, feature id) -> pixel
};

class BoardViewScene : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new std::string(
        (fs::temp_directory_path() / ("board_view_test_" + std::to_string(getpid()))).string());
    auto station =
        ReadStationLayout(std::string(LINECAL_SOURCE_DIR) + "/deploy/stations/reference.json");
    auto car = ReadCarModel(std::string(LINECAL_SOURCE_DIR) + "/deploy/cars/reference.json");
    ASSERT_TRUE(station.ok() && car.ok());
    SimulatorOptions o;
    o.sensors = {"surround_front", "surround_rear", "surround_left", "surround_right"};
    auto sim = SimulateCapture(*station, *car, o, 3, *dir_);
    ASSERT_TRUE(sim.ok()) << sim.status();
    summary_ = new SimulationSummary(*std::move(sim));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
    delete summary_;
  }

  static Truth TruthOf(const std::string& sensor) {
    Truth t;
    for (const auto& s : summary_->ground_truth["sensors"]) {
      if (s["name"] != sensor) continue;
      for (const auto& f : s["frames"][0]["features"])
        t.uv[{f["board"].get<std::string>(), f["id"].get<int>()}] =
            Eigen::Vector2d(f["u"].get<double>(), f["v"].get<double>());
    }
    return t;
  }

  static std::string* dir_;
  static SimulationSummary* summary_;
};
std::string* BoardViewScene::dir_ = nullptr;
SimulationSummary* BoardViewScene::summary_ = nullptr;

double RmsError(const Detection& d, const Truth& truth, const std::string& board) {
  double sum2 = 0;
  for (const DetectedFeature& f : d.features) {
    auto it = truth.uv.find({board, f.id});
    if (it == truth.uv.end()) {
      ADD_FAILURE() << board << " feature " << f.id << " is not in the ground truth";
      return 1e9;
    }
    sum2 += (f.uv_px - it->second).squaredNorm();
  }
  return std::sqrt(sum2 / d.features.size());
}

TEST_F(BoardViewScene, SurroundBoardsFoundInTheirViewsAtTheTruePixels) {
  absl::StatusOr<Capture> capture = ReadCapture(*dir_);
  ASSERT_TRUE(capture.ok()) << capture.status();
  for (const CaptureSensor& recorded : capture->manifest.sensors) {
    SCOPED_TRACE(recorded.name);
    const SensorModel* sensor = capture->car.FindSensor(recorded.name);
    ASSERT_NE(sensor, nullptr);
    absl::StatusOr<CameraModel> camera = CameraModel::Create(*sensor->intrinsics);
    ASSERT_TRUE(camera.ok());
    absl::StatusOr<Image8> image = ReadImage8(capture->PathOf(recorded.frames[0]));
    ASSERT_TRUE(image.ok());
    const Rigid3d T_camera_station = sensor->T_car_sensor_nominal.Inverse() *
                                     capture->manifest.aligner.T_station_car().Inverse();
    const Truth truth = TruthOf(recorded.name);
    int found = 0;
    for (const std::string& id : sensor->targets) {
      const StationBoard* board = capture->station.FindBoard(id);
      ASSERT_NE(board, nullptr);
      std::optional<Detection> d = DetectInBoardView(
          *camera, image->view(), T_camera_station * board->T_station_board, board->board);
      ASSERT_TRUE(d.has_value()) << id;
      if (!d->found) continue;
      ++found;
      const double rms = RmsError(*d, truth, id);
      // The detectors' own accuracy on these small, obliquely seen boards: corner fits on the
      // checkers, line fits on the chessboard and vertical board, marker corners (L-corners
      // from edge lines) on the ArUco and round-hole markers, which are about as far off in the
      // raw image when the detector finds them there (rear_aruco: 0.27 px raw).
      const BoardType type = board->board.params().type;
      const double bar = type == BoardType::kChecker                                      ? 0.05
                         : type == BoardType::kChessboard || type == BoardType::kVertical ? 0.15
                                                                                          : 0.35;
      EXPECT_LT(rms, bar) << id;
      std::printf("%s %s: %zu features, rms %.4f px\n", recorded.name.c_str(), id.c_str(),
                  d->features.size(), rms);
      if (std::optional<Detection> raw = DetectBoard(image->view(), board->board);
          raw && raw->found) {
        // Where the raw image suffices, the view is no worse.
        EXPECT_LT(rms, 1.25 * RmsError(*raw, truth, id) + 0.01) << id;
      }
    }
    // Every surround camera finds at least one of its boards, the front one (60 degrees off
    // axis, not found in the raw image at all) its chessboard and vertical board.
    EXPECT_GE(found, recorded.name == "surround_front" ? 4 : 1);
  }
}

// The scene of issue 20 where surround_left lost rear_left_board (too_few_features in 7 of 62
// frames): `linecal sim --seed 14 --sensors surround_left --perturb-angle-deg 1.5 --noise 2
// --blur 0.5`. The 6 x 5 checker faces the camera about 67 degrees off the line of sight, so
// its squares image under half as wide as tall: a view at 1.5 times the raw image's finest
// scale shows them 7.8 px across at the board's centre, under the checker detector's 12 px.
// DetectInBoardView looks again in a view where they reach 12 px, and finds the board at the
// true pixels.
TEST(BoardView, AFarTurnedCheckerIsSampledFinelyEnoughToBeFound) {
  const std::string dir =
      (fs::temp_directory_path() / ("board_view_turned_" + std::to_string(getpid()))).string();
  auto station =
      ReadStationLayout(std::string(LINECAL_SOURCE_DIR) + "/deploy/stations/reference.json");
  auto car = ReadCarModel(std::string(LINECAL_SOURCE_DIR) + "/deploy/cars/reference.json");
  ASSERT_TRUE(station.ok() && car.ok());
  SimulatorOptions o;
  o.sensors = {"surround_left"};
  o.perturb_angle_deg = 1.5;
  o.camera.noise_sigma = 2;
  o.camera.blur_sigma_px = 0.5;
  auto sim = SimulateCapture(*station, *car, o, 14, dir);
  ASSERT_TRUE(sim.ok()) << sim.status();
  absl::StatusOr<Capture> capture = ReadCapture(dir);
  ASSERT_TRUE(capture.ok()) << capture.status();
  const SensorModel* sensor = capture->car.FindSensor("surround_left");
  ASSERT_NE(sensor, nullptr);
  absl::StatusOr<CameraModel> camera = CameraModel::Create(*sensor->intrinsics);
  ASSERT_TRUE(camera.ok());
  absl::StatusOr<Image8> image =
      ReadImage8(capture->PathOf(capture->manifest.sensors[0].frames[0]));
  ASSERT_TRUE(image.ok());
  const StationBoard* board = capture->station.FindBoard("rear_left_board");
  ASSERT_NE(board, nullptr);
  const Rigid3d T_camera_board = sensor->T_car_sensor_nominal.Inverse() *
                                 capture->manifest.aligner.T_station_car().Inverse() *
                                 board->T_station_board;
  // At the raw image's scale alone the squares are too narrow (the miss, kept as the check
  // that this scene still holds it).
  absl::StatusOr<BoardView> raw_scale =
      BoardView::Render(*camera, image->view(), T_camera_board, board->board.page_size_m());
  ASSERT_TRUE(raw_scale.ok()) << raw_scale.status();
  const std::optional<Detection> narrow = DetectBoard(raw_scale->image().view(), board->board);
  ASSERT_TRUE(narrow.has_value());
  EXPECT_FALSE(narrow->found);
  EXPECT_EQ(narrow->reason, DetectReason::kTooFewFeatures);

  const std::optional<Detection> d =
      DetectInBoardView(*camera, image->view(), T_camera_board, board->board);
  ASSERT_TRUE(d.has_value());
  ASSERT_TRUE(d->found) << DetectReasonName(d->reason);
  EXPECT_EQ(d->features.size(), 30u);
  Truth truth;
  for (const auto& f : sim->ground_truth["sensors"][0]["frames"][0]["features"])
    truth.uv[{f["board"].get<std::string>(), f["id"].get<int>()}] =
        Eigen::Vector2d(f["u"].get<double>(), f["v"].get<double>());
  // The checkers' bar of the test above.
  EXPECT_LT(RmsError(*d, truth, "rear_left_board"), 0.05);
  fs::remove_all(dir);
}

TEST(BoardView, RefusesBoardsBehindTheCameraAndBadOptions) {
  CameraIntrinsics k;
  k.type = CameraModelType::kFisheye;
  k.width = 640;
  k.height = 480;
  k.fx = k.fy = 200;
  k.cx = 320;
  k.cy = 240;
  absl::StatusOr<CameraModel> camera = CameraModel::Create(k);
  ASSERT_TRUE(camera.ok());
  Image8 raw(640, 480, 100);
  const Eigen::Vector2d page(0.8, 0.6);
  // Facing the camera 2 m ahead: a view; behind it (the fisheye's valid region ends before
  // the negative axis) or edge-on: refused with the reason.
  const Rigid3d facing(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX())),
                       {0, 0, 2});
  absl::StatusOr<BoardView> view = BoardView::Render(*camera, raw.view(), facing, page);
  ASSERT_TRUE(view.ok()) << view.status();
  EXPECT_EQ(view->image().at(view->image().width / 2, view->image().height / 2), 100);
  const std::optional<Eigen::Vector2d> centre =
      view->ToRaw(*camera, {(view->image().width - 1) / 2.0, (view->image().height - 1) / 2.0});
  ASSERT_TRUE(centre.has_value());
  EXPECT_NEAR(centre->x(), 320, 1.0);
  EXPECT_NEAR(centre->y(), 240, 1.0);
  const Rigid3d edge_on(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY())),
                        {0, 0, 2});
  EXPECT_EQ(BoardView::Render(*camera, raw.view(), edge_on, page).status().code(),
            absl::StatusCode::kInvalidArgument);
  const Rigid3d behind(Eigen::Quaterniond::Identity(), {0, 0, -2});
  EXPECT_EQ(BoardView::Render(*camera, raw.view(), behind, page).status().code(),
            absl::StatusCode::kInvalidArgument);
  BoardViewOptions bad;
  bad.scale = 0;
  absl::Status s = BoardView::Render(*camera, raw.view(), facing, page, bad).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("scale"), std::string::npos) << s;
  BoardViewOptions negative_cell;
  negative_cell.min_cell_px = -1;
  s = BoardView::Render(*camera, raw.view(), facing, page, negative_cell).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("min_cell_px"), std::string::npos) << s;
}

}  // namespace
}  // namespace linecal

// Speed of every camera board detector (docs/acceptance.md: chessboard, circle, vertical <= 4 ms
// at 1280 x 720 on one thread; ArUco board <= OpenCV's detectMarkers; AprilTag grid <= 0.8 x
// OpenCV's aruco AprilTag 36h11 detector with a 2-bit border; 2448 x 2048 <= 3 x 1280 x 720),
// with OpenCV 4.6 on the same images in the same process as the baseline. Built with the
// tests, run by hand (docs/detectors.md):
//   build-dir/bin/detectors_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
// Each image: the board over 45% of the image width (at most 80% of its height), turned 30 degrees,
// noise 2, blur 0.7, in front of a cluttered wall; the same field of view at both sizes. The marker
// boards also at their smallest (4 px data cells), 1280 x 720, with OpenCV on the same images.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <opencv2/aruco.hpp>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <string>
#include <tuple>
#include <vector>

#include "detectors/detect.h"
#include "tests/detectors/circle/circle_scene.h"

namespace linecal {
namespace {

// The benchmark's boards, by index: kAllBoardTypes' boards with their default parameters
// (BoardParams of that type; the generic ones 9 x 6), then kHexagonal.
constexpr int kHexagonal = static_cast<int>(kAllBoardTypes.size());

// BoofCV's hexagonal circle grid as the corpus's photos show it (boofcv/
// circle_hexagonal_sony_hx5v: 28 x 24, circles 1/1.2 of their distance).
BoardParams ParamsOf(int board) {
  BoardParams p;
  if (board < kHexagonal) {
    p.type = kAllBoardTypes[board];
    return p;
  }
  p.type = BoardType::kCircleGrid;
  p.hexagonal = true;
  p.cols = 28;
  p.rows = 24;
  p.spacing_m = 0.012;
  p.diameter_m = 0.01;
  return p;
}

const Board& BoardOf(int board) {
  static auto* boards = new std::map<int, Board>;
  auto it = boards->find(board);
  if (it == boards->end()) it = boards->emplace(board, *Board::Create(ParamsOf(board))).first;
  return it->second;
}

std::string LabelOf(int board) {
  return board == kHexagonal ? "circle_grid hexagonal 28x24" : BoardTypeName(kAllBoardTypes[board]);
}

// cell_px > 0: the board as far as makes its smallest cell (a marker's data cell) that many
// pixels, as the evaluation's farthest boards.
const Image8& Frame(int board, int width, int height, int cell_px = 0) {
  static auto* frames = new std::map<std::tuple<int, int, int, int>, Image8>;
  const auto key = std::make_tuple(board, width, height, cell_px);
  auto it = frames->find(key);
  if (it != frames->end()) return it->second;
  const CameraModel camera = circle_scene::Camera(width, height);
  const Eigen::Vector2d page_m = BoardOf(board).page_size_m();
  // 45% of the width seen straight on (the 30 degree turn narrows it by cos 30), and a tall
  // board (the vertical one) no more than 80% of the height.
  const double distance_m =
      cell_px > 0
          ? camera.intrinsics().fx * circle_scene::SmallestFeatureM(BoardOf(board)) / cell_px
          : std::max(camera.intrinsics().fx * page_m.x() / (0.45 * width),
                     camera.intrinsics().fy * page_m.y() / (0.8 * height));
  CameraRenderOptions o = circle_scene::Effects(2.0, 0.7);
  o.clutter = true;
  StationLayout layout =
      circle_scene::OneBoard(ParamsOf(board).type, {distance_m, 30, 10, 8, -0.1, -0.05});
  layout.boards.front().params = ParamsOf(board);
  layout.boards.front().board = BoardOf(board);
  absl::StatusOr<CameraFrame> frame = circle_scene::RenderScene(layout, o, 1, camera);
  if (!frame.ok()) {
    std::fprintf(stderr, "render: %s\n", frame.status().ToString().c_str());
    std::exit(2);
  }
  return frames->emplace(key, std::move(frame->image8)).first->second;
}

const Image8& Frame(BoardType type, int width, int height, int cell_px = 0) {
  return Frame(static_cast<int>(type), width, height, cell_px);
}

cv::Mat MatOf(const Image8& image) {
  return cv::Mat(image.height, image.width, CV_8UC1,
                 const_cast<std::uint8_t*>(image.pixels.data()));
}

// Args: board (ParamsOf), width, height, the smallest cell in pixels (Frame; 0: the usual
// framing).
void BM_Detect(benchmark::State& state) {
  const int board = static_cast<int>(state.range(0));
  const Image8& image = Frame(board, static_cast<int>(state.range(1)),
                              static_cast<int>(state.range(2)), static_cast<int>(state.range(3)));
  state.SetLabel(LabelOf(board));
  for (auto _ : state) {
    const std::optional<Detection> d = DetectBoard(image.view(), BoardOf(board));
    if (!d || !d->found) {
      state.SkipWithError("board not found");
      break;
    }
    benchmark::DoNotOptimize(d);
  }
}

void DetectArgs(benchmark::internal::Benchmark* b) {
  for (BoardType type : kAllBoardTypes) {
    b->Args({static_cast<int>(type), 1280, 720, 0});
    b->Args({static_cast<int>(type), 2448, 2048, 0});
  }
  // The marker boards at their smallest (4 px data cells), where the ArUco and round-hole
  // markers' sides are fitted to the page model (detectors/markers/page_edge_fit.h); the
  // AprilTag grid's two-cell borders are wide enough not to be.
  for (BoardType type : {BoardType::kAruco, BoardType::kApriltag, BoardType::kRoundHole}) {
    b->Args({static_cast<int>(type), 1280, 720, 4});
  }
  b->Args({kHexagonal, 1280, 720, 0});
}
BENCHMARK(BM_Detect)->Apply(DetectArgs)->Unit(benchmark::kMillisecond);

// OpenCV's aruco module on the same image: DICT_4X4_50 with its default parameters on the
// ArUco board (the reference toolbox's call), and the AprilTag 36h11 dictionary with
// markerBorderBits = 2 on the AprilTag grid (Kalibr's layout). Args: dictionary, width, height,
// the smallest cell in pixels (Frame; 0: the usual framing).
void BM_OpenCvDetectMarkers(benchmark::State& state) {
  const int dictionary_id = static_cast<int>(state.range(0));
  const bool apriltag = dictionary_id == cv::aruco::DICT_APRILTAG_36h11;
  const Image8& image =
      Frame(apriltag ? BoardType::kApriltag : BoardType::kAruco, static_cast<int>(state.range(1)),
            static_cast<int>(state.range(2)), static_cast<int>(state.range(3)));
  const cv::Mat mat = MatOf(image);
  const cv::Ptr<cv::aruco::Dictionary> dictionary =
      cv::aruco::getPredefinedDictionary(dictionary_id);
  const cv::Ptr<cv::aruco::DetectorParameters> params = cv::aruco::DetectorParameters::create();
  if (apriltag) params->markerBorderBits = 2;
  state.SetLabel(apriltag ? "apriltag 36h11, border 2" : "4x4_50");
  // How many markers it finds is part of the comparison (ours must find the whole board).
  std::size_t found = 0;
  for (auto _ : state) {
    std::vector<std::vector<cv::Point2f>> corners;
    std::vector<int> ids;
    cv::aruco::detectMarkers(mat, dictionary, corners, ids, params);
    found = ids.size();
    benchmark::DoNotOptimize(ids);
  }
  state.counters["markers_found"] = static_cast<double>(found);
  state.counters["markers_printed"] = apriltag ? 36 : 4;
}
BENCHMARK(BM_OpenCvDetectMarkers)
    ->Args({cv::aruco::DICT_4X4_50, 1280, 720, 0})
    ->Args({cv::aruco::DICT_4X4_50, 2448, 2048, 0})
    ->Args({cv::aruco::DICT_APRILTAG_36h11, 1280, 720, 0})
    ->Args({cv::aruco::DICT_APRILTAG_36h11, 2448, 2048, 0})
    ->Args({cv::aruco::DICT_4X4_50, 1280, 720, 4})
    ->Args({cv::aruco::DICT_APRILTAG_36h11, 1280, 720, 4})
    ->Unit(benchmark::kMillisecond);

// The candidate stage of cv::findCirclesGrid (the reference toolbox's circle detector):
// SimpleBlobDetector with both blob polarities on the circle board, which needs them; with
// findCirclesGrid's default parameters (dark blobs) on the hexagonal grid, whose layout
// findCirclesGrid cannot group (no OpenCV detector finds it, so its candidate stage is the
// nearest baseline). Args: board (ParamsOf), width, height.
void BM_OpenCvSimpleBlobDetector(benchmark::State& state) {
  const int board = static_cast<int>(state.range(0));
  const Image8& image =
      Frame(board, static_cast<int>(state.range(1)), static_cast<int>(state.range(2)));
  const cv::Mat mat = MatOf(image);
  cv::SimpleBlobDetector::Params params;
  params.filterByColor = board != static_cast<int>(BoardType::kCircle);
  const cv::Ptr<cv::SimpleBlobDetector> detector = cv::SimpleBlobDetector::create(params);
  state.SetLabel(LabelOf(board));
  std::size_t found = 0;
  for (auto _ : state) {
    std::vector<cv::KeyPoint> keypoints;
    detector->detect(mat, keypoints);
    found = keypoints.size();
    benchmark::DoNotOptimize(keypoints);
  }
  state.counters["blobs_found"] = static_cast<double>(found);
}
BENCHMARK(BM_OpenCvSimpleBlobDetector)
    ->Args({static_cast<int>(BoardType::kCircle), 1280, 720})
    ->Args({static_cast<int>(BoardType::kCircle), 2448, 2048})
    ->Args({kHexagonal, 1280, 720})
    ->Unit(benchmark::kMillisecond);

// cv::findChessboardCornersSB (default flags) on the generic 9 x 6 checker: OpenCV's detector of
// the chessboard class, the baseline of the square grid, which OpenCV has no detector for
// (a grid of separate squares: BoofCV's). Args: width, height.
void BM_OpenCvFindChessboardCornersSB(benchmark::State& state) {
  const Image8& image = Frame(BoardType::kChecker, static_cast<int>(state.range(0)),
                              static_cast<int>(state.range(1)));
  const cv::Mat mat = MatOf(image);
  const BoardParams& p = ParamsOf(static_cast<int>(BoardType::kChecker));
  state.SetLabel("checker 9x6");
  bool found = false;
  for (auto _ : state) {
    std::vector<cv::Point2f> corners;
    found = cv::findChessboardCornersSB(mat, cv::Size(p.cols, p.rows), corners);
    benchmark::DoNotOptimize(corners);
  }
  state.counters["found"] = found ? 1 : 0;
}
BENCHMARK(BM_OpenCvFindChessboardCornersSB)->Args({1280, 720})->Unit(benchmark::kMillisecond);

// OpenCV's ChArUco detection on the ChArUco render: cv::aruco::detectMarkers (DICT_4X4_50,
// default parameters) and interpolateCornersCharuco on a CharucoBoard of the same layout
// (OpenCV 4.6 draws the pattern linecal's default board has). Args: width, height.
void BM_OpenCvCharuco(benchmark::State& state) {
  const Image8& image = Frame(BoardType::kCharuco, static_cast<int>(state.range(0)),
                              static_cast<int>(state.range(1)));
  const cv::Mat mat = MatOf(image);
  const BoardParams& p = ParamsOf(static_cast<int>(BoardType::kCharuco));
  const cv::Ptr<cv::aruco::Dictionary> dictionary =
      cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50);
  const cv::Ptr<cv::aruco::CharucoBoard> board = cv::aruco::CharucoBoard::create(
      p.cols, p.rows, static_cast<float>(p.square_m), static_cast<float>(p.marker_m), dictionary);
  const cv::Ptr<cv::aruco::DetectorParameters> params = cv::aruco::DetectorParameters::create();
  state.SetLabel("charuco 9x6, 4x4_50");
  std::size_t found = 0;
  for (auto _ : state) {
    std::vector<std::vector<cv::Point2f>> marker_corners;
    std::vector<int> marker_ids;
    cv::aruco::detectMarkers(mat, dictionary, marker_corners, marker_ids, params);
    std::vector<cv::Point2f> corners;
    std::vector<int> ids;
    if (!marker_ids.empty()) {
      cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, mat, board, corners, ids);
    }
    found = ids.size();
    benchmark::DoNotOptimize(ids);
  }
  state.counters["corners_found"] = static_cast<double>(found);
  state.counters["corners_printed"] = (p.cols - 1) * (p.rows - 1);
}
BENCHMARK(BM_OpenCvCharuco)->Args({1280, 720})->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace linecal

int main(int argc, char** argv) {
  cv::setNumThreads(1);  // the bars are for one thread
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  return 0;
}

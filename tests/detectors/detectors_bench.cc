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
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <tuple>
#include <vector>

#include "detectors/detect.h"
#include "tests/detectors/circle/circle_scene.h"

namespace linecal {
namespace {

const Board& BoardOf(BoardType type) {
  static auto* boards = new std::map<BoardType, Board>;
  auto it = boards->find(type);
  if (it == boards->end()) {
    BoardParams p;
    p.type = type;
    it = boards->emplace(type, *Board::Create(p)).first;
  }
  return it->second;
}

// cell_px > 0: the board as far as makes its smallest cell (a marker's data cell) that many
// pixels, as the evaluation's farthest boards.
const Image8& Frame(BoardType type, int width, int height, int cell_px = 0) {
  static auto* frames = new std::map<std::tuple<BoardType, int, int, int>, Image8>;
  const auto key = std::make_tuple(type, width, height, cell_px);
  auto it = frames->find(key);
  if (it != frames->end()) return it->second;
  const CameraModel camera = circle_scene::Camera(width, height);
  const Eigen::Vector2d page_m = BoardOf(type).page_size_m();
  // 45% of the width seen straight on (the 30 degree turn narrows it by cos 30), and a tall
  // board (the vertical one) no more than 80% of the height.
  const double distance_m =
      cell_px > 0 ? camera.intrinsics().fx * circle_scene::SmallestFeatureM(BoardOf(type)) / cell_px
                  : std::max(camera.intrinsics().fx * page_m.x() / (0.45 * width),
                             camera.intrinsics().fy * page_m.y() / (0.8 * height));
  CameraRenderOptions o = circle_scene::Effects(2.0, 0.7);
  o.clutter = true;
  absl::StatusOr<CameraFrame> frame = circle_scene::RenderScene(
      circle_scene::OneBoard(type, {distance_m, 30, 10, 8, -0.1, -0.05}), o, 1, camera);
  if (!frame.ok()) {
    std::fprintf(stderr, "render: %s\n", frame.status().ToString().c_str());
    std::exit(2);
  }
  return frames->emplace(key, std::move(frame->image8)).first->second;
}

cv::Mat MatOf(const Image8& image) {
  return cv::Mat(image.height, image.width, CV_8UC1, const_cast<std::uint8_t*>(image.pixels.data()));
}

// Args: board type, width, height, the smallest cell in pixels (Frame; 0: the usual framing).
void BM_Detect(benchmark::State& state) {
  const BoardType type = static_cast<BoardType>(state.range(0));
  const Image8& image = Frame(type, static_cast<int>(state.range(1)),
                              static_cast<int>(state.range(2)), static_cast<int>(state.range(3)));
  state.SetLabel(BoardTypeName(type));
  for (auto _ : state) {
    const std::optional<Detection> d = DetectBoard(image.view(), BoardOf(type));
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
  const cv::Ptr<cv::aruco::Dictionary> dictionary = cv::aruco::getPredefinedDictionary(dictionary_id);
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
// SimpleBlobDetector with both blob polarities, as the circle board needs.
void BM_OpenCvSimpleBlobDetector(benchmark::State& state) {
  const Image8& image =
      Frame(BoardType::kCircle, static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  const cv::Mat mat = MatOf(image);
  cv::SimpleBlobDetector::Params params;
  params.filterByColor = false;
  const cv::Ptr<cv::SimpleBlobDetector> detector = cv::SimpleBlobDetector::create(params);
  for (auto _ : state) {
    std::vector<cv::KeyPoint> keypoints;
    detector->detect(mat, keypoints);
    benchmark::DoNotOptimize(keypoints);
  }
}
BENCHMARK(BM_OpenCvSimpleBlobDetector)->Args({1280, 720})->Args({2448, 2048})->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace linecal

int main(int argc, char** argv) {
  cv::setNumThreads(1);  // the bars are for one thread
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  return 0;
}

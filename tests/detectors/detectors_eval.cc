// Camera board detector evaluation over docs/acceptance.md's test set, rendered by the station
// simulator with exact ground truth (docs/detectors.md):
//   - every board at three distances: its page over 80% of the image width (or height), its
//     smallest square or cell 12 px (marker boards: a data cell 4 px) in the image, and their
//     geometric mean (circle_scene::EvaluationDistances: a turned board stands nearer so
//     that its far edge's cells keep that size; --fronto-size sizes it face-on instead);
//   - in-plane roll -30 / 0 / 30 degrees, seven yaw-pitch pairs up to 50 degrees;
//   - three sets of effects: clean (noise 0, blur 0.5), noisy (noise 4, blur 1.0), hard
//     (noise 6, blur 1.5, a 4:1 illumination gradient, gamma 0.6 or 1.6, JPEG 80, clutter);
//   - false detections: every other board's detector on each render, and board-free
//     cluttered renders.
// Prints per board: the detection rate of renders that show the whole board, false and wrong
// detections (a feature farther from its truth than 40% of the smallest feature), the RMS
// and largest feature error (clean, noisy), the circle centre bias (the mean error vector of
// the clean circle-board renders). With --check, exits 1 when a bar is missed (see Options);
// detection rates are printed, not checked.
//   detectors_eval [--board NAME]... [--width W --height H] [--reduced] [--board-free N]
//                  [--check] [--fronto-size] [--seed S] [--repeat N] [--misses DIR]
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "detectors/detect.h"
#include "station/io/image_io.h"
#include "tests/detectors/circle/circle_scene.h"

namespace linecal {
namespace {

using circle_scene::Pose;

// docs/acceptance.md, Detectors (images).
constexpr double kCleanRmsBarPx = 0.05;
constexpr double kNoisyRmsBarPx = 0.12;
constexpr double kCircleBiasBarPx = 0.02;

struct Options {
  std::vector<BoardType> boards{kAllBoardTypes.begin(), kAllBoardTypes.end()};
  int width = 1280;
  int height = 720;
  bool reduced = false;
  int board_free = 200;
  // --check: exit 1 when a bar on accuracy, false or wrong detections is missed (what CI
  // holds on the reduced grid; docs/detectors.md). Detection rates are printed only.
  bool check = false;
  bool fronto_size = false;  // --fronto-size: see circle_scene::EvaluationDistances
  // The first render's seed (noise, clutter, the board's offset), and how many times the
  // grid is rendered, each time with the next seeds: one render moves a hard-set rate by
  // 1.6%, so a rate near the 99.5% bar needs several passes to be told from it.
  std::uint64_t seed = 1;
  int repeat = 1;
  std::string misses_dir;  // --misses DIR: each missed render written there as a PNG
};

struct EffectSet {
  const char* name;
  double noise;
  double blur;
  bool hard;
};
constexpr std::array<EffectSet, 3> kSets = {EffectSet{"clean", 0.0, 0.5, false},
                                            EffectSet{"noisy", 4.0, 1.0, false},
                                            EffectSet{"hard", 6.0, 1.5, true}};

struct Tally {
  int frames = 0;  // renders showing the whole board
  int found = 0;
  int wrong = 0;  // found, but a feature off by more than 40% of the smallest feature
  double sum_sq_px = 0.0;
  int features = 0;
  double max_px = 0.0;
  Eigen::Vector2d sum_error_px = Eigen::Vector2d::Zero();
};

struct BoardResult {
  std::array<Tally, 3> sets;
  int false_detections = 0;  // this board's detector reporting a board on another's render
};

const Board& BoardOf(BoardType type) {
  static std::array<Board, kAllBoardTypes.size()>* boards = [] {
    auto* b = new std::array<Board, kAllBoardTypes.size()>;
    for (BoardType t : kAllBoardTypes) {
      BoardParams p;
      p.type = t;
      (*b)[static_cast<int>(t)] = *Board::Create(p);
    }
    return b;
  }();
  return (*boards)[static_cast<int>(type)];
}

int CameraFeatureCount(const Board& board) {
  return static_cast<int>(
      std::count_if(board.features().begin(), board.features().end(),
                    [](const BoardFeature& f) { return f.kind != FeatureKind::kHoleCentre; }));
}

CameraRenderOptions EffectsOf(const EffectSet& set, std::uint64_t seed) {
  return set.hard ? circle_scene::HardEffects(seed) : circle_scene::Effects(set.noise, set.blur);
}

// Runs every other board's detector on a render of `shown` (nullptr: no board).
void CountFalseDetections(const Image8& image, const BoardType* shown, const Options& options,
                          std::array<BoardResult, kAllBoardTypes.size()>* results) {
  for (BoardType other : options.boards) {
    if (shown != nullptr && other == *shown) continue;
    // The ArUco board and the round-hole board share their four markers (docs/boards.md): the
    // ArUco detector on the round-hole board is told apart by the paint check, so both count.
    const std::optional<Detection> d = DetectBoard(image.view(), BoardOf(other));
    if (d && d->found) {
      ++(*results)[static_cast<int>(other)].false_detections;
      std::printf("false detection: %s on a render of %s\n", BoardTypeName(other),
                  shown ? BoardTypeName(*shown) : "no board");
    }
  }
}

// One render of the grid: the board, the effect set (index into kSets), the pose, the size of
// the smallest feature face-on (px), the render's seed, and the features a whole view shows.
struct RenderCase {
  BoardType type;
  std::size_t set;
  double distance, roll, yaw, pitch, feature_px;
  std::uint64_t seed;
  int expected;
};

// Scores one render of `c.type`: the other boards' false detections, then, when the whole board
// is in view, the detection against the rendered truth into `results` (found, the features'
// errors, wrong when one is off by more than 0.4 x the smallest feature); prints misses, wrong
// detections and boards partly in view, and writes missed renders to options.misses_dir.
void ScoreRender(const RenderCase& c, const CameraFrame& frame, const Options& options,
                 std::array<BoardResult, kAllBoardTypes.size()>* results) {
  CountFalseDetections(frame.image8, &c.type, options, results);
  const auto visible =
      std::count_if(frame.features.begin(), frame.features.end(),
                    [](const RenderedFeature& f) { return f.kind != FeatureKind::kHoleCentre; });
  if (visible != c.expected) {
    if (visible > 0 && visible < c.expected / 2) return;  // mostly out of view
    if (visible > 0) {
      std::printf(
          "not wholly in view: %s %s, distance %.2f m roll %.0f yaw %.0f pitch %.0f: "
          "%d of %d\n",
          BoardTypeName(c.type), kSets[c.set].name, c.distance, c.roll, c.yaw, c.pitch,
          static_cast<int>(visible), c.expected);
    }
    return;
  }
  const Detection d = *DetectBoard(frame.image8.view(), BoardOf(c.type));
  Tally& t = (*results)[static_cast<int>(c.type)].sets[c.set];
  ++t.frames;
  if (!d.found) {
    std::printf(
        "miss: %s %s, distance %.2f m (feature %.1f px) roll %.0f yaw %.0f pitch %.0f "
        "seed %llu: %s\n",
        BoardTypeName(c.type), kSets[c.set].name, c.distance, c.feature_px, c.roll, c.yaw, c.pitch,
        static_cast<unsigned long long>(c.seed), DetectReasonName(d.reason));
    if (!options.misses_dir.empty()) {
      const std::string path = options.misses_dir + "/" + BoardTypeName(c.type) + "_" +
                               kSets[c.set].name + "_seed" + std::to_string(c.seed) + ".png";
      const absl::Status written = WritePng8(path, frame.image8.view());
      if (!written.ok()) std::fprintf(stderr, "%s\n", written.ToString().c_str());
    }
    return;
  }
  ++t.found;
  double worst = 0.0;
  for (const DetectedFeature& f : d.features) {
    const auto truth = std::find_if(frame.features.begin(), frame.features.end(),
                                    [&](const RenderedFeature& r) { return r.feature_id == f.id; });
    if (truth == frame.features.end()) continue;
    const Eigen::Vector2d e = f.uv_px - truth->uv_px;
    t.sum_sq_px += e.squaredNorm();
    t.sum_error_px += e;
    ++t.features;
    worst = std::max(worst, e.norm());
  }
  t.max_px = std::max(t.max_px, worst);
  if (worst > 0.4 * c.feature_px) {
    ++t.wrong;
    std::printf(
        "wrong: %s %s, distance %.2f m roll %.0f yaw %.0f pitch %.0f: a feature %.1f "
        "px off\n",
        BoardTypeName(c.type), kSets[c.set].name, c.distance, c.roll, c.yaw, c.pitch, worst);
  }
}

// Prints the results as a markdown table, a line under each board that misses a bar (false or
// wrong detections, accuracy); returns whether every board meets every bar.
bool PrintResults(const Options& options,
                  const std::array<BoardResult, kAllBoardTypes.size()>& results) {
  bool bars_met = true;
  std::printf("\n%d x %d, %s grid x %d from seed %llu, %d board-free renders\n\n", options.width,
              options.height, options.reduced ? "reduced" : "full", options.repeat,
              static_cast<unsigned long long>(options.seed), options.board_free);
  std::printf(
      "| board | renders (whole board) | found | rate clean / noisy / hard | false | wrong | "
      "RMS clean px | max clean px | RMS noisy px | max noisy px | circle bias px |\n");
  std::printf("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (BoardType type : options.boards) {
    const BoardResult& r = results[static_cast<int>(type)];
    int frames = 0;
    int found = 0;
    int wrong = 0;
    for (const Tally& t : r.sets) {
      frames += t.frames;
      found += t.found;
      wrong += t.wrong;
    }
    const auto rms = [](const Tally& t) {
      return t.features ? std::sqrt(t.sum_sq_px / t.features) : 0.0;
    };
    const auto rate = [](const Tally& t) { return 100.0 * t.found / std::max(1, t.frames); };
    const Tally& clean = r.sets[0];
    const Tally& noisy = r.sets[1];
    const double bias = clean.features ? (clean.sum_error_px / clean.features).norm() : 0.0;
    char bias_text[32] = "—";
    if (type == BoardType::kCircle) std::snprintf(bias_text, sizeof bias_text, "%.4f", bias);
    std::printf(
        "| %s | %d | %d | %.1f%% / %.1f%% / %.1f%% | %d | %d | %.4f | %.3f | %.4f | %.3f | %s |\n",
        BoardTypeName(type), frames, found, rate(r.sets[0]), rate(r.sets[1]), rate(r.sets[2]),
        r.false_detections, wrong, rms(clean), clean.max_px, rms(noisy), noisy.max_px, bias_text);
    const bool safe = r.false_detections == 0 && wrong == 0;
    const bool accurate = rms(clean) <= kCleanRmsBarPx && rms(noisy) <= kNoisyRmsBarPx &&
                          (type != BoardType::kCircle || bias <= kCircleBiasBarPx);
    if (!safe) std::printf("  ^ %s: false or wrong detections\n", BoardTypeName(type));
    if (!accurate) std::printf("  ^ %s misses a bar on accuracy\n", BoardTypeName(type));
    if (!safe || !accurate) bars_met = false;
  }
  return bars_met;
}

int Run(const Options& options) {
  const CameraModel camera = circle_scene::Camera(options.width, options.height);
  std::array<BoardResult, kAllBoardTypes.size()> results;
  const std::vector<double> rolls =
      options.reduced ? std::vector<double>{-30.0, 30.0} : std::vector<double>{-30.0, 0.0, 30.0};
  std::vector<std::array<double, 2>> yaw_pitch = {{0, 0},   {50, 0},  {-50, 0},  {0, 50},
                                                  {0, -50}, {35, 35}, {-35, -35}};
  if (options.reduced) yaw_pitch = {{0, 0}, {45, 0}, {-30, -30}};
  std::uint64_t seed = options.seed;
  for (int pass = 0; pass < options.repeat; ++pass) {
    for (BoardType type : options.boards) {
      const Board& board = BoardOf(type);
      const int expected = CameraFeatureCount(board);
      std::printf("%s: smallest feature %.1f mm; face-on distances", BoardTypeName(type),
                  1e3 * circle_scene::SmallestFeatureM(board));
      for (double d : circle_scene::EvaluationDistances(board, camera, options.reduced, 0.0, 0.0,
                                                        options.fronto_size)) {
        std::printf(" %.2f m", d);
      }
      std::printf("\n");
      for (const auto& [yaw, pitch] : yaw_pitch) {
        const std::vector<double> distances = circle_scene::EvaluationDistances(
            board, camera, options.reduced, yaw, pitch, options.fronto_size);
        if (distances.empty()) {
          std::printf(
              "no size: %s turned yaw %.0f pitch %.0f: cells under the smallest size even at "
              "80%% of the image\n",
              BoardTypeName(type), yaw, pitch);
        }
        for (const double distance : distances) {
          // The smallest feature face-on at this distance; turned, it is smaller at the far edge.
          const double feature_px =
              camera.intrinsics().fx * circle_scene::SmallestFeatureM(board) / distance;
          for (const double roll : rolls) {
            for (std::size_t s = 0; s < kSets.size(); ++s) {
              const Pose pose = circle_scene::EvaluationPose(distance, yaw, pitch, roll, seed);
              const absl::StatusOr<CameraFrame> frame = circle_scene::RenderScene(
                  circle_scene::OneBoard(type, pose), EffectsOf(kSets[s], seed), seed, camera);
              ++seed;
              if (!frame.ok()) {
                std::fprintf(stderr, "render: %s\n", frame.status().ToString().c_str());
                return 2;
              }
              ScoreRender({type, s, distance, roll, yaw, pitch, feature_px, seed - 1, expected},
                          *frame, options, &results);
            }
          }
        }
      }
    }
  }
  for (int i = 0; i < options.board_free; ++i) {
    StationLayout empty;
    empty.surfaces.push_back(circle_scene::Wall());
    CameraRenderOptions o = EffectsOf(kSets[i % 3], seed);
    o.clutter = true;
    o.clutter_seed = seed;
    const absl::StatusOr<CameraFrame> frame = circle_scene::RenderScene(empty, o, seed++, camera);
    if (!frame.ok()) return 2;
    CountFalseDetections(frame->image8, nullptr, options, &results);
  }

  const bool bars_met = PrintResults(options, results);
  return options.check && !bars_met ? 1 : 0;
}

bool ParseArgs(int argc, char** argv, Options* o) {
  bool boards_given = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--board" && has_value) {
      const std::string name = argv[++i];
      const auto t = std::find_if(kAllBoardTypes.begin(), kAllBoardTypes.end(),
                                  [&](BoardType b) { return name == BoardTypeName(b); });
      if (t == kAllBoardTypes.end()) {
        std::fprintf(stderr, "detectors_eval: --board: unknown board '%s'\n", name.c_str());
        return false;
      }
      // Repeated, the boards add up (in the order given, which sets their renders' seeds):
      // each board's detector runs on the others' renders.
      if (!boards_given) o->boards.clear();
      boards_given = true;
      o->boards.push_back(*t);
    } else if (a == "--width" && has_value) {
      o->width = std::atoi(argv[++i]);
    } else if (a == "--height" && has_value) {
      o->height = std::atoi(argv[++i]);
    } else if (a == "--board-free" && has_value) {
      o->board_free = std::atoi(argv[++i]);
    } else if (a == "--reduced") {
      o->reduced = true;
    } else if (a == "--check") {
      o->check = true;
    } else if (a == "--fronto-size") {
      o->fronto_size = true;
    } else if (a == "--seed" && has_value) {
      o->seed = std::strtoull(argv[++i], nullptr, 10);
    } else if (a == "--repeat" && has_value) {
      o->repeat = std::atoi(argv[++i]);
    } else if (a == "--misses" && has_value) {
      o->misses_dir = argv[++i];
    } else {
      std::fprintf(stderr, "detectors_eval: unknown or incomplete argument '%s'\n", a.c_str());
      return false;
    }
  }
  if (o->width < 64 || o->height < 64 || o->board_free < 0 || o->repeat < 1 || o->seed == 0) {
    std::fprintf(
        stderr,
        "detectors_eval: --width/--height must be >= 64, --board-free >= 0, --repeat >= 1, "
        "--seed >= 1\n");
    return false;
  }
  return true;
}

}  // namespace
}  // namespace linecal

int main(int argc, char** argv) {
  linecal::Options options;
  if (!linecal::ParseArgs(argc, argv, &options)) return 2;
  return linecal::Run(options);
}

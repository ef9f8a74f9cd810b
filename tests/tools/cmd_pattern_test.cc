// `linecal boards` and `linecal pattern` run as programs: output, files and exit codes
// (docs/interfaces.md: 0 success, 2 bad usage or input with a one-line message).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "station/io/image_io.h"
#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

using testing_tools::RunLinecal;

class PatternCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("linecal_pattern_cli_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  std::filesystem::path dir_;
};

std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST_F(PatternCliTest, BoardsJsonListsAllBoards) {
  const auto run = RunLinecal("boards --json");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  const std::map<std::string, int> expected = {
      {"chessboard", 20},   {"circle", 30},     {"vertical", 51}, {"aruco", 16},
      {"apriltag", 144},    {"round_hole", 21}, {"checker", 54},  {"circle_grid", 54},
      {"square_grid", 216}, {"charuco", 40}};
  ASSERT_EQ(j.at("boards").size(), expected.size());
  for (const nlohmann::json& b : j.at("boards")) {
    const std::string name = b.at("name");
    ASSERT_TRUE(expected.count(name)) << name;
    EXPECT_EQ(b.at("feature_count").get<int>(), expected.at(name)) << name;
    EXPECT_GT(b.at("page_width_m").get<double>(), 0) << name;
    EXPECT_EQ(b.at("parameters").at("scale").get<double>(), 1.0) << name;
  }
  EXPECT_EQ(j.at("boards")[0].at("name"), "chessboard");
  EXPECT_DOUBLE_EQ(j.at("boards")[0].at("page_width_m").get<double>(), 2.6);
  EXPECT_EQ(j.at("boards")[0].at("feature_kinds").at("x_corner").get<int>(), 4);
  EXPECT_EQ(j.at("boards")[6].at("parameters").at("cols").get<int>(), 9);
  EXPECT_EQ(j.at("boards")[4].at("parameters").at("border_bits").get<int>(), 2);
  EXPECT_EQ(j.at("boards")[7].at("parameters").at("spacing_m").get<double>(), 0.025);
  EXPECT_FALSE(j.at("boards")[7].at("parameters").at("asymmetric").get<bool>());
  EXPECT_EQ(j.at("boards")[8].at("parameters").at("gap_m").get<double>(), 0.025);
  EXPECT_EQ(j.at("boards")[9].at("parameters").at("marker_m").get<double>(), 0.01875);

  const auto text = RunLinecal("boards");
  EXPECT_EQ(text.exit_code, 0);
  EXPECT_NE(text.out.find("round_hole"), std::string::npos);
  EXPECT_EQ(RunLinecal("boards --bogus").exit_code, 2);
}

TEST_F(PatternCliTest, SvgHasTheBoardSizeInMillimetres) {
  const auto run = RunLinecal("pattern --board vertical --out " + Path("v.svg"));
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const std::string svg = ReadText(Path("v.svg"));
  EXPECT_NE(svg.find("width=\"300mm\" height=\"1000mm\" viewBox=\"0 0 300 1000\""),
            std::string::npos);

  const auto scaled = RunLinecal(
      "pattern --board checker --cols 7 --rows 5 --square 0.03 "
      "--scale 2 --json --out " +
      Path("c.svg"));
  ASSERT_EQ(scaled.exit_code, 0) << scaled.err;
  // (7 + 3) x (5 + 3) squares of 2 x 30 mm.
  EXPECT_NE(ReadText(Path("c.svg")).find("width=\"600mm\" height=\"480mm\""), std::string::npos);
  const nlohmann::json j = nlohmann::json::parse(scaled.out);
  EXPECT_EQ(j.at("format"), "svg");
  EXPECT_DOUBLE_EQ(j.at("page_width_m").get<double>(), 0.6);
}

TEST_F(PatternCliTest, CircleGridPageHasItsMargin) {
  // OpenCV's 4 x 11 asymmetric grid at 20 mm: centres over 7 x 10 spacings, and two spacings
  // of margin on every side: 220 x 280 mm.
  const auto run = RunLinecal(
      "pattern --board circle_grid --cols 4 --rows 11 --spacing 0.02 --diameter 0.015 "
      "--asymmetric --json --out " +
      Path("g.svg"));
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const std::string svg = ReadText(Path("g.svg"));
  EXPECT_NE(svg.find("width=\"220mm\" height=\"280mm\""), std::string::npos);
  EXPECT_DOUBLE_EQ(nlohmann::json::parse(run.out).at("page_height_m").get<double>(), 0.28);
}

// BoofCV's 3 x 4 square grid drawn by `linecal pattern` and found by `linecal detect` on the
// drawing: all 48 corners with their ids where the drawing put them.
TEST_F(PatternCliTest, SquareGridPatternIsFoundByDetect) {
  const std::string board = "--board square_grid --cols 3 --rows 4 --square 0.03 --gap 0.03";
  const auto pattern = RunLinecal("pattern " + board + " --dpi 100 --json --out " + Path("g.png"));
  ASSERT_EQ(pattern.exit_code, 0) << pattern.err;
  // Squares over 150 x 210 mm, a 30 mm margin a side: 210 x 270 mm.
  const nlohmann::json page = nlohmann::json::parse(pattern.out);
  EXPECT_DOUBLE_EQ(page.at("page_width_m").get<double>(), 0.21);
  EXPECT_DOUBLE_EQ(page.at("page_height_m").get<double>(), 0.27);
  const auto detect = RunLinecal("detect " + board + " --json --image " + Path("g.png"));
  ASSERT_EQ(detect.exit_code, 0) << detect.err << detect.out;
  const nlohmann::json j = nlohmann::json::parse(detect.out);
  EXPECT_EQ(j.at("board"), "square_grid");
  EXPECT_EQ(j.at("found"), true);
  ASSERT_EQ(j.at("features").size(), 48u);
  // Corner (C, R) lies (30 + (C / 2) 60 + (C % 2) 30) mm from the page's left edge, likewise
  // from its top: at 100 dpi, 100 / 25.4 px per mm, less half a pixel (pixel centres).
  constexpr double kPxPerMm = 100.0 / 25.4;
  for (const nlohmann::json& f : j.at("features")) {
    const int id = f.at("id").get<int>();
    const int c = id % 6, r = id / 6;
    const double u = (30.0 + (c / 2) * 60.0 + (c % 2) * 30.0) * kPxPerMm - 0.5;
    const double v = (30.0 + (r / 2) * 60.0 + (r % 2) * 30.0) * kPxPerMm - 0.5;
    EXPECT_NEAR(f.at("u").get<double>(), u, 0.5) << id;
    EXPECT_NEAR(f.at("v").get<double>(), v, 0.5) << id;
  }
}

TEST_F(PatternCliTest, PngSizeIsDpiTimesBoardSize) {
  const auto run = RunLinecal("pattern --board aruco --dpi 50 --json --out " + Path("a.png"));
  ASSERT_EQ(run.exit_code, 0) << run.err;
  // 1.1 m at 50 dpi: 1.1 / 0.0254 * 50 = 2165.35 -> 2165 pixels.
  const absl::StatusOr<Image8> image = ReadImage8(Path("a.png"));
  ASSERT_TRUE(image.ok()) << image.status();
  EXPECT_EQ(image->width, 2165);
  EXPECT_EQ(image->height, 2165);
  const nlohmann::json j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j.at("width_px").get<int>(), 2165);
  EXPECT_EQ(j.at("format"), "png");
  // pHYs: 50 dpi = 1968.5 px/m, written rounded.
  const std::string bytes = ReadText(Path("a.png"));
  const std::size_t at = bytes.find("pHYs");
  ASSERT_NE(at, std::string::npos);
  const auto byte = [&](std::size_t i) {
    return static_cast<std::uint32_t>(static_cast<std::uint8_t>(bytes[i]));
  };
  EXPECT_EQ((byte(at + 4) << 24) | (byte(at + 5) << 16) | (byte(at + 6) << 8) | byte(at + 7),
            1969u);
  // Black marker border and white page where expected: the top marker's top-left corner is
  // at PDF (434, 130) mm, i.e. pixel (434, 130) * 50 / 25.4.
  EXPECT_EQ(image->at(static_cast<int>(440 * 50 / 25.4), static_cast<int>(136 * 50 / 25.4)), 0);
  EXPECT_EQ(image->at(static_cast<int>(420 * 50 / 25.4), static_cast<int>(120 * 50 / 25.4)), 255);

  // The default resolution, 150 dpi, with the 1-bit border AprilGrid: 841 x 1189 mm.
  const auto april = RunLinecal("pattern --board apriltag --border-bits 1 --out " + Path("t.png"));
  ASSERT_EQ(april.exit_code, 0) << april.err;
  const absl::StatusOr<Image8> tags = ReadImage8(Path("t.png"));
  ASSERT_TRUE(tags.ok());
  EXPECT_EQ(tags->width, static_cast<int>(std::lround(0.841 / 0.0254 * 150)));
  EXPECT_EQ(tags->height, static_cast<int>(std::lround(1.189 / 0.0254 * 150)));
}

TEST_F(PatternCliTest, BadUsageExitsWithTwoAndOneLine) {
  const struct {
    std::string args;
    std::string message;
  } cases[] = {
      {"pattern --out " + Path("x.svg"), "--board or --target is required"},
      {"pattern --board nope --out " + Path("x.svg"), "unknown board 'nope'"},
      {"pattern --board aruco", "missing --out"},
      {"pattern --board aruco --out " + Path("x.txt"), "must end in .svg or .png"},
      {"pattern --board aruco --cols 5 --out " + Path("x.svg"),
       "--cols applies to --board checker or circle_grid or square_grid or charuco only, not "
       "aruco"},
      {"pattern --board checker --spacing 0.02 --out " + Path("x.svg"),
       "--spacing applies to --board circle_grid only, not checker"},
      {"pattern --board circle_grid --square 0.02 --out " + Path("x.svg"),
       "--square applies to --board checker or square_grid or charuco only, not circle_grid"},
      {"pattern --board checker --gap 0.02 --out " + Path("x.svg"),
       "--gap applies to --board square_grid only, not checker"},
      {"pattern --board square_grid --gap 0 --out " + Path("x.svg"),
       "--gap: 0 m is outside (0, 1]"},
      {"pattern --board circle_grid --diameter 0.03 --out " + Path("x.svg"),
       "--diameter: 0.03 m must be > 0 and below"},
      {"pattern --board circle_grid --spacing 0 --out " + Path("x.svg"), "--spacing: 0 m"},
      {"pattern --board aruco --border-bits 1 --out " + Path("x.svg"), "--border-bits applies"},
      {"pattern --board apriltag --border-bits 3 --out " + Path("x.svg"), "--border-bits: 3"},
      {"pattern --board checker --cols 1 --out " + Path("x.svg"), "--cols: 1 is outside"},
      {"pattern --board checker --square -1 --out " + Path("x.svg"), "--square"},
      {"pattern --board aruco --scale 0 --out " + Path("x.svg"), "--scale: 0"},
      {"pattern --board aruco --dpi 100 --out " + Path("x.svg"), "--dpi applies to .png"},
      {"pattern --board aruco --dpi abc --out " + Path("x.png"), "--dpi: 'abc'"},
      {"pattern --board chessboard --dpi 600 --out " + Path("x.png"), "use --dpi 160 or less"},
      {"pattern --board aruco --out " + Path("no/such/dir/x.svg"), "cannot create"},
  };
  for (const auto& c : cases) {
    const auto run = RunLinecal(c.args);
    EXPECT_EQ(run.exit_code, 2) << c.args;
    EXPECT_NE(run.err.find(c.message), std::string::npos) << c.args << "\n" << run.err;
    EXPECT_EQ(std::count(run.err.begin(), run.err.end(), '\n'), 1) << run.err;
  }
  EXPECT_FALSE(std::filesystem::exists(Path("x.png")));
}

// BoofCV's hexagonal grid drawn by `linecal pattern` and found in the drawing by `linecal
// detect`: 12 zig-zag columns, 9 rows (54 circles of 20 mm, neighbours 24 mm apart), at 100
// dpi. The centres span 5.5 x 4 sqrt(3) spacings, the page two more on every side.
TEST_F(PatternCliTest, HexagonalCircleGridIsDrawnAndFound) {
  const std::string board =
      "--board circle_grid --cols 12 --rows 9 --spacing 0.024 --diameter 0.02 --hexagonal";
  const auto drawn = RunLinecal("pattern " + board + " --dpi 100 --json --out " + Path("h.png"));
  ASSERT_EQ(drawn.exit_code, 0) << drawn.err;
  const nlohmann::json page = nlohmann::json::parse(drawn.out);
  EXPECT_NEAR(page.at("page_width_m").get<double>(), 0.024 * 9.5, 1e-12);
  EXPECT_NEAR(page.at("page_height_m").get<double>(), 0.024 * (4.0 * std::sqrt(3.0) + 4.0), 1e-12);

  const auto found = RunLinecal("detect " + board + " --image " + Path("h.png") + " --json");
  ASSERT_EQ(found.exit_code, 0) << found.err << found.out;
  const nlohmann::json j = nlohmann::json::parse(found.out);
  EXPECT_EQ(j.at("found"), true);
  ASSERT_EQ(j.at("features").size(), 54u);
  // Circle id k of row i (6 a row, from the top) on zig-zag column 2 k' + (8 - i) % 2: its
  // centre two spacings plus c / 2 spacings from the page's left and two plus i sqrt(3) / 2
  // from its top, at 100 / 25.4 px per mm (pixel centres at integers).
  constexpr double kPxPerM = 100.0 / 0.0254;
  for (const nlohmann::json& f : j.at("features")) {
    const int id = f.at("id").get<int>();
    const int i = id / 6, c = 2 * (id % 6) + (8 - i) % 2;
    const double u = (2.0 + 0.5 * c) * 0.024 * kPxPerM - 0.5;
    const double v = (2.0 + 0.5 * std::sqrt(3.0) * i) * 0.024 * kPxPerM - 0.5;
    EXPECT_NEAR(f.at("u").get<double>(), u, 0.1) << id;
    EXPECT_NEAR(f.at("v").get<double>(), v, 0.1) << id;
  }

  // The layouts exclude each other, the flag is the circle grid's, and a hexagonal grid has
  // three rows and columns at least.
  const struct {
    std::string args;
    std::string message;
  } bad[] = {
      {"--board circle_grid --hexagonal --asymmetric",
       "--hexagonal: a grid is hexagonal or asymmetric, not both"},
      {"--board checker --hexagonal", "--hexagonal applies to --board circle_grid only"},
      {"--board circle_grid --hexagonal --cols 2", "--cols: 2 is outside [3, 100]"},
      {"--board circle_grid --hexagonal --rows 2", "--rows: 2 is outside [3, 100]"},
  };
  for (const auto& c : bad) {
    const auto run = RunLinecal("pattern " + c.args + " --out " + Path("x.svg"));
    EXPECT_EQ(run.exit_code, 2) << c.args;
    EXPECT_NE(run.err.find(c.message), std::string::npos) << c.args << "\n" << run.err;
  }
}

// A ChArUco board drawn by `linecal pattern` is found by `linecal detect` with every corner
// where the drawing puts it: OpenCV's ids, row-major from the top-left.
TEST_F(PatternCliTest, CharucoPatternIsDetectedWithItsCornerIds) {
  const std::string board = "--board charuco --cols 5 --rows 4 --square 0.03 --marker 0.022";
  for (const bool legacy : {false, true}) {
    SCOPED_TRACE(legacy ? "legacy" : "current");
    const std::string flags = board + (legacy ? " --legacy-pattern" : "");
    const auto drawn = RunLinecal("pattern " + flags + " --dpi 100 --out " + Path("c.png"));
    ASSERT_EQ(drawn.exit_code, 0) << drawn.err;
    const auto run = RunLinecal("detect " + flags + " --json --image " + Path("c.png"));
    ASSERT_EQ(run.exit_code, 0) << run.err;
    const nlohmann::json j = nlohmann::json::parse(run.out);
    EXPECT_TRUE(j.at("found").get<bool>());
    EXPECT_TRUE(j.at("complete").get<bool>());
    const nlohmann::json& features = j.at("features");
    ASSERT_EQ(features.size(), 12u);  // (5 - 1) x (4 - 1)
    // 30 mm squares at 100 dpi, one square of margin: inner corner (row r, col c) of the
    // drawing at ((c + 2) * 30, (r + 2) * 30) mm from the page's top-left, pixel centres at
    // half a pixel.
    const double px_per_mm = 100.0 / 25.4;
    for (int id = 0; id < 12; ++id) {
      const nlohmann::json& f = features[id];
      EXPECT_EQ(f.at("id").get<int>(), id);
      const int r = id / 4;
      const int c = id % 4;
      EXPECT_NEAR(f.at("u").get<double>(), (c + 2) * 30.0 * px_per_mm - 0.5, 0.05) << id;
      EXPECT_NEAR(f.at("v").get<double>(), (r + 2) * 30.0 * px_per_mm - 0.5, 0.05) << id;
    }
  }
  // The legacy pattern of an even row count is another board: the current one is not found
  // in its drawing (the markers sit in the other squares).
  const auto drawn = RunLinecal("pattern " + board + " --legacy-pattern --out " + Path("l.png"));
  ASSERT_EQ(drawn.exit_code, 0) << drawn.err;
  const auto other = RunLinecal("detect " + board + " --json --image " + Path("l.png"));
  EXPECT_EQ(other.exit_code, 1) << other.err;
  EXPECT_TRUE(nlohmann::json::parse(other.out).at("features").empty());

  const auto bad = RunLinecal("pattern " + board.substr(0, board.find(" --marker")) +
                              " --marker 0.03 --out " + Path("b.png"));
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("--marker"), std::string::npos) << bad.err;
  EXPECT_EQ(RunLinecal("pattern --board checker --marker 0.01 --out " + Path("b.png")).exit_code,
            2);
}

// --dictionary: the board drawn with OpenCV's DICT_6X6_250 is found with that flag, every
// corner with its id; read as the default DICT_4X4_50 board, nothing. Errors name the flag and
// the value.
TEST_F(PatternCliTest, CharucoDictionaryFlagDrawsAndDetectsThatDictionary) {
  const std::string board = "--board charuco --cols 5 --rows 4 --square 0.03 --marker 0.024";
  const std::string flags = board + " --dictionary DICT_6X6_250";
  const auto drawn = RunLinecal("pattern " + flags + " --dpi 150 --out " + Path("d.png"));
  ASSERT_EQ(drawn.exit_code, 0) << drawn.err;
  const auto run = RunLinecal("detect " + flags + " --json --image " + Path("d.png"));
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  EXPECT_TRUE(j.at("complete").get<bool>());
  ASSERT_EQ(j.at("features").size(), 12u);
  for (int id = 0; id < 12; ++id) EXPECT_EQ(j.at("features")[id].at("id").get<int>(), id);
  const auto other = RunLinecal("detect " + board + " --json --image " + Path("d.png"));
  EXPECT_EQ(other.exit_code, 1) << other.err;
  EXPECT_TRUE(nlohmann::json::parse(other.out).at("features").empty());

  const struct {
    std::string args;
    std::string message;
  } errors[] = {
      {board + " --dictionary DICT_5X5_60",
       "--dictionary: unknown dictionary 'DICT_5X5_60' (one of DICT_4X4_50, DICT_4X4_100"},
      {"--board charuco --cols 15 --rows 14 --dictionary DICT_6X6_100",
       "--dictionary: DICT_6X6_100 has 100 markers; 15 x 14 squares hold 105"},
      {"--board checker --dictionary DICT_6X6_100",
       "--dictionary applies to --board charuco only, not checker"},
  };
  for (const auto& e : errors) {
    const auto bad = RunLinecal("pattern " + e.args + " --out " + Path("b.png"));
    EXPECT_EQ(bad.exit_code, 2) << e.args;
    EXPECT_NE(bad.err.find(e.message), std::string::npos) << e.args << "\n" << bad.err;
  }
}

}  // namespace
}  // namespace linecal

// `linecal pattern` and `linecal detect` with `--target FILE`, Kalibr's target YAML
// (tools/linecal/target_file.h), run as programs on real files: each kind of file gives the
// same board as its flags, the board is found on its own printed page, and every bad file
// exits 2 with one line naming the file and the key.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

using testing_tools::RunLinecal;

class TargetCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("linecal_target_cli_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  // Writes `text` to a file of the test's folder; returns its path.
  std::string Write(const std::string& name, const std::string& text) const {
    const std::string path = (dir_ / name).string();
    std::ofstream(path) << text;
    return path;
  }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  std::filesystem::path dir_;
};

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Kalibr's own examples, comments and quoting as Kalibr's documentation writes them.
constexpr char kCheckerboard[] =
    "target_type: 'checkerboard' #gridtype\n"
    "targetCols: 6               #number of internal chessboard corners\n"
    "targetRows: 7               #number of internal chessboard corners\n"
    "rowSpacingMeters: 0.03      #size of one chessboard square [m]\n"
    "colSpacingMeters: 0.03      #size of one chessboard square [m]\n";
constexpr char kCircleGrid[] =
    "target_type: 'circlegrid' #gridtype\n"
    "targetCols: 4             #number of internal circles\n"
    "targetRows: 11            #number of internal circles\n"
    "spacingMeters: 0.02       #distance between circles [m]\n"
    "asymmetricGrid: True      #use asymmetric grid (opencv) [bool]\n";
constexpr char kAprilGrid[] =
    "target_type: 'aprilgrid' #gridtype\n"
    "tagCols: 6               #number of apriltags\n"
    "tagRows: 6               #number of apriltags\n"
    "tagSize: 0.044           #size of apriltag, edge to edge [m]\n"
    "tagSpacing: 0.3          #ratio of space between tags to tagSize\n";

// Another size, gap and first id, as a Kalibr user's own grid may have.
constexpr char kAprilGrid43[] =
    "target_type: 'aprilgrid'\n"
    "tagCols: 4\n"
    "tagRows: 3\n"
    "tagSize: 0.044\n"
    "tagSpacing: 0.25\n"
    "tagStartId: 100\n";

struct SameBoard {
  const char* name;
  const char* yaml;
  const char* flags;  // the same board as --board flags
  int features;
};

TEST_F(TargetCliTest, EachKindDrawsTheBoardOfItsFlagsAndIsFoundOnIt) {
  const std::vector<SameBoard> cases = {
      {"checkerboard", kCheckerboard, "--board checker --cols 6 --rows 7 --square 0.03", 42},
      {"circlegrid", kCircleGrid,
       "--board circle_grid --cols 4 --rows 11 --spacing 0.02 --diameter 0.01 --asymmetric", 44},
      {"aprilgrid", kAprilGrid, "--board apriltag --scale 0.5", 144},
      {"aprilgrid43", kAprilGrid43,
       "--board apriltag --scale 0.5 --tag-cols 4 --tag-rows 3 --tag-spacing 0.25 --start-id 100",
       48},
  };
  for (const SameBoard& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string yaml = Write(std::string(c.name) + ".yaml", c.yaml);
    const auto from_file = RunLinecal("pattern --target '" + yaml + "' --dpi 100 --out '" +
                                      Path("file.png") + "' --json");
    ASSERT_EQ(from_file.exit_code, 0) << from_file.err;
    const auto from_flags = RunLinecal(std::string("pattern ") + c.flags + " --dpi 100 --out '" +
                                       Path("flags.png") + "' --json");
    ASSERT_EQ(from_flags.exit_code, 0) << from_flags.err;
    nlohmann::json a = nlohmann::json::parse(from_file.out);
    nlohmann::json b = nlohmann::json::parse(from_flags.out);
    a.erase("out");
    b.erase("out");
    EXPECT_EQ(a, b);
    EXPECT_EQ(ReadBytes(Path("file.png")), ReadBytes(Path("flags.png")));

    const auto detected =
        RunLinecal("detect --target '" + yaml + "' --image '" + Path("file.png") + "' --json");
    ASSERT_EQ(detected.exit_code, 0) << detected.err;
    const nlohmann::json d = nlohmann::json::parse(detected.out);
    EXPECT_TRUE(d.at("found").get<bool>());
    EXPECT_EQ(d.at("features").size(), static_cast<std::size_t>(c.features));
  }
}

TEST_F(TargetCliTest, TheFileSetsTheFeaturePositions) {
  const std::string yaml = Write("checkerboard.yaml", kCheckerboard);
  ASSERT_EQ(RunLinecal("pattern --target '" + yaml + "' --dpi 100 --out '" + Path("p.png") + "'")
                .exit_code,
            0);
  const auto run =
      RunLinecal("detect --target '" + yaml + "' --image '" + Path("p.png") + "' --json");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json f = nlohmann::json::parse(run.out).at("features");
  // Neighbours along a row are one 30 mm square apart in the board frame.
  EXPECT_NEAR(f[1].at("x").get<double>() - f[0].at("x").get<double>(), 0.03, 1e-12);
  EXPECT_NEAR(f[0].at("y").get<double>() - f[6].at("y").get<double>(), 0.03, 1e-12);
}

struct BadFile {
  const char* name;
  const char* yaml;     // nullptr: the file does not exist
  const char* extra;    // further flags
  const char* message;  // what stderr says after "linecal detect: "
};

TEST_F(TargetCliTest, BadFilesExitTwoNamingTheFileAndTheKey) {
  const std::vector<BadFile> cases = {
      {"missing.yaml", nullptr, "", "missing.yaml: no such file"},
      {"notyaml.yaml", "a: [\n", "", "notyaml.yaml: not YAML (line 2"},
      {"list.yaml", "- 1\n- 2\n", "", "list.yaml: not a YAML map"},
      {"notype.yaml", "targetCols: 6\n", "", "notype.yaml: target_type: missing"},
      {"type.yaml", "target_type: 'charuco'\n", "",
       "type.yaml: target_type: 'charuco' is not checkerboard, circlegrid or aprilgrid"},
      {"cols.yaml", "target_type: checkerboard\ntargetCols: six\n", "",
       "cols.yaml: targetCols: 'six' is not a whole number"},
      {"rows.yaml", "target_type: checkerboard\ntargetCols: 6\n", "",
       "rows.yaml: targetRows: missing"},
      {"range.yaml",
       "target_type: checkerboard\ntargetCols: 1\ntargetRows: 7\nrowSpacingMeters: 0.03\n"
       "colSpacingMeters: 0.03\n",
       "", "range.yaml: targetCols: 1 is outside [2, 100]"},
      {"oblong.yaml",
       "target_type: checkerboard\ntargetCols: 6\ntargetRows: 7\nrowSpacingMeters: 0.03\n"
       "colSpacingMeters: 0.04\n",
       "", "oblong.yaml: colSpacingMeters: 0.04 differs from rowSpacingMeters 0.03"},
      {"nan.yaml", "target_type: circlegrid\ntargetCols: 4\ntargetRows: 5\nspacingMeters: .nan\n",
       "", "nan.yaml: spacingMeters: not a finite number"},
      {"bool.yaml",
       "target_type: circlegrid\ntargetCols: 4\ntargetRows: 5\nspacingMeters: 0.02\n"
       "asymmetricGrid: maybe\n",
       "", "bool.yaml: asymmetricGrid: 'maybe' is not a boolean"},
      {"grid.yaml",
       "target_type: aprilgrid\ntagCols: 0\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n", "",
       "grid.yaml: tagCols: 0 x 6 tags: each in [1, 50], two tags at least"},
      {"gap.yaml",
       "target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.01\n", "",
       "gap.yaml: tagSpacing: 0.01 is outside [0.05, 1]"},
      {"start.yaml",
       "target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n"
       "tagStartId: 560\n",
       "", "start.yaml: tagStartId: 560: ids 560..595 must lie in tag36h11's 0..586"},
      {"tiny.yaml",
       "target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.00001\ntagSpacing: 0.3\n", "",
       "tiny.yaml: tagSize: 1e-05 m is outside [8.8e-05, 8.8] m"},
      {"mixed.yaml", kCheckerboard, "--cols 5",
       "--cols cannot be combined with --target (the file gives the board)"},
      {"diameter.yaml", kCheckerboard, "--diameter 0.01",
       "--diameter applies to a circle_grid only;"},
      {"big.yaml", kCircleGrid, "--diameter 0.05",
       "--diameter: 0.05 m must be > 0 and below the nearest circles' distance"},
  };
  const std::string image = Path("any.png");
  ASSERT_EQ(RunLinecal("pattern --board checker --dpi 20 --out '" + image + "'").exit_code, 0);
  for (const BadFile& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string path = c.yaml == nullptr ? Path(c.name) : Write(c.name, c.yaml);
    const auto run =
        RunLinecal("detect --target '" + path + "' " + c.extra + " --image '" + image + "'");
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find(c.message), std::string::npos) << run.err;
    EXPECT_EQ(std::count(run.err.begin(), run.err.end(), '\n'), 1) << run.err;
  }
  const auto neither = RunLinecal("detect --image '" + image + "'");
  EXPECT_EQ(neither.exit_code, 2);
  EXPECT_NE(neither.err.find("--board or --target is required"), std::string::npos);
}

}  // namespace
}  // namespace linecal

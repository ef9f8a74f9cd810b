// linecal plant migrate / cycles / yield / export through the built binary, against a real
// PostgreSQL 15 holding the data set of tests/support/plant_data_set.h: the numbers and ids
// of the table and JSON outputs, and the errors that name a flag or the server.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "daemon/plant/plant_db.h"
#include "tests/support/plant_data_set.h"
#include "tests/support/postgres_test.h"
#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

using testing_support::PostgresCluster;
using testing_tools::LinecalRun;
using testing_tools::RunLinecal;

class CmdPlantTest : public testing_support::PostgresTest {
 protected:
  void SetUp() override {
    PostgresTest::SetUp();
    if (IsSkipped() || HasFatalFailure()) return;
    // Through the environment: the superuser's password holds quotes and spaces.
    setenv("LINECAL_PLANT_DSN", cluster_->Dsn("plant").c_str(), 1);
  }
  void TearDown() override { unsetenv("LINECAL_PLANT_DSN"); }

  // Migrates (through the command) and loads the data set.
  void Load() {
    ASSERT_EQ(RunLinecal("plant migrate").exit_code, 0);
    absl::StatusOr<std::unique_ptr<PlantDb>> db = PlantDb::Connect(cluster_->Dsn("plant"));
    ASSERT_TRUE(db.ok()) << db.status();
    for (const testing_support::StationBatch& b : testing_support::PlantDataSet()) {
      ASSERT_TRUE((*db)->ApplyBatch(b.station_id, b.cycles).ok());
    }
  }
};

std::vector<std::string> Lines(const std::string& text) {
  return absl::StrSplit(text, '\n', absl::SkipEmpty());
}

TEST_F(CmdPlantTest, MigrateCreatesTheSchemaThenHasNothingToDo) {
  const std::string server = absl::StrCat("127.0.0.1:", cluster_->port());
  LinecalRun run = RunLinecal("plant migrate");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(run.out, absl::StrCat("plant database ", server, ": schema version 0 -> 2\n"));
  run = RunLinecal("plant migrate --json");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j["schema_version_before"], 2);
  EXPECT_EQ(j["schema_version"], 2);
  EXPECT_EQ(j["server"], server);
  run = RunLinecal("plant migrate");
  EXPECT_EQ(run.out, absl::StrCat("plant database ", server, ": schema version 2, up to date\n"));
}

TEST_F(CmdPlantTest, CyclesListsEveryAttemptNewestFirst) {
  Load();
  LinecalRun run = RunLinecal("plant cycles --vin VIN1 --json");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  ASSERT_EQ(j.size(), 3u);
  const std::vector<std::pair<std::string, int>> expected = {
      {"eol-2", 1}, {"eol-1", 3}, {"eol-1", 2}};
  for (size_t i = 0; i < expected.size(); ++i) {
    EXPECT_EQ(j[i]["station_id"], expected[i].first) << i;
    EXPECT_EQ(j[i]["cycle_id"], expected[i].second) << i;
  }
  EXPECT_EQ(j[2]["verdict"], "fail");
  EXPECT_EQ(j[2]["reason"], "yaw_out_of_tolerance");
  EXPECT_EQ(j[2]["started"], "2026-11-02T09:00:00+00:00");
  EXPECT_EQ(j[2]["request"]["vin"], "VIN1");
  ASSERT_EQ(j[2]["sensors"].size(), 2u);
  EXPECT_EQ(j[2]["sensors"][0]["sensor"], "front_camera");
  EXPECT_EQ(j[2]["sensors"][0]["verdict"], "fail");
  EXPECT_EQ(j[2]["sensors"][0]["measured"]["roll_deg"], 2.0 / 3.0);
  EXPECT_EQ(j[2]["sensors"][0]["ranging"]["board_m"], 5.0);
  EXPECT_EQ(j[2]["sensors"][0]["T_car_sensor"].size(), 16u);

  run = RunLinecal("plant cycles --vin VIN1");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const std::vector<std::string> lines = Lines(run.out);
  ASSERT_EQ(lines.size(), 4u) << run.out;
  EXPECT_EQ(lines[1].substr(0, 21), "eol-2               1");
  EXPECT_NE(lines[1].find("2026-11-02 14:00:00  VIN1"), std::string::npos) << lines[1];
  EXPECT_NE(lines[3].find("fail    yaw_out_of_tolerance; front_camera:fail(yaw_out_of_tolerance) "
                          "roof_lidar:pass"),
            std::string::npos)
      << lines[3];

  run = RunLinecal("plant cycles --vin NOBODY");
  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(Lines(run.out).size(), 1u);  // the header only
}

TEST_F(CmdPlantTest, YieldCountsFirstAttemptsPerStationModelAndSensor) {
  Load();
  LinecalRun run = RunLinecal("plant yield --since 2026-11-02 --json");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j["since"], "2026-11-02T00:00:00+00:00");
  std::vector<std::string> rows;
  for (const nlohmann::json& r : j["yield"]) {
    rows.push_back(absl::StrCat(r["station_id"].get<std::string>(), " ",
                                r["car_model_id"].get<std::string>(), " ",
                                r["sensor"].get<std::string>(), " ", r["passed"].get<int>(), "/",
                                r["first_attempts"].get<int>()));
  }
  // 2026-11-02 00:00 is before the data set's kPlantT0Ns, and eol-1 #1 is from the day before.
  EXPECT_EQ(rows, testing_support::PlantDataSetYieldRows());
  EXPECT_NEAR(j["yield"][2]["yield_percent"].get<double>(), 200.0 / 3.0, 1e-9);
  ASSERT_EQ(j["failure_reasons"].size(), 3u);
  EXPECT_EQ(j["failure_reasons"][0]["reason"], "yaw_out_of_tolerance");
  EXPECT_EQ(j["failure_reasons"][0]["count"], 2);

  run = RunLinecal("plant yield --since 2026-11-02T08:00:00Z --station eol-1 --top 1");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const std::vector<std::string> lines = Lines(run.out);
  ASSERT_EQ(lines.size(), 9u) << run.out;
  EXPECT_EQ(lines[0], "first-pass yield since 2026-11-02 08:00:00 UTC");
  EXPECT_EQ(lines[2],
            "eol-1        model-a      (cycle)                           3       1   33.3%");
  EXPECT_EQ(lines[4],
            "eol-1        model-a      roof_lidar                        3       2   66.7%");
  // --top 1 at eol-1: board_not_found and yaw_out_of_tolerance tie at 1; by name.
  EXPECT_EQ(lines[7], "front_camera         board_not_found                       1");
  EXPECT_EQ(lines[8], "roof_lidar           too_few_points                        1");

  run = RunLinecal("plant yield --since 2026-11-02 --car-model model-b --json");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(nlohmann::json::parse(run.out)["yield"].size(), 3u);
}

TEST_F(CmdPlantTest, ExportWritesCsvAndJson) {
  Load();
  LinecalRun run = RunLinecal("plant export --since 2026-11-02");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const std::vector<std::string> lines = Lines(run.out);
  ASSERT_EQ(lines.size(), 1u + 7 * 2) << run.out;  // header, 7 cycles of 2 sensors
  EXPECT_EQ(lines[0].substr(0, 60), "station_id,cycle_id,vin,car_model_id,state,verdict,reason,st");
  const std::vector<std::string> first = absl::StrSplit(lines[1], ',');
  ASSERT_GE(first.size(), 14u);
  EXPECT_EQ(first[0], "eol-1");
  EXPECT_EQ(first[1], "2");
  EXPECT_EQ(first[2], "VIN1");
  EXPECT_EQ(first[7], "2026-11-02T09:00:00+00:00");
  EXPECT_EQ(first[10], "front_camera");
  EXPECT_EQ(first[12], "fail");
  EXPECT_EQ(first[16], "0.66666666666666663");  // measured roll, all 17 digits
  EXPECT_EQ(lines.back().substr(0, 18), "eol-2,2,VIN4,model");

  run = RunLinecal("plant export --since 2026-11-02 --format json");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  ASSERT_EQ(j.size(), 7u);
  EXPECT_EQ(j[0]["station_id"], "eol-1");
  EXPECT_EQ(j[0]["cycle_id"], 2);
  EXPECT_EQ(j[6]["station_id"], "eol-2");
  EXPECT_EQ(j[6]["cycle_id"], 2);

  run = RunLinecal("plant export --since 2026-11-02 --limit 2 --format json");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(nlohmann::json::parse(run.out).size(), 2u);
  EXPECT_NE(run.err.find("stopped at --limit 2 cycles"), std::string::npos) << run.err;
}

TEST_F(CmdPlantTest, ErrorsNameTheFlagOrTheServerNeverThePassword) {
  const std::string server = absl::StrCat("127.0.0.1:", cluster_->port());
  LinecalRun run = RunLinecal("plant export --since yesterday");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("--since: 'yesterday'"), std::string::npos) << run.err;
  run = RunLinecal("plant export --since 2026-11-02 --format xml");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("--format: 'xml': must be csv or json"), std::string::npos) << run.err;
  run = RunLinecal("plant yield --since 2026-11-02 --top 0");
  EXPECT_NE(run.err.find("--top: '0'"), std::string::npos) << run.err;

  // Before the migration: the schema check says what to do.
  run = RunLinecal("plant cycles --vin V");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("run `linecal plant migrate`"), std::string::npos) << run.err;

  // A login role whose password comes from --password-file.
  ASSERT_EQ(RunLinecal("plant migrate").exit_code, 0);
  ASSERT_TRUE(cluster_
                  ->Psql(cluster_->Dsn("plant"),
                         "CREATE ROLE quality LOGIN PASSWORD 'q-pass-77' IN ROLE linecal_report")
                  .ok());
  const std::string password_file = absl::StrCat(cluster_->dir(), "/quality.pw");
  std::ofstream(password_file) << "q-pass-77\n";
  const std::string dsn =
      absl::StrCat("'host=127.0.0.1 port=", cluster_->port(), " dbname=plant user=quality'");
  run = RunLinecal(
      absl::StrCat("plant cycles --vin V --dsn ", dsn, " --password-file ", password_file));
  EXPECT_EQ(run.exit_code, 1) << run.err;  // connected, no such car
  run = RunLinecal(absl::StrCat("plant cycles --vin V --dsn ", dsn));
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find(server), std::string::npos) << run.err;
  run = RunLinecal(absl::StrCat("plant cycles --vin V --dsn ", dsn, " --password-file /nowhere"));
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("--password-file: "), std::string::npos) << run.err;

  // The server down: the message names it, not the password.
  ASSERT_TRUE(cluster_->Stop().ok());
  run = RunLinecal("plant yield --since 2026-11-02");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find(server), std::string::npos) << run.err;
  EXPECT_EQ(run.err.find(PostgresCluster::kSuperuserPassword), std::string::npos) << run.err;

  unsetenv("LINECAL_PLANT_DSN");
  run = RunLinecal("plant cycles --vin V");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("--dsn: not given and LINECAL_PLANT_DSN is not set"), std::string::npos)
      << run.err;
}

}  // namespace
}  // namespace linecal

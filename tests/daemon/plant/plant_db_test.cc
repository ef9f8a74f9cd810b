// The plant database client against a real PostgreSQL 15 (tests/support/postgres_cluster.h):
// migrations, ApplyBatch's round trip and idempotence, the roles, the reports' numbers, and
// the errors of a bad connection string or a server that is down.
#include "daemon/plant/plant_db.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "absl/time/clock.h"
#include "absl/time/time.h"
#include "tests/support/plant_data_set.h"
#include "tests/support/postgres_test.h"

namespace linecal {
namespace {

#define ASSERT_OK(expr)                                    \
  do {                                                     \
    const absl::Status status_ = (expr);                   \
    ASSERT_TRUE(status_.ok()) << #expr << ": " << status_; \
  } while (0)

using testing_support::kHourNs;
using testing_support::kPlantT0Ns;
using testing_support::MakePlantCycle;
using testing_support::PostgresCluster;

class PlantDbTest : public testing_support::PostgresTest {
 protected:
  std::unique_ptr<PlantDb> Connect(const std::string& dsn) {
    absl::StatusOr<std::unique_ptr<PlantDb>> db = PlantDb::Connect(dsn);
    EXPECT_TRUE(db.ok()) << db.status();
    return db.ok() ? *std::move(db) : nullptr;
  }
  // The superuser's connection, migrated.
  std::unique_ptr<PlantDb> Migrated() {
    std::unique_ptr<PlantDb> db = Connect(cluster_->Dsn("plant"));
    if (db != nullptr) {
      EXPECT_TRUE(db->Migrate().ok());
    }
    return db;
  }
  std::string Sql(const std::string& sql) {
    absl::StatusOr<std::string> out = cluster_->Psql(cluster_->Dsn("plant"), sql);
    EXPECT_TRUE(out.ok()) << out.status();
    return out.value_or("");
  }
  // "cycles|sensors|events" row counts.
  std::string Counts() {
    return Sql(
        "SELECT (SELECT count(*) FROM cycles) || '|' || (SELECT count(*) FROM "
        "sensor_results) || '|' || (SELECT count(*) FROM events)");
  }
};

YieldFilter Since(int64_t since_ns, const std::string& station = "") {
  YieldFilter filter;
  filter.since_ns = since_ns;
  filter.station_id = station;
  return filter;
}

// "station/cycle id" of each record, in order.
std::vector<std::string> Keys(const std::vector<PlantCycleRecord>& records) {
  std::vector<std::string> keys;
  for (const PlantCycleRecord& r : records) {
    keys.push_back(absl::StrCat(r.station_id, "/", r.cycle.id));
  }
  return keys;
}

PlantCycle Simple(int64_t id, const std::string& vin, int64_t started_ns) {
  return MakePlantCycle(id, vin, "model-a", started_ns,
                        {testing_support::FullSensor("cam", "camera", Verdict::kPass, "")});
}

TEST_F(PlantDbTest, MigratesAnEmptyDatabaseOnceAndChecksTheVersion) {
  std::unique_ptr<PlantDb> db = Connect(cluster_->Dsn("plant"));
  ASSERT_NE(db, nullptr);
  EXPECT_EQ(db->SchemaVersion().value_or(-1), 0);
  absl::Status check = db->CheckSchema();
  EXPECT_EQ(check.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(check.message().find("schema version 0 is older than this linecal's 2"),
            std::string::npos)
      << check;

  ASSERT_TRUE(db->Migrate().ok());
  EXPECT_EQ(db->SchemaVersion().value_or(-1), 2);
  EXPECT_TRUE(db->CheckSchema().ok());
  const std::string applied = Sql("SELECT version, applied_at FROM schema_migrations");
  EXPECT_EQ(Sql("SELECT string_agg(table_name, ',' ORDER BY table_name) FROM "
                "information_schema.tables WHERE table_schema = 'public'"),
            "board_results,cycles,events,schema_migrations,sensor_results,stations");

  // Again: nothing to do, nothing changed.
  ASSERT_TRUE(db->Migrate().ok());
  EXPECT_EQ(Sql("SELECT version, applied_at FROM schema_migrations"), applied);
}

TEST_F(PlantDbTest, MigratesAnOlderSchemaAndRefusesANewerOne) {
  // Older: the migrations table exists but no migration was applied (version 0).
  Sql("CREATE TABLE schema_migrations (version integer PRIMARY KEY, "
      "applied_at timestamptz NOT NULL DEFAULT now())");
  std::unique_ptr<PlantDb> db = Connect(cluster_->Dsn("plant"));
  ASSERT_NE(db, nullptr);
  EXPECT_EQ(db->SchemaVersion().value_or(-1), 0);
  ASSERT_TRUE(db->Migrate().ok());
  EXPECT_EQ(db->SchemaVersion().value_or(-1), 2);

  // Newer: a later linecal migrated to version 3.
  Sql("INSERT INTO schema_migrations (version) VALUES (3)");
  for (const absl::Status& s : {db->CheckSchema(), db->Migrate()}) {
    EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition);
    EXPECT_NE(s.message().find("schema version 3 is newer than this linecal's 2"),
              std::string::npos)
        << s;
    EXPECT_NE(s.message().find(absl::StrCat("127.0.0.1:", cluster_->port())), std::string::npos);
  }
  EXPECT_EQ(Sql("SELECT string_agg(version::text, ',' ORDER BY version) FROM schema_migrations"),
            "1,2,3");
}

TEST_F(PlantDbTest, ApplyBatchStoresEveryFieldAsGiven) {
  std::unique_ptr<PlantDb> db = Migrated();
  ASSERT_NE(db, nullptr);
  PlantCycle sent = MakePlantCycle(
      42, "WVWZZZ1JZXW000001", "model-a", kPlantT0Ns + 123456789,
      {testing_support::FullSensor("front_camera", "camera", Verdict::kFail, "yaw_bad"),
       testing_support::FullSensor("roof_lidar", "lidar", Verdict::kPass, "")});
  sent.cycle.state = CycleState::kAborted;
  sent.cycle.sensors[1].T_car_sensor.clear();  // not solved
  ASSERT_TRUE(db->ApplyBatch("eol-7", {sent}).ok());

  absl::StatusOr<std::vector<PlantCycleRecord>> got = db->CyclesByVin("WVWZZZ1JZXW000001");
  ASSERT_TRUE(got.ok()) << got.status();
  ASSERT_EQ(got->size(), 1u);
  const PlantCycleRecord& r = (*got)[0];
  EXPECT_EQ(r.station_id, "eol-7");
  const StoredCycle& c = r.cycle;
  EXPECT_EQ(c.id, 42);
  EXPECT_EQ(c.vin, sent.cycle.vin);
  EXPECT_EQ(c.car_model_id, "model-a");
  EXPECT_EQ(c.state, CycleState::kAborted);
  EXPECT_EQ(c.verdict, Verdict::kFail);
  EXPECT_EQ(c.reason, "yaw_bad");
  EXPECT_EQ(c.started_ns, kPlantT0Ns + 123456789);
  EXPECT_EQ(c.ended_ns, sent.cycle.ended_ns);
  EXPECT_EQ(c.capture_path, sent.cycle.capture_path);
  // jsonb keeps the value, not the spelling (key order, spaces).
  EXPECT_EQ(nlohmann::json::parse(c.request_json), nlohmann::json::parse(sent.cycle.request_json));
  ASSERT_EQ(c.sensors.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    StoredSensorResult expected = sent.cycle.sensors[i];
    const StoredSensorResult& actual = c.sensors[i];
    if (!expected.ranging_json.empty()) {
      EXPECT_EQ(nlohmann::json::parse(actual.ranging_json),
                nlohmann::json::parse(expected.ranging_json));
      expected.ranging_json = actual.ranging_json;
    }
    EXPECT_EQ(actual, expected) << "sensor " << expected.sensor;  // every double bit-exact
  }
  EXPECT_EQ(c.sensors[1].T_car_sensor.size(), 0u);
  EXPECT_FALSE(c.sensors[1].vanishing_point_u_px.has_value());
  const int64_t now_ns = absl::ToUnixNanos(absl::Now());
  EXPECT_GT(r.received_ns, now_ns - 60 * 1000000000LL);
  EXPECT_LE(r.received_ns, now_ns + 1000000000LL);

  EXPECT_EQ(Sql("SELECT sequence || ' ' || time_ns || ' ' || type || ' ' || detail || ' ' || "
                "verdict FROM events WHERE station_id = 'eol-7' ORDER BY sequence"),
            absl::StrCat("0 ", kPlantT0Ns + 123456789, " started aligner ok \n1 ",
                         sent.cycle.ended_ns, " cycle_ended yaw_bad fail"));
  EXPECT_EQ(Sql("SELECT started_at AT TIME ZONE 'UTC' FROM cycles"), "2026-11-02 08:00:00.123457");
}

// A version-1 database (one migrated and turned back: no board_results) with a cycle migrates
// to 2; the old cycle reads without boards, a new one with them.
TEST_F(PlantDbTest, MigratesSchemaOneToBoardResults) {
  std::unique_ptr<PlantDb> db = Migrated();
  ASSERT_NE(db, nullptr);
  ASSERT_OK(db->ApplyBatch("eol-7", {Simple(1, "VIN1", kPlantT0Ns)}));
  Sql("DROP TABLE board_results; DELETE FROM schema_migrations WHERE version = 2");
  EXPECT_EQ(db->SchemaVersion().value_or(-1), 1);
  ASSERT_OK(db->Migrate());
  EXPECT_EQ(db->SchemaVersion().value_or(-1), 2);
  ASSERT_OK(db->ApplyBatch("eol-7", {Simple(2, "VIN1", kPlantT0Ns + kHourNs)}));
  const std::vector<PlantCycleRecord> got = db->CyclesByVin("VIN1").value();
  ASSERT_EQ(got.size(), 2u);  // newest first
  ASSERT_EQ(got[1].cycle.sensors.size(), 1u);
  EXPECT_TRUE(got[1].cycle.sensors[0].boards.empty());
  EXPECT_EQ(got[0].cycle.sensors.at(0).boards, Simple(2, "VIN1", 0).cycle.sensors[0].boards);
}

TEST_F(PlantDbTest, ReapplyingChangesNothing) {
  std::unique_ptr<PlantDb> db = Migrated();
  ASSERT_NE(db, nullptr);
  const std::vector<PlantCycle> batch = {Simple(1, "A", kPlantT0Ns), Simple(2, "B", kPlantT0Ns + 1),
                                         Simple(3, "C", kPlantT0Ns + 2)};
  ASSERT_TRUE(db->ApplyBatch("eol-1", batch).ok());
  EXPECT_EQ(Counts(), "3|3|6");
  ASSERT_TRUE(db->ApplyBatch("eol-1", batch).ok());
  EXPECT_EQ(Counts(), "3|3|6");

  // A different copy of cycle 2 (and a duplicate inside the batch) next to a new cycle 4:
  // only cycle 4 is added; cycle 2 keeps its first copy, sensors and events included.
  PlantCycle changed = Simple(2, "B-changed", kPlantT0Ns + 99);
  changed.cycle.sensors.push_back(
      testing_support::FullSensor("extra", "radar", Verdict::kFail, "why"));
  changed.events.push_back(
      {2, 2, kPlantT0Ns + 100, EventType::kSensorProgress, "", "late", std::nullopt});
  ASSERT_TRUE(db->ApplyBatch("eol-1", {changed, Simple(4, "D", kPlantT0Ns + 3),
                                       Simple(4, "D-again", kPlantT0Ns + 4)})
                  .ok());
  EXPECT_EQ(Counts(), "4|4|8");
  EXPECT_EQ(Sql("SELECT vin FROM cycles WHERE cycle_id IN (2, 4) ORDER BY cycle_id"), "B\nD");
  EXPECT_EQ(Sql("SELECT count(*) FROM stations"), "1");
}

TEST_F(PlantDbTest, KeepsGapsOutOfOrderCyclesAndStationsApart) {
  std::unique_ptr<PlantDb> db = Migrated();
  ASSERT_NE(db, nullptr);
  ASSERT_TRUE(
      db->ApplyBatch("eol-1", {Simple(9, "X", kPlantT0Ns + 9), Simple(2, "X", kPlantT0Ns + 2),
                               Simple(5, "X", kPlantT0Ns + 5)})
          .ok());
  ASSERT_TRUE(db->ApplyBatch("eol-1", {Simple(1, "X", kPlantT0Ns + 1)}).ok());
  // The same cycle ids at another station are other cycles.
  ASSERT_TRUE(
      db->ApplyBatch("eol-2", {Simple(1, "X", kPlantT0Ns + 11), Simple(2, "X", kPlantT0Ns + 12)})
          .ok());
  ASSERT_TRUE(db->ApplyBatch("eol-3", {}).ok());  // registers the station only
  EXPECT_EQ(Counts(), "6|6|12");
  EXPECT_EQ(Sql("SELECT string_agg(station_id, ',' ORDER BY station_id) FROM stations"),
            "eol-1,eol-2,eol-3");

  absl::StatusOr<std::vector<PlantCycleRecord>> all = db->CyclesSince(kPlantT0Ns + 2, 1000);
  ASSERT_TRUE(all.ok()) << all.status();
  EXPECT_EQ(Keys(*all),
            (std::vector<std::string>{"eol-1/2", "eol-1/5", "eol-1/9", "eol-2/1", "eol-2/2"}));
  absl::StatusOr<std::vector<PlantCycleRecord>> two = db->CyclesSince(0, 2);
  ASSERT_TRUE(two.ok());
  ASSERT_EQ(two->size(), 2u);
  EXPECT_EQ((*two)[1].cycle.id, 2);
  EXPECT_EQ((*two)[1].cycle.sensors.size(), 1u);

  EXPECT_EQ(db->ApplyBatch("", {}).code(), absl::StatusCode::kInvalidArgument);
  PlantCycle running = Simple(10, "X", kPlantT0Ns);
  running.cycle.state = CycleState::kRunning;
  const absl::Status s = db->ApplyBatch("eol-1", {running});
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("cycle 10 is still running"), std::string::npos) << s;
  EXPECT_EQ(db->CyclesSince(0, 0).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(PlantDbTest, ReportsYieldAndAttemptsOfTheDataSet) {
  std::unique_ptr<PlantDb> db = Migrated();
  ASSERT_NE(db, nullptr);
  for (const testing_support::StationBatch& b : testing_support::PlantDataSet()) {
    ASSERT_TRUE(db->ApplyBatch(b.station_id, b.cycles).ok());
  }
  absl::StatusOr<std::vector<PlantCycleRecord>> vin1 = db->CyclesByVin("VIN1");
  ASSERT_TRUE(vin1.ok()) << vin1.status();
  EXPECT_EQ(Keys(*vin1), (std::vector<std::string>{"eol-2/1", "eol-1/3", "eol-1/2"}));

  absl::StatusOr<YieldReport> report = db->Yield(Since(kPlantT0Ns));
  ASSERT_TRUE(report.ok()) << report.status();
  std::vector<std::string> rows;
  for (const YieldRow& r : report->rows) {
    rows.push_back(absl::StrCat(r.station_id, " ", r.car_model_id, " ", r.sensor, " ", r.passed,
                                "/", r.first_attempts));
  }
  EXPECT_EQ(rows, testing_support::PlantDataSetYieldRows());
  std::vector<std::string> reasons;
  for (const FailureReason& f : report->reasons) {
    reasons.push_back(absl::StrCat(f.sensor, " ", f.reason, " ", f.count));
  }
  EXPECT_EQ(reasons, (std::vector<std::string>{"front_camera yaw_out_of_tolerance 2",
                                               "front_camera board_not_found 1",
                                               "roof_lidar too_few_points 1"}));

  YieldFilter filter = Since(kPlantT0Ns, "eol-2");
  filter.car_model_id = "model-b";
  filter.top_reasons = 1;
  report = db->Yield(filter);
  ASSERT_TRUE(report.ok());
  ASSERT_EQ(report->rows.size(), 3u);
  EXPECT_EQ(report->rows[0].car_model_id, "model-b");
  ASSERT_EQ(report->reasons.size(), 1u);
  EXPECT_EQ(report->reasons[0].reason, "yaw_out_of_tolerance");
  // Since the first hour's end: eol-1 #2 is out, and #3 is still not a first attempt.
  report = db->Yield(Since(kPlantT0Ns + kHourNs + 1, "eol-1"));
  ASSERT_TRUE(report.ok());
  ASSERT_FALSE(report->rows.empty());
  EXPECT_EQ(report->rows[0].first_attempts, 2);
  EXPECT_EQ(report->rows[0].passed, 1);
  filter.top_reasons = 0;
  EXPECT_EQ(db->Yield(filter).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(PlantDbTest, StationRoleOnlyAddsAndReportRoleOnlyReads) {
  std::unique_ptr<PlantDb> admin = Migrated();
  ASSERT_NE(admin, nullptr);
  Sql("CREATE ROLE station_7 LOGIN PASSWORD 'st-secret' IN ROLE linecal_station; "
      "CREATE ROLE quality LOGIN PASSWORD 'rp-secret' IN ROLE linecal_report");
  const std::string station_dsn = cluster_->Dsn("plant", "station_7", "st-secret");
  const std::string report_dsn = cluster_->Dsn("plant", "quality", "rp-secret");

  std::unique_ptr<PlantDb> station = Connect(station_dsn);
  ASSERT_NE(station, nullptr);
  EXPECT_TRUE(station->CheckSchema().ok());
  ASSERT_TRUE(station->ApplyBatch("eol-7", {Simple(1, "V", kPlantT0Ns)}).ok());
  ASSERT_TRUE(station->ApplyBatch("eol-7", {Simple(1, "V", kPlantT0Ns)}).ok());  // idempotent
  EXPECT_EQ(station->CyclesByVin("V").status().code(), absl::StatusCode::kPermissionDenied);
  for (const char* sql :
       {"DELETE FROM cycles", "UPDATE cycles SET verdict = 'pass'", "DELETE FROM sensor_results",
        "UPDATE events SET detail = ''", "TRUNCATE cycles", "SELECT vin FROM cycles",
        "CREATE TABLE sneaky (x int)"}) {
    absl::StatusOr<std::string> out = cluster_->Psql(station_dsn, sql);
    EXPECT_FALSE(out.ok()) << sql;
    EXPECT_NE(out.status().message().find("permission denied"), std::string::npos)
        << sql << ": " << out.status();
  }

  std::unique_ptr<PlantDb> report = Connect(report_dsn);
  ASSERT_NE(report, nullptr);
  EXPECT_TRUE(report->CheckSchema().ok());
  absl::StatusOr<std::vector<PlantCycleRecord>> read = report->CyclesByVin("V");
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->size(), 1u);
  EXPECT_TRUE(report->Yield(Since(0)).ok());
  const absl::Status write = report->ApplyBatch("eol-8", {Simple(1, "V", kPlantT0Ns)});
  EXPECT_EQ(write.code(), absl::StatusCode::kPermissionDenied) << write;
  for (const char* sql :
       {"INSERT INTO stations VALUES ('x')", "DELETE FROM cycles", "UPDATE cycles SET vin = 'x'"}) {
    absl::StatusOr<std::string> out = cluster_->Psql(report_dsn, sql);
    EXPECT_NE(out.status().message().find("permission denied"), std::string::npos)
        << sql << ": " << out.status();
  }
  EXPECT_EQ(Counts(), "1|1|2");
}

TEST_F(PlantDbTest, ConnectionErrorsNameTheServerAndNeverThePassword) {
  const std::string server = absl::StrCat("127.0.0.1:", cluster_->port());
  // A wrong password.
  absl::StatusOr<std::unique_ptr<PlantDb>> db =
      PlantDb::Connect(cluster_->Dsn("plant", "postgres", "wrong-pw-1234"));
  EXPECT_EQ(db.status().code(), absl::StatusCode::kPermissionDenied) << db.status();
  EXPECT_NE(db.status().message().find(server), std::string::npos) << db.status();
  EXPECT_EQ(db.status().message().find("wrong-pw-1234"), std::string::npos);
  // An unknown database.
  db = PlantDb::Connect(cluster_->Dsn("nowhere"));
  EXPECT_EQ(db.status().code(), absl::StatusCode::kNotFound) << db.status();
  // Malformed strings: InvalidArgument, without the password.
  db = PlantDb::Connect("host=127.0.0.1 password=hunter2 oops");
  EXPECT_EQ(db.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(db.status().message().find("hunter2"), std::string::npos) << db.status();
  db = PlantDb::Connect("host=127.0.0.1 colour=blue");
  EXPECT_EQ(db.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(db.status().message().find("colour"), std::string::npos) << db.status();

  // Connected, then the server goes down: Unavailable; back up: the same PlantDb works.
  std::unique_ptr<PlantDb> plant = Migrated();
  ASSERT_NE(plant, nullptr);
  ASSERT_OK(cluster_->Stop());
  absl::Status down = plant->ApplyBatch("eol-1", {Simple(1, "V", kPlantT0Ns)});
  EXPECT_EQ(down.code(), absl::StatusCode::kUnavailable) << down;
  EXPECT_NE(down.message().find(server), std::string::npos) << down;
  db = PlantDb::Connect(cluster_->Dsn("plant"));
  EXPECT_EQ(db.status().code(), absl::StatusCode::kUnavailable) << db.status();
  EXPECT_NE(db.status().message().find(server), std::string::npos) << db.status();
  EXPECT_EQ(db.status().message().find(PostgresCluster::kSuperuserPassword), std::string::npos);
  ASSERT_OK(cluster_->Start());
  ASSERT_TRUE(plant->ApplyBatch("eol-1", {Simple(1, "V", kPlantT0Ns)}).ok());

  // Killed (a crash): Unavailable, and after recovery the committed rows are all there.
  ASSERT_OK(cluster_->Kill());
  EXPECT_EQ(plant->ApplyBatch("eol-1", {Simple(2, "V", kPlantT0Ns)}).code(),
            absl::StatusCode::kUnavailable);
  ASSERT_OK(cluster_->Start());
  ASSERT_TRUE(plant->ApplyBatch("eol-1", {Simple(2, "V", kPlantT0Ns)}).ok());
  EXPECT_EQ(Counts(), "2|2|4");
}

TEST_F(PlantDbTest, AServerThatStopsAnsweringFailsTheCallInsteadOfHangingIt) {
  ASSERT_NE(Migrated(), nullptr);
  PlantDbOptions options;
  options.connect_timeout = std::chrono::milliseconds(2000);
  options.statement_timeout = std::chrono::milliseconds(250);
  absl::StatusOr<std::unique_ptr<PlantDb>> db = PlantDb::Connect(cluster_->Dsn("plant"), options);
  ASSERT_TRUE(db.ok()) << db.status();
  ASSERT_OK((*db)->ApplyBatch("eol-1", {Simple(1, "V", kPlantT0Ns)}));

  ASSERT_OK(cluster_->Pause());
  absl::Time start = absl::Now();
  const absl::Status stalled = (*db)->ApplyBatch("eol-1", {Simple(2, "V", kPlantT0Ns)});
  EXPECT_EQ(stalled.code(), absl::StatusCode::kUnavailable) << stalled;
  EXPECT_NE(stalled.message().find("no answer within 500 ms"), std::string::npos) << stalled;
  EXPECT_LT(absl::Now() - start, absl::Seconds(2));
  // Connecting: the kernel accepts, nobody answers; libpq's connect_timeout ends it.
  start = absl::Now();
  EXPECT_EQ(PlantDb::Connect(cluster_->Dsn("plant"), options).status().code(),
            absl::StatusCode::kUnavailable);
  EXPECT_LT(absl::Now() - start, absl::Seconds(5));

  ASSERT_OK(cluster_->Resume());
  ASSERT_OK((*db)->ApplyBatch("eol-1", {Simple(2, "V", kPlantT0Ns)}));
  EXPECT_EQ(Counts(), "2|2|4");
}

}  // namespace
}  // namespace linecal

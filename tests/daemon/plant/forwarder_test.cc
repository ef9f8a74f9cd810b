// The forwarder's parts that need no PostgreSQL: the retry schedule, the connection string it
// builds from linecald.json's `plant` section, and its behaviour with a plant that refuses
// every connection (a real loopback port with nothing listening): the cycles stay queued,
// the error is reported, and stopping does not wait on the plant.
#include "daemon/plant/forwarder.h"

#include <gtest/gtest.h>
#include <libpq-fe.h>

#include <chrono>
#include <map>
#include <string>
#include <thread>

#include "absl/strings/str_cat.h"
#include "tests/daemon/ended_cycle.h"
#include "tests/daemon/plant/tcp_proxy.h"
#include "tests/daemon/scratch_dir.h"

namespace linecal {
namespace {

using std::chrono::milliseconds;

// The options libpq reads from `conninfo`, by keyword (those set).
std::map<std::string, std::string> Parsed(const std::string& conninfo) {
  char* error = nullptr;
  PQconninfoOption* options = PQconninfoParse(conninfo.c_str(), &error);
  EXPECT_NE(options, nullptr) << (error ? error : "");
  PQfreemem(error);
  std::map<std::string, std::string> out;
  for (const PQconninfoOption* o = options; o != nullptr && o->keyword != nullptr; ++o) {
    if (o->val != nullptr) out[o->keyword] = o->val;
  }
  PQconninfoFree(options);
  return out;
}

TEST(RetryDelayTest, DoublesFromTheFirstIntervalUpToTheCapWithJitterInTheUpperHalf) {
  ForwarderOptions o;
  o.first_retry_interval = milliseconds(200);
  o.max_retry_interval = milliseconds(30000);
  EXPECT_EQ(RetryDelay(1, o, 1.0), milliseconds(200));
  EXPECT_EQ(RetryDelay(1, o, 0.0), milliseconds(100));
  EXPECT_EQ(RetryDelay(2, o, 1.0), milliseconds(400));
  EXPECT_EQ(RetryDelay(5, o, 0.5), milliseconds(2400));  // 3200 * 0.75
  EXPECT_EQ(RetryDelay(8, o, 1.0), milliseconds(25600));
  EXPECT_EQ(RetryDelay(9, o, 1.0), milliseconds(30000));  // capped
  EXPECT_EQ(RetryDelay(1000000, o, 0.0), milliseconds(15000));
}

TEST(PlantConnectionStringTest, KeepsTheDsnAddsTlsPasswordAndNetworkTimeouts) {
  PlantConfig c;
  c.dsn = "host=plant.example port=5433 dbname=linecal user=station keepalives_idle=30";
  c.password = "pa ss'\\word";
  c.tls = PlantTlsConfig{"verify-ca", "/etc/linecal/plant-ca.pem", "/c.pem", "/k.pem"};
  const absl::StatusOr<std::string> conninfo = PlantConnectionString(c);
  ASSERT_TRUE(conninfo.ok()) << conninfo.status();
  std::map<std::string, std::string> o = Parsed(*conninfo);
  EXPECT_EQ(o["host"], "plant.example");
  EXPECT_EQ(o["port"], "5433");
  EXPECT_EQ(o["dbname"], "linecal");
  EXPECT_EQ(o["user"], "station");
  EXPECT_EQ(o["password"], "pa ss'\\word");  // quoted so that libpq reads it back whole
  EXPECT_EQ(o["sslmode"], "verify-ca");
  EXPECT_EQ(o["sslrootcert"], "/etc/linecal/plant-ca.pem");
  EXPECT_EQ(o["sslcert"], "/c.pem");
  EXPECT_EQ(o["sslkey"], "/k.pem");
  EXPECT_EQ(o["keepalives"], "1");
  EXPECT_EQ(o["keepalives_idle"], "30");  // the DSN's own value wins
  EXPECT_EQ(o["tcp_user_timeout"], "10000");
}

TEST(PlantConnectionStringTest, ReadsUrisAndRefusesPasswordsAndGarbage) {
  PlantConfig c;
  c.dsn = "postgresql://station@plant.example:5433/linecal?sslmode=require";
  const absl::StatusOr<std::string> uri = PlantConnectionString(c);
  ASSERT_TRUE(uri.ok()) << uri.status();
  std::map<std::string, std::string> o = Parsed(*uri);
  EXPECT_EQ(o["host"], "plant.example");
  EXPECT_EQ(o["user"], "station");
  EXPECT_EQ(o["sslmode"], "require");
  EXPECT_EQ(o.count("password"), 0u);

  for (const char* dsn : {"host=h password=hunter2", "postgresql://station:hunter2@h/linecal"}) {
    c.dsn = dsn;
    const absl::StatusOr<std::string> refused = PlantConnectionString(c);
    EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument) << dsn;
    EXPECT_NE(refused.status().message().find("password_file or PGPASSWORD"), std::string::npos);
    EXPECT_EQ(refused.status().message().find("hunter2"), std::string::npos);
  }
  c.dsn = "host=h nonsense";
  EXPECT_EQ(PlantConnectionString(c).status().code(), absl::StatusCode::kInvalidArgument);
  c.dsn = "host=h no_such_option=1";
  EXPECT_EQ(PlantConnectionString(c).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(ForwarderTest, RefusedConnectionsKeepTheBacklogReportTheErrorAndStopAtOnce) {
  const std::filesystem::path dir = testing_daemon::FreshTestDir("linecal_forwarder");
  StoreOptions store_options;
  store_options.outbox = true;
  std::unique_ptr<Store> store = *Store::Open((dir / "station.db").string(), store_options);
  const int64_t now_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                             std::chrono::system_clock::now().time_since_epoch())
                             .count();
  for (int i = 0; i < 3; ++i) {
    const int64_t ended_ns = now_ns - 5'000'000'000 + i;
    ASSERT_NE(testing_daemon::EndCycleInStore(*store, ended_ns - 1, ended_ns), 0);
  }

  ForwarderOptions o;
  o.conninfo = absl::StrCat("host=127.0.0.1 port=", testing_plant::ClosedLoopbackPort(),
                            " dbname=linecal user=x");
  o.station_id = "line1";
  o.first_retry_interval = milliseconds(20);
  o.max_retry_interval = milliseconds(100);
  std::vector<std::string> log;
  std::mutex log_mutex;
  o.log = [&](const LogRecord& record) {
    std::lock_guard<std::mutex> lock(log_mutex);
    log.push_back(LogLevelName(record.level) + std::string(": ") + record.message);
  };
  absl::StatusOr<std::unique_ptr<Forwarder>> forwarder = Forwarder::Start(store.get(), o);
  ASSERT_TRUE(forwarder.ok()) << forwarder.status();
  // Several attempts (20, 40, 80, 100 ms apart at most): the error does not change.
  std::this_thread::sleep_for(milliseconds(500));
  const ForwarderStats stats = (*forwarder)->Stats();
  EXPECT_EQ(stats.backlog, 3);
  EXPECT_EQ(stats.shipped, 0);
  EXPECT_EQ(stats.last_error.code(), absl::StatusCode::kUnavailable) << stats.last_error;
  // Ended about 5 s ago; the test takes well under 5 s more.
  EXPECT_GE(stats.oldest_unshipped_age, std::chrono::seconds(5));
  EXPECT_LT(stats.oldest_unshipped_age, std::chrono::seconds(10));
  {
    std::lock_guard<std::mutex> lock(log_mutex);
    ASSERT_EQ(log.size(), 1u) << "one warning per change of error, not per attempt";
    EXPECT_EQ(log[0].rfind("warning: plant database: ", 0), 0u) << log[0];
  }
  const auto before = std::chrono::steady_clock::now();
  EXPECT_EQ((*forwarder)->Stop(before + std::chrono::seconds(5)), 3);
  // A drain with the plant down ends at its first failure, not at the deadline.
  EXPECT_LT(std::chrono::steady_clock::now() - before, std::chrono::seconds(2));
  EXPECT_EQ((*forwarder)->Stop(before), 3);  // again: at once
  // The backlog is still there for the next start, in order.
  const std::vector<OutboxEntry> queued = *store->ReadOutbox(10);
  ASSERT_EQ(queued.size(), 3u);
  EXPECT_LT(queued[0].cycle.id, queued[2].cycle.id);
  std::filesystem::remove_all(dir);
}

TEST(ForwarderTest, StartRefusesABadBatchOrStationId) {
  ForwarderOptions o;
  o.station_id = "line1";
  o.batch = 0;
  EXPECT_EQ(Forwarder::Start(nullptr, o).status().code(), absl::StatusCode::kInvalidArgument);
  o.batch = 10001;
  EXPECT_EQ(Forwarder::Start(nullptr, o).status().code(), absl::StatusCode::kInvalidArgument);
  o.batch = 10;
  o.station_id = "";
  EXPECT_EQ(Forwarder::Start(nullptr, o).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace linecal

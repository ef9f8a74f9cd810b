#pragma once
// The station's forwarder (docs/plant.md, "Forwarding"): one thread that ships the store's
// outbox (daemon/store/store.h) to the plant PostgreSQL database in queue order, in batches,
// through PlantDb::ApplyBatch, and removes each batch from the outbox once the plant has
// committed it. Delivery is at least once (a crash between the commit at the plant and the
// removal resends the batch) and the plant applies a cycle once (key: station id + cycle id),
// so every cycle arrives exactly once, in order per station.
//
// The station never waits on it: a cycle's end is one SQLite transaction (the outbox entry
// included); Notify() only wakes the thread. After a failure (server down, refusing, a lost
// connection, a schema older or newer than PlantDb::kSchemaVersion) the connection is dropped
// and the next attempt, which reconnects and checks the schema, comes after an exponential
// backoff with jitter bounded by max_retry_interval. Nothing queued is ever dropped.
//
// Thread safety: every method may be called from any thread.

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "daemon/log/daemon_log.h"
#include "daemon/plant/plant_db.h"
#include "daemon/store/store.h"

namespace linecal {

// The `plant` section of linecald.json (docs/daemon.md, "Plant database").
struct PlantTlsConfig {
  std::string mode = "verify-full";  // libpq sslmode: disable, require, verify-ca, verify-full
  std::string ca_path;               // sslrootcert; empty: libpq's default (~/.postgresql)
  std::string cert_path, key_path;   // sslcert, sslkey: a client certificate; both or neither
};

struct PlantConfig {
  // A libpq connection string or postgresql:// URI without a password.
  std::string dsn;
  std::string station_id;             // the station's name at the plant
  int batch = 100;                    // cycles per transaction at the plant
  std::optional<PlantTlsConfig> tls;  // absent: the DSN's own sslmode (libpq's default: prefer)
  // The password (the password_file's first line). Empty: PGPASSWORD or ~/.pgpass, as libpq
  // finds them. Never logged, never in a message.
  std::string password;
  // Health stays SERVING while the oldest unshipped cycle ended less than this long ago.
  std::chrono::seconds max_backlog_age{3600};
  // The longest wait between two attempts while the plant fails.
  std::chrono::milliseconds max_retry_interval{30000};
};

// The libpq connection string the forwarder connects with: `config.dsn`'s options, the tls
// section's sslmode/sslrootcert/sslcert/sslkey, the password, and TCP keepalives and
// tcp_user_timeout (10 s) unless the DSN sets them, so that a server host that vanished
// fails a call instead of hanging it. InvalidArgument saying why (the caller names the key)
// for a string libpq cannot parse (libpq's words, which quote at most a malformed fragment)
// or one holding a password (credentials belong in password_file or PGPASSWORD). Pure.
absl::StatusOr<std::string> PlantConnectionString(const PlantConfig& config);

struct ForwarderOptions {
  std::string conninfo;  // PlantConnectionString's
  std::string station_id;
  int batch = 100;  // 1..10000
  PlantDbOptions db;
  // The first retry waits about first_retry_interval, each next one twice as long, up to
  // max_retry_interval; each wait is drawn uniformly from [50%, 100%] of that (jitter, so
  // that the stations of a plant do not retry in step after an outage).
  std::chrono::milliseconds first_retry_interval{200};
  std::chrono::milliseconds max_retry_interval{30000};
  // Where the forwarder says that the plant failed or answers again (warning/info records
  // without a cycle, messages without the password): linecald's log. Empty: nowhere.
  LogSink log;
};

// The wait before the retry after `failures` (>= 1) failures in a row, for `jitter` in
// [0, 1]: min(max, first * 2^(failures - 1)) * (0.5 + jitter / 2). Pure.
std::chrono::milliseconds RetryDelay(int failures, const ForwarderOptions& options, double jitter);

struct ForwarderStats {
  int64_t backlog = 0;  // cycles queued, not yet at the plant
  // How long ago the oldest unshipped cycle ended; zero when the backlog is empty.
  std::chrono::nanoseconds oldest_unshipped_age{0};
  // The last attempt's failure (code and message, which never hold the password); OK once
  // an attempt succeeded since.
  absl::Status last_error;
  int64_t shipped = 0;  // cycles the plant acknowledged since Start
};

class Forwarder {
 public:
  // Starts the thread, which ships what the outbox holds at once. `store` must outlive the
  // Forwarder. InvalidArgument for a batch outside 1..10000 or an empty station id.
  static absl::StatusOr<std::unique_ptr<Forwarder>> Start(Store* store, ForwarderOptions options);
  // Stop(now): stops without draining.
  ~Forwarder();
  Forwarder(const Forwarder&) = delete;
  Forwarder& operator=(const Forwarder&) = delete;

  // A cycle ended (its outbox entry is committed): ship it now. Never blocks on the plant.
  void Notify();
  // The backlog from the store, the rest from the thread. Cost: Store::Backlog.
  ForwarderStats Stats();
  // Ships what is queued until `deadline` as long as the plant answers (a failure ends the
  // drain at once, no retry), then stops the thread. Returns the cycles left queued. When the
  // thread is inside a call to the plant that does not return by the deadline (a server that
  // stalls), it is left to end on its own without touching the store again, so that the
  // daemon's exit never waits on the plant. Later calls return at once.
  int64_t Stop(std::chrono::steady_clock::time_point deadline);

 private:
  struct Shared;
  Forwarder(Store* store, std::shared_ptr<Shared> shared) : store_(store), shared_(shared) {}
  static void Run(std::shared_ptr<Shared> shared);

  Store* store_;
  std::shared_ptr<Shared> shared_;  // also held by the thread, which may outlive this object
};

}  // namespace linecal

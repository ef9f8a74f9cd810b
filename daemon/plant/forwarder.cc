#include "daemon/plant/forwarder.h"

#include <libpq-fe.h>

#include <algorithm>
#include <condition_variable>
#include <map>
#include <mutex>
#include <random>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

// How long Stop waits past its deadline for a call to the plant already under way: a batch
// commits in milliseconds on a plant network, so one still running after this is stalled.
constexpr std::chrono::milliseconds kInFlightGrace{500};

// libpq connection parameters the forwarder sets unless the DSN does: TCP keepalives after
// 5 s idle, every 2 s, 3 missed (a silent peer is noticed within about 11 s), and 10 s for
// sent data to be acknowledged. Without them a connection whose server host vanished (power,
// cable) blocks the forwarder's call until the kernel's two-hour keepalive.
constexpr std::pair<const char*, const char*> kNetworkDefaults[] = {
    {"keepalives", "1"},       {"keepalives_idle", "5"},      {"keepalives_interval", "2"},
    {"keepalives_count", "3"}, {"tcp_user_timeout", "10000"},
};

// A value as libpq's keyword=value syntax reads it: single-quoted, \ and ' escaped.
std::string QuoteConnValue(const std::string& value) {
  std::string out = "'";
  for (char c : value) {
    if (c == '\\' || c == '\'') out += '\\';
    out += c;
  }
  return out + "'";
}

}  // namespace

absl::StatusOr<std::string> PlantConnectionString(const PlantConfig& config) {
  char* error = nullptr;
  PQconninfoOption* parsed = PQconninfoParse(config.dsn.c_str(), &error);
  if (parsed == nullptr) {
    const std::string why = error != nullptr ? error : "out of memory";
    PQfreemem(error);
    return absl::InvalidArgumentError(
        absl::StrCat("not a libpq connection string: ", absl::StripTrailingAsciiWhitespace(why)));
  }
  std::map<std::string, std::string> options;
  for (const PQconninfoOption* o = parsed; o->keyword != nullptr; ++o) {
    if (o->val != nullptr) options[o->keyword] = o->val;
  }
  PQconninfoFree(parsed);
  if (auto p = options.find("password"); p != options.end() && !p->second.empty()) {
    return absl::InvalidArgumentError(
        "holds a password; give it in plant.password_file or PGPASSWORD instead "
        "(the configuration file is readable by more than the daemon)");
  }
  if (config.tls) {
    options["sslmode"] = config.tls->mode;
    if (!config.tls->ca_path.empty()) options["sslrootcert"] = config.tls->ca_path;
    if (!config.tls->cert_path.empty()) options["sslcert"] = config.tls->cert_path;
    if (!config.tls->key_path.empty()) options["sslkey"] = config.tls->key_path;
  }
  if (!config.password.empty()) options["password"] = config.password;
  for (const auto& [keyword, value] : kNetworkDefaults) options.emplace(keyword, value);
  std::string conninfo;
  for (const auto& [keyword, value] : options) {
    absl::StrAppend(&conninfo, conninfo.empty() ? "" : " ", keyword, "=", QuoteConnValue(value));
  }
  return conninfo;
}

std::chrono::milliseconds RetryDelay(int failures, const ForwarderOptions& options, double jitter) {
  // Doubling stops once past the cap: 2^20 times any first interval is beyond any cap.
  const int doublings = std::clamp(failures - 1, 0, 20);
  const std::chrono::milliseconds full = std::min(
      options.max_retry_interval, options.first_retry_interval * (int64_t{1} << doublings));
  const double fraction = 0.5 + std::clamp(jitter, 0.0, 1.0) / 2;
  return std::chrono::milliseconds(
      static_cast<int64_t>(static_cast<double>(full.count()) * fraction));
}

struct Forwarder::Shared {
  Store* store;
  const ForwarderOptions options;

  std::mutex mutex;              // guards what follows, up to store_mutex
  std::condition_variable wake;  // Notify, Stop
  std::condition_variable exited_changed;
  bool notified = false;
  bool stop = false;
  std::chrono::steady_clock::time_point drain_deadline;  // once stop
  bool exited = false;
  absl::Status last_error;
  std::thread thread;     // joined or detached by the first Stop
  std::mutex stop_mutex;  // one Stop at a time

  // Held by the thread while it uses the store or the log; Stop sets `abandoned` under it,
  // after which the thread never touches either (they may be gone). Taken after `mutex`.
  std::mutex store_mutex;
  bool abandoned = false;
  // Counted under store_mutex together with MarkShipped, so that Stats, reading both under
  // it, never sees a batch gone from the backlog and not yet counted.
  int64_t shipped = 0;

  Shared(Store* s, ForwarderOptions o) : store(s), options(std::move(o)) {}

  // Stopping, and the drain's time is up.
  bool DeadlinePassed() {
    std::lock_guard<std::mutex> lock(mutex);
    return stop && std::chrono::steady_clock::now() >= drain_deadline;
  }
  // Ships batches until the outbox is empty (OK), a failure (its status; `db` is dropped),
  // or a stop whose deadline passed (Cancelled).
  absl::Status ShipQueued(std::unique_ptr<PlantDb>* db);
  // Connects and checks the schema when there is no connection.
  absl::Status EnsureConnected(std::unique_ptr<PlantDb>* db);
  // Under store_mutex: once abandoned, the log (the daemon's, possibly gone) is not used.
  void Log(LogLevel level, const std::string& message) {
    std::lock_guard<std::mutex> lock(store_mutex);
    if (!abandoned && options.log) options.log({level, message});
  }
};

absl::Status Forwarder::Shared::EnsureConnected(std::unique_ptr<PlantDb>* db) {
  if (*db) return absl::OkStatus();
  absl::StatusOr<std::unique_ptr<PlantDb>> connected =
      PlantDb::Connect(options.conninfo, options.db);
  if (!connected.ok()) return connected.status();
  if (absl::Status s = (*connected)->CheckSchema(); !s.ok()) return s;
  *db = *std::move(connected);
  return absl::OkStatus();
}

absl::Status Forwarder::Shared::ShipQueued(std::unique_ptr<PlantDb>* db) {
  while (true) {
    if (DeadlinePassed()) return absl::CancelledError("stopped");
    std::vector<OutboxEntry> entries;
    {
      std::lock_guard<std::mutex> lock(store_mutex);
      if (abandoned) return absl::CancelledError("stopped");
      absl::StatusOr<std::vector<OutboxEntry>> read = store->ReadOutbox(options.batch);
      if (!read.ok()) return read.status();
      entries = *std::move(read);
    }
    if (entries.empty()) return absl::OkStatus();
    if (absl::Status s = EnsureConnected(db); !s.ok()) return s;
    const int64_t last_seq = entries.back().seq;
    std::vector<PlantCycle> cycles;
    cycles.reserve(entries.size());
    for (OutboxEntry& e : entries) cycles.push_back({std::move(e.cycle), std::move(e.events)});
    if (absl::Status s = (*db)->ApplyBatch(options.station_id, cycles); !s.ok()) {
      db->reset();  // the next attempt reconnects and checks the schema again
      return s;
    }
    {
      std::lock_guard<std::mutex> lock(store_mutex);
      if (abandoned) return absl::CancelledError("stopped");
      // Not removed (a full disk): the batch is sent again, which the plant ignores.
      if (absl::Status s = store->MarkShipped(last_seq); !s.ok()) return s;
      shipped += static_cast<int64_t>(cycles.size());
    }
    std::lock_guard<std::mutex> lock(mutex);
    last_error = absl::OkStatus();
  }
}

absl::StatusOr<std::unique_ptr<Forwarder>> Forwarder::Start(Store* store,
                                                            ForwarderOptions options) {
  // 10,000: a transaction of a few hundred megabytes at the plant at most; past that a batch
  // only delays the first commit.
  if (options.batch < 1 || options.batch > 10000) {
    return absl::InvalidArgumentError(
        absl::StrCat("plant.batch: must be in [1, 10000], got ", options.batch));
  }
  if (options.station_id.empty()) {
    return absl::InvalidArgumentError("plant.station_id: must not be empty");
  }
  auto shared = std::make_shared<Shared>(store, std::move(options));
  shared->thread = std::thread(&Forwarder::Run, shared);
  return std::unique_ptr<Forwarder>(new Forwarder(store, std::move(shared)));
}

void Forwarder::Run(std::shared_ptr<Shared> s) {
  std::unique_ptr<PlantDb> db;
  std::mt19937 random(std::random_device{}());
  std::uniform_real_distribution<double> jitter(0.0, 1.0);
  int failures = 0;
  while (true) {
    const absl::Status result = s->ShipQueued(&db);
    std::unique_lock<std::mutex> lock(s->mutex);
    if (!absl::IsCancelled(result)) {
      if (!result.ok() && result.message() != s->last_error.message()) {
        s->Log(LogLevel::kWarning, absl::StrCat("plant database: ", result.message(),
                                                "; the cycles stay queued and are sent again"));
      } else if (result.ok() && failures > 0) {
        s->Log(LogLevel::kInfo, "plant database: reachable again, the queue is shipped");
      }
      s->last_error = result;
    }
    // Stopping: the queue is drained, the drain failed (no retry) or its time is up.
    if (s->stop) break;
    if (result.ok()) {
      failures = 0;
      s->wake.wait(lock, [&] { return s->notified || s->stop; });
    } else {
      ++failures;
      const std::chrono::milliseconds delay = RetryDelay(failures, s->options, jitter(random));
      if (s->wake.wait_for(lock, delay, [&] { return s->stop; })) break;
    }
    s->notified = false;
  }
  s->exited = true;
  s->exited_changed.notify_all();
}

Forwarder::~Forwarder() { Stop(std::chrono::steady_clock::now()); }

void Forwarder::Notify() {
  std::lock_guard<std::mutex> lock(shared_->mutex);
  shared_->notified = true;
  shared_->wake.notify_one();
}

ForwarderStats Forwarder::Stats() {
  ForwarderStats stats;
  {
    std::lock_guard<std::mutex> lock(shared_->mutex);
    stats.last_error = shared_->last_error;
  }
  absl::StatusOr<OutboxBacklog> backlog;
  {
    std::lock_guard<std::mutex> lock(shared_->store_mutex);
    stats.shipped = shared_->shipped;
    backlog = store_->Backlog();
  }
  if (!backlog.ok()) {
    stats.last_error = backlog.status();
    return stats;
  }
  stats.backlog = backlog->cycles;
  if (backlog->cycles > 0) {
    const auto now = std::chrono::system_clock::now().time_since_epoch();
    stats.oldest_unshipped_age = std::max(std::chrono::nanoseconds(0),
                                          now - std::chrono::nanoseconds(backlog->oldest_ended_ns));
  }
  return stats;
}

int64_t Forwarder::Stop(std::chrono::steady_clock::time_point deadline) {
  Shared& s = *shared_;
  std::lock_guard<std::mutex> stopping(s.stop_mutex);
  if (s.thread.joinable()) {
    bool exited = false;
    {
      std::unique_lock<std::mutex> lock(s.mutex);
      s.stop = true;
      s.drain_deadline = deadline;
      s.wake.notify_all();
      exited =
          s.exited_changed.wait_until(lock, deadline + kInFlightGrace, [&] { return s.exited; });
    }
    if (exited) {
      s.thread.join();
    } else {
      s.Log(LogLevel::kWarning,
            "plant database: a call did not return by the stop's deadline; left to "
            "end on its own, its cycles stay queued");
      std::lock_guard<std::mutex> lock(s.store_mutex);
      s.abandoned = true;
      s.thread.detach();
    }
  }
  absl::StatusOr<OutboxBacklog> backlog = store_->Backlog();
  return backlog.ok() ? backlog->cycles : 0;
}

}  // namespace linecal

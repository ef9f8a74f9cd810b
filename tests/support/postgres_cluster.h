#pragma once
// A throwaway PostgreSQL 15 server for the plant database's tests (docs/plant.md): initdb
// into a fresh temporary directory, the server on a free loopback port (and a Unix socket in
// that directory), fsync off for speed (a commit that returned is still in the WAL: it
// survives Kill()), stopped (pg_ctl stop -m immediate) and the directory removed when the
// PostgresCluster is destroyed.
//
// PostgreSQL refuses to run as root, and the tests run as root here and on CI: initdb,
// pg_ctl and the server then run as the `postgres` user (runuser), which owns the directory.
// Clients (PlantDb, psql) connect over TCP with the superuser `postgres` and its password
// (scram-sha-256), or any role a test creates.
//
// Faults for the forwarding tests: Stop() (a clean shutdown), Start() (again, same port and
// data), Kill() (SIGKILL to the server and its backends: a crash, recovered from the WAL on
// the next Start()), Pause() / Resume() (SIGSTOP / SIGCONT to them: a frozen host whose
// kernel still accepts connections and acknowledges packets, but nothing answers).
//
// Thread safety: none; one test drives it. Cost: Create() ~1-2 s (initdb), Start() ~0.3 s.

#include <sys/types.h>

#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace linecal::testing_support {

class PostgresCluster {
 public:
  // Where initdb, pg_ctl, postgres and psql are (Debian's postgresql-15).
  static constexpr char kBinDir[] = "/usr/lib/postgresql/15/bin";
  static constexpr char kSuperuser[] = "postgres";
  static constexpr char kSuperuserPassword[] = "superuser secret 'quoted'";

  // Empty when the server can be run, else why not (for GTEST_SKIP): names the missing path.
  static std::string MissingReason();

  // initdb and Start(). Errors name the command and quote its output (the server log).
  static absl::StatusOr<std::unique_ptr<PostgresCluster>> Create();
  ~PostgresCluster();  // pg_ctl stop -m immediate, then removes the directory
  PostgresCluster(const PostgresCluster&) = delete;
  PostgresCluster& operator=(const PostgresCluster&) = delete;

  absl::Status Start();  // pg_ctl start -w; FailedPrecondition when running
  absl::Status Stop();   // pg_ctl stop -m fast -w (clients are disconnected)
  // SIGKILL to the postmaster and every child of it; returns when they are all dead.
  absl::Status Kill();
  // SIGSTOP / SIGCONT to the postmaster and every child of it (the destructor resumes).
  absl::Status Pause();
  absl::Status Resume();
  bool running() const { return running_; }

  const std::string& dir() const { return dir_; }  // the temporary directory
  std::string host() const { return "127.0.0.1"; }
  int port() const { return port_; }
  // A libpq connection string for `user` (default: the superuser, with its password).
  std::string Dsn(const std::string& dbname, const std::string& user = kSuperuser,
                  const std::string& password = kSuperuserPassword) const;

  // CREATE DATABASE `name` (as the superuser).
  absl::Status CreateDatabase(const std::string& name);
  // Runs `sql` with psql connected by `dsn` (Dsn(...): the superuser or another role) and
  // returns psql's unaligned output (-At: one line per row, '|' between columns, no final
  // newline). Errors quote psql's message (a permission denied, a syntax error).
  absl::StatusOr<std::string> Psql(const std::string& dsn, const std::string& sql);

 private:
  PostgresCluster(std::string dir, int port) : dir_(std::move(dir)), port_(port) {}
  // Runs `argv` (as the postgres user when we are root); its output goes to `log`.
  absl::Status RunAsServerUser(const std::vector<std::string>& argv, const std::string& log);
  // The postmaster (from postmaster.pid) and its children.
  absl::StatusOr<std::vector<pid_t>> ServerPids() const;
  absl::Status Signal(int signal);

  std::string dir_;
  int port_;
  bool running_ = false;
};

}  // namespace linecal::testing_support

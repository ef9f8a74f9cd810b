#include "tests/support/postgres_cluster.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <pwd.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_replace.h"
#include "absl/strings/str_split.h"

extern char** environ;

namespace linecal::testing_support {
namespace {

namespace fs = std::filesystem;

std::string Bin(const char* name) { return absl::StrCat(PostgresCluster::kBinDir, "/", name); }

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// The last `n` bytes of `text`: enough of a server log to say why it failed.
std::string Tail(const std::string& text, size_t n = 1500) {
  return text.size() <= n ? text : absl::StrCat("…", text.substr(text.size() - n));
}

// Runs argv with stdout and stderr into `output`; its exit code, or -1.
int Spawn(const std::vector<std::string>& argv, const std::string& output) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, output.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = 0;
  const int error = posix_spawn(&pid, args[0], &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (error != 0) return -1;
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// A loopback TCP port nobody listens on now (the kernel's choice for port 0).
absl::StatusOr<int> FreePort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return absl::InternalError(absl::StrCat("socket: ", std::strerror(errno)));
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t size = sizeof address;
  const bool ok = bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0 &&
                  getsockname(fd, reinterpret_cast<sockaddr*>(&address), &size) == 0;
  close(fd);
  if (!ok) return absl::InternalError(absl::StrCat("bind 127.0.0.1:0: ", std::strerror(errno)));
  return ntohs(address.sin_port);
}

// A libpq keyword value, quoted.
std::string Quote(const std::string& value) {
  return absl::StrCat("'", absl::StrReplaceAll(value, {{"\\", "\\\\"}, {"'", "\\'"}}), "'");
}

// Whether `pid` is gone or a zombie (dead, waiting for a parent that may never reap it: the
// postmaster's parent is init once pg_ctl has exited).
bool Dead(pid_t pid) {
  if (kill(pid, 0) != 0) return true;
  const std::string stat = ReadFile(absl::StrCat("/proc/", pid, "/stat"));
  const size_t paren = stat.rfind(')');
  return paren == std::string::npos || stat.substr(paren + 2, 1) == "Z";
}

// The pids whose parent is `parent` (from /proc).
std::vector<pid_t> Children(pid_t parent) {
  std::vector<pid_t> children;
  for (const fs::directory_entry& entry : fs::directory_iterator("/proc")) {
    int pid = 0;
    if (!absl::SimpleAtoi(entry.path().filename().string(), &pid)) continue;
    const std::string stat = ReadFile(absl::StrCat(entry.path().string(), "/stat"));
    const size_t paren = stat.rfind(')');
    if (paren == std::string::npos) continue;
    // After ") ": state, then ppid.
    const std::vector<std::string> fields = absl::StrSplit(stat.substr(paren + 2), ' ');
    int ppid = 0;
    if (fields.size() > 1 && absl::SimpleAtoi(fields[1], &ppid) && ppid == parent) {
      children.push_back(pid);
    }
  }
  return children;
}

}  // namespace

std::string PostgresCluster::MissingReason() {
  for (const char* tool : {"initdb", "pg_ctl", "postgres", "psql"}) {
    if (!fs::exists(Bin(tool))) {
      return absl::StrCat(Bin(tool),
                          " is not installed (Debian package postgresql-15): "
                          "skipping the tests against a real PostgreSQL");
    }
  }
  return "";
}

absl::Status PostgresCluster::RunAsServerUser(const std::vector<std::string>& argv,
                                              const std::string& log) {
  std::vector<std::string> command;
  if (geteuid() == 0) command = {"/usr/sbin/runuser", "-u", kSuperuser, "--"};
  command.insert(command.end(), argv.begin(), argv.end());
  const int code = Spawn(command, log);
  if (code == 0) return absl::OkStatus();
  return absl::InternalError(
      absl::StrCat(absl::StrJoin(argv, " "), " exited with ", code, ": ", Tail(ReadFile(log))));
}

absl::StatusOr<std::unique_ptr<PostgresCluster>> PostgresCluster::Create() {
  if (std::string why = MissingReason(); !why.empty()) return absl::NotFoundError(why);
  std::string dir = (fs::temp_directory_path() / "linecal_pg_XXXXXX").string();
  if (mkdtemp(dir.data()) == nullptr) {
    return absl::InternalError(absl::StrCat("mkdtemp ", dir, ": ", std::strerror(errno)));
  }
  absl::StatusOr<int> port = FreePort();
  if (!port.ok()) return port.status();
  std::unique_ptr<PostgresCluster> cluster(new PostgresCluster(dir, *port));
  const std::string password_file = absl::StrCat(dir, "/superuser_password");
  std::ofstream(password_file) << kSuperuserPassword << "\n";
  if (geteuid() == 0) {
    const passwd* user = getpwnam(kSuperuser);
    if (user == nullptr) {
      return absl::FailedPreconditionError(
          absl::StrCat("no user '", kSuperuser, "' to run PostgreSQL as (we are root)"));
    }
    if (chown(dir.c_str(), user->pw_uid, user->pw_gid) != 0 ||
        chown(password_file.c_str(), user->pw_uid, user->pw_gid) != 0) {
      return absl::InternalError(absl::StrCat("chown ", dir, ": ", std::strerror(errno)));
    }
  }
  const std::string data = absl::StrCat(dir, "/data");
  absl::Status s = cluster->RunAsServerUser(
      {Bin("initdb"), "-D", data, "-U", kSuperuser, "--pwfile", password_file, "--auth-local=trust",
       "--auth-host=scram-sha-256", "-E", "UTF8", "--locale=C", "-N"},
      absl::StrCat(dir, "/initdb.log"));
  if (!s.ok()) return s;
  // Throwaway data: no fsync (the OS's cache survives a killed server, not a power cut),
  // but synchronous_commit stays on: a commit that returned is in the WAL the server
  // recovers from after Kill(). The socket goes in our directory, not /var/run/postgresql.
  std::ofstream(absl::StrCat(data, "/postgresql.conf"), std::ios::app)
      << "port = " << *port << "\nlisten_addresses = '127.0.0.1'\n"
      << "unix_socket_directories = '" << dir << "'\n"
      << "fsync = off\nfull_page_writes = off\n";
  if (s = cluster->Start(); !s.ok()) return s;
  return cluster;
}

PostgresCluster::~PostgresCluster() {
  if (running_) {
    (void)Resume();  // a paused server would not see pg_ctl's signal
    (void)RunAsServerUser(
        {Bin("pg_ctl"), "-D", absl::StrCat(dir_, "/data"), "-m", "immediate", "-w", "stop"},
        absl::StrCat(dir_, "/pg_ctl.log"));
  }
  std::error_code ignored;
  fs::remove_all(dir_, ignored);
}

absl::Status PostgresCluster::Start() {
  if (running_) return absl::FailedPreconditionError("the PostgreSQL server is running already");
  absl::Status s = RunAsServerUser({Bin("pg_ctl"), "-D", absl::StrCat(dir_, "/data"), "-l",
                                    absl::StrCat(dir_, "/server.log"), "-w", "-t", "60", "start"},
                                   absl::StrCat(dir_, "/pg_ctl.log"));
  if (!s.ok()) {
    return absl::InternalError(absl::StrCat(
        s.message(), "\nserver log: ", Tail(ReadFile(absl::StrCat(dir_, "/server.log")))));
  }
  running_ = true;
  return absl::OkStatus();
}

absl::Status PostgresCluster::Stop() {
  absl::Status s = RunAsServerUser(
      {Bin("pg_ctl"), "-D", absl::StrCat(dir_, "/data"), "-m", "fast", "-w", "stop"},
      absl::StrCat(dir_, "/pg_ctl.log"));
  if (s.ok()) running_ = false;
  return s;
}

absl::StatusOr<std::vector<pid_t>> PostgresCluster::ServerPids() const {
  const std::string lock_file = absl::StrCat(dir_, "/data/postmaster.pid");
  int pid = 0;
  const std::string lock = ReadFile(lock_file);
  if (!absl::SimpleAtoi(lock.substr(0, lock.find('\n')), &pid) || pid <= 0) {
    return absl::FailedPreconditionError(absl::StrCat("no server pid in ", lock_file));
  }
  std::vector<pid_t> pids = Children(pid);
  pids.push_back(pid);
  return pids;
}

absl::Status PostgresCluster::Signal(int signal) {
  absl::StatusOr<std::vector<pid_t>> pids = ServerPids();
  if (!pids.ok()) return pids.status();
  for (pid_t pid : *pids) kill(pid, signal);
  return absl::OkStatus();
}

absl::Status PostgresCluster::Pause() { return Signal(SIGSTOP); }

absl::Status PostgresCluster::Resume() { return Signal(SIGCONT); }

absl::Status PostgresCluster::Kill() {
  absl::StatusOr<std::vector<pid_t>> victims = ServerPids();
  if (!victims.ok()) return victims.status();
  for (pid_t victim : *victims) kill(victim, SIGKILL);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  for (pid_t victim : *victims) {
    while (!Dead(victim)) {
      if (std::chrono::steady_clock::now() > deadline) {
        return absl::DeadlineExceededError(absl::StrCat("pid ", victim, " survived SIGKILL"));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }
  // A zombie postmaster nobody reaps would still answer kill(pid, 0), and its lock files
  // would make the next server refuse to start; after a real crash that pid is gone.
  fs::remove(absl::StrCat(dir_, "/data/postmaster.pid"));
  fs::remove(absl::StrCat(dir_, "/.s.PGSQL.", port_, ".lock"));
  running_ = false;
  return absl::OkStatus();
}

std::string PostgresCluster::Dsn(const std::string& dbname, const std::string& user,
                                 const std::string& password) const {
  return absl::StrCat("host=", host(), " port=", port_, " dbname=", Quote(dbname),
                      " user=", Quote(user), " password=", Quote(password));
}

absl::Status PostgresCluster::CreateDatabase(const std::string& name) {
  return Psql(Dsn("postgres"), absl::StrCat("CREATE DATABASE \"", name, "\"")).status();
}

absl::StatusOr<std::string> PostgresCluster::Psql(const std::string& dsn, const std::string& sql) {
  // psql runs as whoever we are: a client needs no privilege.
  const std::string output = absl::StrCat(dir_, "/psql_", getpid(), ".out");
  const int code =
      Spawn({Bin("psql"), "-X", "-At", "-v", "ON_ERROR_STOP=1", "-d", dsn, "-c", sql}, output);
  std::string text = ReadFile(output);
  fs::remove(output);
  if (code != 0) {
    return absl::InternalError(absl::StrCat("psql -c '", sql, "' exited with ", code, ": ", text));
  }
  if (!text.empty() && text.back() == '\n') text.pop_back();
  return text;
}

}  // namespace linecal::testing_support

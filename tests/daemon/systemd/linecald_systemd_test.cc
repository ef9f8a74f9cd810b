// systemd integration: the notification protocol on real AF_UNIX sockets (path and abstract),
// and the installed daemon: `cmake --install` into a temporary prefix, the unit's hardening
// keys, and linecald started as systemd would (NOTIFY_SOCKET, WATCHDOG_USEC) sending
// READY=1, WATCHDOG=1 and, on SIGTERM, STOPPING=1 before a clean exit.
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "daemon/systemd/sd_notify.h"
#include "tests/support/scoped_path.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;

// A datagram socket bound where systemd would listen; Receive() waits up to `timeout`.
class NotifySocket {
 public:
  explicit NotifySocket(const std::string& name) : name_(name) {
    fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::memcpy(a.sun_path, name.data(), name.size());
    if (name[0] == '@') a.sun_path[0] = '\0';
    if (name[0] == '/') ::unlink(name.c_str());
    bound_ = ::bind(fd_, reinterpret_cast<sockaddr*>(&a),
                    static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + name.size())) == 0;
  }
  ~NotifySocket() {
    ::close(fd_);
    if (name_[0] == '/') ::unlink(name_.c_str());
  }
  bool bound() const { return bound_; }
  std::string Receive(milliseconds timeout) {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(timeout.count())) != 1) return "";
    char buffer[4096];
    const ssize_t n = ::recv(fd_, buffer, sizeof buffer, 0);
    return n > 0 ? std::string(buffer, static_cast<std::size_t>(n)) : "";
  }

 private:
  std::string name_;
  int fd_ = -1;
  bool bound_ = false;
};

// A file or folder in this process's scratch directory, which goes at exit (the forked
// daemon leaves by exec or _exit, so only the test process removes it).
std::string Scratch(const std::string& what) {
  static const testing_support::ScopedPath root("linecald_systemd");
  fs::create_directories(root.path());
  return (root.path() / what).string();
}

TEST(SystemdNotifier, SendsToPathAndAbstractSockets) {
  NotifySocket path_socket(Scratch("notify.sock"));
  ASSERT_TRUE(path_socket.bound());
  EXPECT_TRUE(
      SystemdNotifier(Scratch("notify.sock"), std::nullopt).Notify("READY=1\nSTATUS=up").ok());
  EXPECT_EQ(path_socket.Receive(milliseconds(1000)), "READY=1\nSTATUS=up");

  const std::string abstract = "@linecal-test-" + std::to_string(::getpid());
  NotifySocket abstract_socket(abstract);
  ASSERT_TRUE(abstract_socket.bound());
  EXPECT_TRUE(SystemdNotifier(abstract, std::nullopt).Notify("WATCHDOG=1").ok());
  EXPECT_EQ(abstract_socket.Receive(milliseconds(1000)), "WATCHDOG=1");

  // Outside systemd: nothing to do, no error.
  EXPECT_FALSE(SystemdNotifier("", std::nullopt).enabled());
  EXPECT_TRUE(SystemdNotifier("", std::nullopt).Notify("READY=1").ok());
  // A socket that is not there, and a name that is not a socket path.
  const absl::Status gone = SystemdNotifier(Scratch("gone.sock"), std::nullopt).Notify("READY=1");
  EXPECT_EQ(gone.code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(gone.message().find("gone.sock"), std::string::npos) << gone;
  EXPECT_EQ(SystemdNotifier("relative.sock", std::nullopt).Notify("READY=1").code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(SystemdNotifier, WatchdogFromTheEnvironmentOnlyForThisProcess) {
  ::setenv("NOTIFY_SOCKET", "/run/systemd/notify", 1);
  ::setenv("WATCHDOG_USEC", "2500000", 1);
  ::unsetenv("WATCHDOG_PID");
  SystemdNotifier n = SystemdNotifier::FromEnvironment();
  EXPECT_TRUE(n.enabled());
  ASSERT_TRUE(n.watchdog_interval().has_value());
  EXPECT_EQ(n.watchdog_interval()->count(), 2500000);
  ::setenv("WATCHDOG_PID", std::to_string(::getpid() + 1).c_str(), 1);  // meant for another process
  EXPECT_FALSE(SystemdNotifier::FromEnvironment().watchdog_interval().has_value());
  ::setenv("WATCHDOG_PID", std::to_string(::getpid()).c_str(), 1);
  EXPECT_TRUE(SystemdNotifier::FromEnvironment().watchdog_interval().has_value());
  ::setenv("WATCHDOG_USEC", "soon", 1);
  EXPECT_FALSE(SystemdNotifier::FromEnvironment().watchdog_interval().has_value());
  for (const char* v : {"NOTIFY_SOCKET", "WATCHDOG_USEC", "WATCHDOG_PID"}) ::unsetenv(v);
  EXPECT_FALSE(SystemdNotifier::FromEnvironment().enabled());
}

std::string ReadFile(const fs::path& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

TEST(InstalledDaemon, UnitConfigAndNotifications) {
  const fs::path prefix = Scratch("prefix");
  fs::remove_all(prefix);
  const std::string install = std::string(LINECAL_CMAKE_COMMAND) + " --install " +
                              LINECAL_BINARY_DIR + " --prefix " + prefix.string() + " > " +
                              Scratch("install.log") + " 2>&1";
  ASSERT_EQ(std::system(install.c_str()), 0) << ReadFile(Scratch("install.log"));
  for (const char* f : {"bin/linecald", "bin/linecal", "etc/linecal/linecald.json",
                        "lib/systemd/system/linecald.service", "lib/sysusers.d/linecal.conf",
                        "share/linecal/stations/reference.json",
                        "share/linecal/cars/reference.json", "share/linecal/cars/Pandar64.csv"}) {
    EXPECT_TRUE(fs::exists(prefix / f)) << f;
  }
  EXPECT_TRUE(fs::is_directory(prefix / "var/lib/linecal"));
  const std::string unit = ReadFile(prefix / "lib/systemd/system/linecald.service");
  const std::string data_dir = (prefix / "var/lib/linecal").string();
  for (const std::string& key : std::vector<std::string>{
           "Type=notify\n", "WatchdogSec=10\n", "LimitNOFILE=65536\n", "User=linecal\n",
           "NoNewPrivileges=yes\n", "ProtectSystem=strict\n", "ReadWritePaths=" + data_dir + "\n",
           "ExecStart=" + (prefix / "bin/linecald").string() + " --config " +
               (prefix / "etc/linecal/linecald.json").string() + "\n"}) {
    EXPECT_NE(unit.find(key), std::string::npos) << key;
  }
  if (std::system("command -v systemd-analyze > /dev/null 2>&1") == 0) {
    const std::string verify = "systemd-analyze verify " +
                               (prefix / "lib/systemd/system/linecald.service").string() + " > " +
                               Scratch("verify.log") + " 2>&1";
    EXPECT_EQ(std::system(verify.c_str()), 0) << ReadFile(Scratch("verify.log"));
  }

  // The installed daemon on its installed configuration, started as systemd starts it.
  const std::string socket = Scratch("daemon.sock");
  NotifySocket notify(socket);
  ASSERT_TRUE(notify.bound());
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::setenv("NOTIFY_SOCKET", socket.c_str(), 1);
    ::setenv("WATCHDOG_USEC", "200000", 1);  // pings every 100 ms
    const std::string log = Scratch("daemon.log");
    FILE* err = std::freopen(log.c_str(), "w", stderr);
    (void)err;
    const std::string binary = (prefix / "bin/linecald").string();
    const std::string config = (prefix / "etc/linecal/linecald.json").string();
    ::execl(binary.c_str(), binary.c_str(), "--config", config.c_str(), "--listen", "127.0.0.1:0",
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const std::string ready = notify.Receive(milliseconds(30000));
  EXPECT_EQ(ready.rfind("READY=1\nSTATUS=listening on 127.0.0.1:0 (port ", 0), 0u)
      << ready << "\n"
      << ReadFile(Scratch("daemon.log"));
  int pings = 0;
  for (int i = 0; i < 3; ++i) pings += notify.Receive(milliseconds(2000)) == "WATCHDOG=1";
  EXPECT_EQ(pings, 3);
  ::kill(pid, SIGTERM);
  std::string last;
  for (int i = 0; i < 50 && last != "STOPPING=1"; ++i) last = notify.Receive(milliseconds(1000));
  EXPECT_EQ(last, "STOPPING=1");
  int status = 0;
  ::waitpid(pid, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << ReadFile(Scratch("daemon.log"));
  // The installed configuration put the database in the installed data directory.
  EXPECT_TRUE(fs::exists(prefix / "var/lib/linecal/station.db"));
  fs::remove_all(prefix);
}

}  // namespace
}  // namespace linecal

#include "daemon/drivers/socketcan.h"

#include <gtest/gtest.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <net/if.h>
#include <net/if_arp.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace linecal {
namespace {

using std::chrono::milliseconds;

// This machine's kernel has no CAN (docs/sensors.md): the real socket(PF_CAN) fails. Tests that
// need to get past it hand Open() a stand-in socket through SocketCanSyscalls.
bool KernelHasCan() {
  const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (fd >= 0) ::close(fd);
  return fd >= 0;
}

// The descriptor the stand-in socket() returns next (Open takes ownership).
int g_next_socket = -1;
int StandInSocket(int, int, int) { return std::exchange(g_next_socket, -1); }

// A real AF_INET datagram socket: the real SIOCGIFFLAGS/SIOCGIFHWADDR work on it.
SocketCanSyscalls RealCallsOnAnInetSocket() {
  g_next_socket = ::socket(AF_INET, SOCK_DGRAM, 0);
  SocketCanSyscalls sys = SocketCanSyscalls::Real();
  sys.socket = StandInSocket;
  return sys;
}

// Stand-ins for a CAN interface that is up: the kernel calls the real reader cannot reach.
int IoctlUpCan(int, unsigned long request, void* arg) {
  ifreq* req = static_cast<ifreq*>(arg);
  if (request == SIOCGIFFLAGS) req->ifr_flags = IFF_UP | IFF_RUNNING;
  if (request == SIOCGIFHWADDR) req->ifr_hwaddr.sa_family = ARPHRD_CAN;
  return 0;
}
int IoctlDownCan(int fd, unsigned long request, void* arg) {
  IoctlUpCan(fd, request, arg);
  if (request == SIOCGIFFLAGS) static_cast<ifreq*>(arg)->ifr_flags = 0;
  return 0;
}
unsigned IndexSeven(const char*) { return 7; }
int SetsockoptOk(int, int, int, const void*, socklen_t) { return 0; }
int BindOk(int, const sockaddr*, socklen_t) { return 0; }
int BindNoDevice(int, const sockaddr*, socklen_t) {
  errno = ENODEV;
  return -1;
}

SocketCanSyscalls AllStandIns(int fd) {
  g_next_socket = fd;
  return {StandInSocket, IndexSeven, IoctlUpCan, SetsockoptOk, BindOk};
}

void ExpectError(const absl::StatusOr<SocketCanReader>& r, absl::StatusCode code,
                 const std::string& part) {
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), code) << r.status();
  EXPECT_NE(r.status().message().find(part), std::string::npos) << r.status();
}

TEST(SocketCanTest, KernelWithoutCanIsReportedAsSuch) {
  if (KernelHasCan()) GTEST_SKIP() << "this kernel has CAN; the path needs one without";
  // The real calls, nothing replaced.
  ExpectError(SocketCanReader::Open("can0"), absl::StatusCode::kFailedPrecondition,
              "can0: kernel has no CAN support (socket(PF_CAN) failed: " +
                  std::string(std::strerror(EAFNOSUPPORT)));
}

TEST(SocketCanTest, NoSuchInterfaceFromTheRealIfNametoindex) {
  ExpectError(SocketCanReader::Open("nosuchcan9", RealCallsOnAnInetSocket()),
              absl::StatusCode::kNotFound, "nosuchcan9: no such interface");
}

TEST(SocketCanTest, LoopbackIsNotACanInterfaceFromTheRealIoctls) {
  // lo is up; its real link type is ARPHRD_LOOPBACK (772).
  ExpectError(SocketCanReader::Open("lo", RealCallsOnAnInetSocket()),
              absl::StatusCode::kFailedPrecondition, "lo: not a CAN interface (link type 772)");
}

TEST(SocketCanTest, InterfaceDownFromTheRealIoctlsWhenTheMachineHasOne) {
  // Any interface that is down will do (the real SIOCGIFFLAGS is checked before the type).
  std::string down;
  if (struct if_nameindex* names = ::if_nameindex()) {
    const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
    for (struct if_nameindex* n = names; n->if_index != 0 && down.empty(); ++n) {
      ifreq req{};
      std::strncpy(req.ifr_name, n->if_name, IFNAMSIZ - 1);
      if (::ioctl(fd, SIOCGIFFLAGS, &req) == 0 && (req.ifr_flags & IFF_UP) == 0) down = n->if_name;
    }
    ::close(fd);
    ::if_freenameindex(names);
  }
  if (down.empty()) GTEST_SKIP() << "no interface is down on this machine";
  ExpectError(SocketCanReader::Open(down, RealCallsOnAnInetSocket()),
              absl::StatusCode::kFailedPrecondition, down + ": interface is down");
}

TEST(SocketCanTest, InterfaceDownWithStandIns) {
  SocketCanSyscalls sys = AllStandIns(::socket(AF_INET, SOCK_DGRAM, 0));
  sys.ioctl_ifreq = IoctlDownCan;
  ExpectError(SocketCanReader::Open("can0", sys), absl::StatusCode::kFailedPrecondition,
              "can0: interface is down (ip link set can0 up type can bitrate 500000)");
}

TEST(SocketCanTest, BindEnodevIsNotACanInterface) {
  SocketCanSyscalls sys = AllStandIns(::socket(AF_INET, SOCK_DGRAM, 0));
  sys.bind = BindNoDevice;
  ExpectError(SocketCanReader::Open("can0", sys), absl::StatusCode::kFailedPrecondition,
              "can0: not a CAN interface (bind");
}

TEST(SocketCanTest, BadNames) {
  ExpectError(SocketCanReader::Open(""), absl::StatusCode::kInvalidArgument, "1..15 characters");
  ExpectError(SocketCanReader::Open("a_name_of_16char"), absl::StatusCode::kInvalidArgument,
              "1..15 characters");
}

// The data path, with a datagram socket pair standing in for the CAN socket: the test writes
// kernel frames into one end, the reader really polls and receives on the other.
class SocketCanReadTest : public testing::Test {
 protected:
  void SetUp() override {
    int pair[2];
    ASSERT_EQ(::socketpair(AF_UNIX, SOCK_DGRAM, 0, pair), 0);
    writer_ = pair[1];
    absl::StatusOr<SocketCanReader> r = SocketCanReader::Open("can7", AllStandIns(pair[0]));
    ASSERT_TRUE(r.ok()) << r.status();
    reader_.emplace(*std::move(r));
  }
  void TearDown() override { ::close(writer_); }

  void Send(const void* data, size_t bytes) {
    ASSERT_EQ(::send(writer_, data, bytes, 0), static_cast<ssize_t>(bytes));
  }

  CanFrame ReadOne() {
    absl::StatusOr<std::optional<CanFrame>> f = reader_->Read(milliseconds(1000));
    EXPECT_TRUE(f.ok()) << f.status();
    EXPECT_TRUE(f.ok() && f->has_value());
    return f.ok() && f->has_value() ? **f : CanFrame{};
  }

  int writer_ = -1;
  std::optional<SocketCanReader> reader_;
};

TEST_F(SocketCanReadTest, ClassicFdRemoteErrorAndExtendedFrames) {
  const CanTime before =
      std::chrono::time_point_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now());
  can_frame classic{};
  classic.can_id = 0x701;
  classic.len = 8;
  const uint8_t example[8] = {0x05, 0x64, 0xFE, 0x8E, 0x80, 0x01, 0x60, 0xA4};
  std::memcpy(classic.data, example, 8);
  Send(&classic, CAN_MTU);
  CanFrame f = ReadOne();
  EXPECT_EQ(f.interface, "can7");
  EXPECT_EQ(f.id, 0x701u);
  EXPECT_FALSE(f.extended || f.fd || f.remote || f.error);
  EXPECT_EQ(std::vector<uint8_t>(f.payload().begin(), f.payload().end()),
            std::vector<uint8_t>(example, example + 8));
  const CanTime after =
      std::chrono::time_point_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now());
  EXPECT_GE(f.time, before);
  EXPECT_LE(f.time, after);

  canfd_frame fd{};
  fd.can_id = 0x1ABCDE12 | CAN_EFF_FLAG;
  fd.len = 12;
  fd.flags = CANFD_BRS | CANFD_ESI;
  fd.data[11] = 0x5A;
  Send(&fd, CANFD_MTU);
  f = ReadOne();
  EXPECT_TRUE(f.fd);
  EXPECT_TRUE(f.extended);
  EXPECT_EQ(f.id, 0x1ABCDE12u);
  EXPECT_EQ(f.fd_flags, kCanFdBitRateSwitch | kCanFdErrorStateIndicator);
  EXPECT_EQ(f.len, 12);
  EXPECT_EQ(f.data[11], 0x5A);

  can_frame remote{};
  remote.can_id = 0x123 | CAN_RTR_FLAG;
  remote.len = 3;
  Send(&remote, CAN_MTU);
  f = ReadOne();
  EXPECT_TRUE(f.remote);
  EXPECT_EQ(f.len, 3);
  EXPECT_TRUE(f.payload().empty());

  can_frame error{};
  error.can_id = CAN_ERR_FLAG | CAN_ERR_CRTL;
  error.len = CAN_ERR_DLC;
  Send(&error, CAN_MTU);
  f = ReadOne();
  EXPECT_TRUE(f.error);
  EXPECT_EQ(f.id, static_cast<uint32_t>(CAN_ERR_CRTL));
  // What the reader produces is what the candump writer accepts.
  EXPECT_NE(FormatCandumpLine(f)->find(") can7 20000004#0000000000000000"), std::string::npos);
}

TEST_F(SocketCanReadTest, TimeoutGivesNoFrame) {
  const auto start = std::chrono::steady_clock::now();
  absl::StatusOr<std::optional<CanFrame>> f = reader_->Read(milliseconds(30));
  ASSERT_TRUE(f.ok()) << f.status();
  EXPECT_FALSE(f->has_value());
  EXPECT_GE(std::chrono::steady_clock::now() - start, milliseconds(30));
}

TEST_F(SocketCanReadTest, WrongSizedDatagramIsDataLoss) {
  const uint8_t junk[20] = {};
  Send(junk, sizeof junk);
  absl::StatusOr<std::optional<CanFrame>> f = reader_->Read(milliseconds(1000));
  ASSERT_FALSE(f.ok());
  EXPECT_EQ(f.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(f.status().message().find("20 bytes"), std::string::npos) << f.status();
  const uint8_t big[100] = {};  // longer than a canfd_frame: refused, not truncated
  Send(big, sizeof big);
  f = reader_->Read(milliseconds(1000));
  ASSERT_FALSE(f.ok());
  EXPECT_EQ(f.status().code(), absl::StatusCode::kDataLoss);
}

TEST(CanFrameFromKernelTest, RejectsAnInvalidClassicLength) {
  canfd_frame k{};
  k.can_id = 0x100;
  k.len = 9;  // a classic frame cannot carry 9 bytes
  const absl::StatusOr<CanFrame> f = CanFrameFromKernel(k, CAN_MTU, "can0", CanTime{});
  ASSERT_FALSE(f.ok());
  EXPECT_EQ(f.status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace linecal

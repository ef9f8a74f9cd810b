#include "station/sensors/lidar/pcd.h"

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <tuple>

#include "gtest/gtest.h"
#include "tests/support/external_data.h"

namespace linecal {
namespace {

std::filesystem::path TempPath(const std::string& name) {
  return std::filesystem::temp_directory_path() /
         (std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "_" +
          name);
}

void WriteText(const std::filesystem::path& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

std::vector<LidarPoint> RandomPoints(int n) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> coord(-100.0f, 100.0f);
  std::uniform_int_distribution<int> ring(0, 63);
  std::vector<LidarPoint> points(n);
  for (int i = 0; i < n; ++i) {
    points[i].x = coord(rng);
    points[i].y = coord(rng);
    points[i].z = coord(rng) * 0.1f;
    points[i].intensity = static_cast<float>(i % 256);
    points[i].ring = static_cast<std::uint16_t>(ring(rng));
    // ns since the epoch in 2023: beyond 2^53, so only an exact int64 field keeps it.
    points[i].time_ns = 1'673'400'471'737'763'166 + 1'000'003LL * i;
  }
  return points;
}

TEST(Pcd, RoundTripsEveryEncodingExactly) {
  const std::vector<LidarPoint> points = RandomPoints(1000);
  for (PcdEncoding e :
       {PcdEncoding::kAscii, PcdEncoding::kBinary, PcdEncoding::kBinaryCompressed}) {
    const std::filesystem::path path = TempPath("cloud.pcd");
    ASSERT_TRUE(WritePcd(path, points, e).ok());
    absl::StatusOr<PcdCloud> cloud = ReadPcd(path);
    ASSERT_TRUE(cloud.ok()) << cloud.status();
    EXPECT_TRUE(cloud->has_intensity);
    EXPECT_TRUE(cloud->has_ring);
    EXPECT_TRUE(cloud->has_time);
    EXPECT_EQ(cloud->non_finite_dropped, 0);
    ASSERT_EQ(cloud->points.size(), points.size());
    for (std::size_t i = 0; i < points.size(); ++i) {
      ASSERT_EQ(cloud->points[i], points[i])
          << "encoding " << static_cast<int>(e) << " point " << i;
    }
    std::filesystem::remove(path);
  }
}

TEST(Pcd, WritesTheFieldsOfTheInterface) {
  const std::filesystem::path path = TempPath("h.pcd");
  ASSERT_TRUE(WritePcd(path, RandomPoints(3)).ok());
  std::ifstream in(path, std::ios::binary);
  std::string header, line;
  while (std::getline(in, line) && line.rfind("DATA", 0) != 0) header += line + "\n";
  EXPECT_NE(header.find("FIELDS x y z intensity ring time\n"), std::string::npos) << header;
  EXPECT_NE(header.find("SIZE 4 4 4 4 2 8\n"), std::string::npos) << header;
  EXPECT_NE(header.find("TYPE F F F F U I\n"), std::string::npos) << header;
  EXPECT_NE(header.find("POINTS 3\n"), std::string::npos) << header;
  EXPECT_EQ(line, "DATA binary");
  std::filesystem::remove(path);
}

TEST(Pcd, EmptyCloudsRoundTrip) {
  for (PcdEncoding e :
       {PcdEncoding::kAscii, PcdEncoding::kBinary, PcdEncoding::kBinaryCompressed}) {
    const std::filesystem::path path = TempPath("empty.pcd");
    ASSERT_TRUE(WritePcd(path, {}, e).ok());
    absl::StatusOr<PcdCloud> cloud = ReadPcd(path);
    ASSERT_TRUE(cloud.ok()) << cloud.status();
    EXPECT_TRUE(cloud->points.empty());
    EXPECT_TRUE(cloud->has_time);
    std::filesystem::remove(path);
  }
}

// The real recordings' reference decodes (docs/external-data.md), written by another program.
TEST(Pcd, ReadsTheReferenceScans) {
  LINECAL_EXTERNAL_OR_SKIP(vlp16_reference, "lidar/vlp16/reference_scan.pcd");
  LINECAL_EXTERNAL_OR_SKIP(pandar64_reference, "lidar/pandar64/reference_scan.pcd");
  // nebula's fields: x y z intensity(U1) return_type channel azimuth elevation distance
  // time_stamp. "channel" and "time_stamp" are not read as ring and time (see pcd.h).
  absl::StatusOr<PcdCloud> vlp = ReadPcd(vlp16_reference);
  ASSERT_TRUE(vlp.ok()) << vlp.status();
  ASSERT_EQ(vlp->points.size(), 14831u);
  EXPECT_TRUE(vlp->has_intensity);
  EXPECT_FALSE(vlp->has_ring);
  EXPECT_FALSE(vlp->has_time);
  // The first point, as printed by an independent reader of the file (Python's struct).
  EXPECT_FLOAT_EQ(vlp->points[0].x, 0.9658387303352356f);
  EXPECT_FLOAT_EQ(vlp->points[0].y, -0.005225741770118475f);
  EXPECT_FLOAT_EQ(vlp->points[0].z, 0.0168590247631073f);
  EXPECT_EQ(vlp->points[0].intensity, 100.0f);

  absl::StatusOr<PcdCloud> p64 = ReadPcd(pandar64_reference);
  ASSERT_TRUE(p64.ok()) << p64.status();
  ASSERT_EQ(p64->points.size(), 93591u);
  EXPECT_FALSE(p64->has_intensity);
  EXPECT_FLOAT_EQ(p64->points[0].y, 1.391494631767273f);
}

TEST(Pcd, ReadsOtherFieldTypesOrganizedCloudsAndSecondsAsTime) {
  const std::filesystem::path path = TempPath("ascii.pcd");
  WriteText(path,
            "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity ring time\n"
            "SIZE 8 8 8 1 1 8\nTYPE F F F U U F\nCOUNT 1 1 1 1 1 1\n"
            "WIDTH 2\nHEIGHT 2\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA ascii\n"
            "1.5 -2.25 3 200 7 0.000000123\n"
            "nan nan nan 0 0 0\n"
            "4 5 6 1 2 1.5\n"
            "7 8 9 2 3 -0.5\n");
  absl::StatusOr<PcdCloud> cloud = ReadPcd(path);
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  EXPECT_EQ(cloud->non_finite_dropped, 1);
  ASSERT_EQ(cloud->points.size(), 3u);
  EXPECT_EQ(cloud->points[0].x, 1.5f);
  EXPECT_EQ(cloud->points[0].y, -2.25f);
  EXPECT_EQ(cloud->points[0].intensity, 200.0f);
  EXPECT_EQ(cloud->points[0].ring, 7);
  EXPECT_EQ(cloud->points[0].time_ns, 123);  // floating-point times are seconds
  EXPECT_EQ(cloud->points[1].time_ns, 1'500'000'000);
  EXPECT_EQ(cloud->points[2].time_ns, -500'000'000);
  std::filesystem::remove(path);
}

TEST(Pcd, RejectsCompressedBodiesWhoseSizesLie) {
  const std::filesystem::path path = TempPath("lzf.pcd");
  ASSERT_TRUE(WritePcd(path, RandomPoints(50), PcdEncoding::kBinaryCompressed).ok());
  std::ifstream in(path, std::ios::binary);
  const std::string good((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  in.close();
  const std::size_t body = good.find("DATA binary_compressed\n") + 23;
  // Bytes 0-3 of the body: compressed size; 4-7: uncompressed size (50 × 26 bytes).
  for (const auto& [at, value, message] :
       std::vector<std::tuple<std::size_t, std::uint32_t, std::string>>{
           {0, 0x7FFFFFFF, "compressed size 2147483647 exceeds the file"},
           {4, 1299, "uncompressed size 1299 is not 1300"}}) {
    std::string bad = good;
    std::memcpy(&bad[body + at], &value, 4);
    WriteText(path, bad);
    const absl::StatusOr<PcdCloud> cloud = ReadPcd(path);
    ASSERT_FALSE(cloud.ok()) << message;
    EXPECT_NE(cloud.status().message().find(message), std::string::npos) << cloud.status();
  }
  // A stream that decompresses to the wrong size.
  std::string bad = good;
  for (std::size_t i = body + 8; i < bad.size(); ++i) bad[i] = 0;
  WriteText(path, bad);
  EXPECT_EQ(ReadPcd(path).status().code(), absl::StatusCode::kInvalidArgument);
  std::filesystem::remove(path);
}

TEST(Pcd, RejectsBrokenFilesWithoutTrustingTheirHeader) {
  const std::filesystem::path path = TempPath("bad.pcd");
  const std::string head = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n";
  struct Case {
    std::string text;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"hello\n", "unknown header entry 'hello'"},
      // The fuzzer's find: a first line PCL does not know made its reader crash.
      {"c .PCD v0.7\n" + head + "WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA binary\n123456789012",
       "unknown header entry 'c'"},
      {"VERSION 0.7\nSIZE 4 4 4\nFIELDS x y z\nTYPE F F F\nWIDTH 1\nHEIGHT 1\nPOINTS 1\n"
       "DATA ascii\n1 2 3\n",
       "header entry FIELDS out of order"},
      {"", "no DATA line"},
      // Four billion points in a file of a few bytes: refused before anything is allocated.
      {head + "WIDTH 1000000000\nHEIGHT 1\nPOINTS 1000000000\nDATA binary\nabc", "do not fit"},
      {head + "WIDTH 4000000000\nHEIGHT 1\nPOINTS 4000000000\nDATA binary\nabc", "is not WIDTH"},
      {head + "WIDTH 2000000\nHEIGHT 1\nPOINTS 2000000\nDATA binary_compressed\nabcdefgh",
       "do not fit"},
      {head + "WIDTH 2\nHEIGHT 2\nPOINTS 3\nDATA ascii\n1 2 3\n", "is not WIDTH"},
      {head + "WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA binary\n1234", "do not fit"},
      {"VERSION 0.7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\n"
       "DATA ascii\n1 2\n",
       "no x, y and z fields"},
      {"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 3\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n"
       "POINTS 1\nDATA ascii\n1 2 3\n",
       "SIZE 3"},
      {"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 2\nWIDTH 1\nHEIGHT 1\n"
       "POINTS 1\nDATA ascii\n1 2 3 4\n",
       "field z is not one number per point"},
      {head + "WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA jpeg\n", "DATA 'jpeg'"},
  };
  for (const Case& c : cases) {
    WriteText(path, c.text);
    const absl::StatusOr<PcdCloud> cloud = ReadPcd(path);
    ASSERT_FALSE(cloud.ok()) << c.message;
    EXPECT_EQ(cloud.status().code(), absl::StatusCode::kInvalidArgument) << c.message;
    EXPECT_NE(cloud.status().message().find(c.message), std::string::npos)
        << cloud.status().message() << " should contain " << c.message;
    EXPECT_NE(cloud.status().message().find(path.string()), std::string::npos);
  }
  std::filesystem::remove(path);
  EXPECT_EQ(ReadPcd("/nonexistent/x.pcd").status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(WritePcd("/nonexistent/dir/x.pcd", RandomPoints(2)).code(),
            absl::StatusCode::kInternal);
}

}  // namespace
}  // namespace linecal

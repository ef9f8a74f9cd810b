// linecal lidar topview: a bird's-eye picture of LiDAR scans, for people to look at.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>

#include "absl/strings/str_cat.h"
#include "station/io/image_io.h"
#include "station/sensors/lidar/pcd.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "lidar topview";

// Height colour map: blue at z_min through green to red at z_max.
std::array<std::uint8_t, 3> HeightColour(double t) {
  t = std::clamp(t, 0.0, 1.0);
  const double r = std::clamp(2.0 * t - 0.5, 0.0, 1.0);
  const double g = 1.0 - std::abs(2.0 * t - 1.0);
  const double b = std::clamp(1.5 - 2.0 * t, 0.0, 1.0);
  return {static_cast<std::uint8_t>(255 * r), static_cast<std::uint8_t>(255 * g),
          static_cast<std::uint8_t>(255 * b)};
}

}  // namespace

int RunLidarTopview(const Args& args) {
  cli::CommandLine cl(
      "linecal lidar topview --pcd FILE [--pcd FILE ...] --out FILE.png [--range M] [--size PX]",
      "Draws LiDAR scans seen from above in the LiDAR frame: the sensor at the centre, its azimuth "
      "0 "
      "(+y) up, points coloured by height from blue (low) to red (high), grey range rings every 5 "
      "m.",
      {{"pcd", "FILE", "a scan (PCD)", true, true},
       {"out", "FILE.png", "the picture to write", true},
       {"range", "M", "metres from the centre to the picture's edge (default 15)"},
       {"size", "PX", "picture width and height in pixels (default 1000)"},
       {"z-min", "M", "height shown blue (default -2)"},
       {"z-max", "M", "height shown red (default 2)"}});
  if (auto code = cli::ParseOrExit(cl, kCommand, args)) return *code;
  absl::StatusOr<double> range = cl.GetDouble("range", 15.0);
  absl::StatusOr<int> size = cl.GetInt("size", 1000);
  absl::StatusOr<double> z_min = cl.GetDouble("z-min", -2.0);
  absl::StatusOr<double> z_max = cl.GetDouble("z-max", 2.0);
  for (const absl::Status& s : {range.status(), size.status(), z_min.status(), z_max.status()}) {
    if (!s.ok()) return cli::BadInput(kCommand, std::string(s.message()));
  }
  if (*range <= 0)
    return cli::BadInput(kCommand, absl::StrCat("--range: must be > 0, got ", *range));
  // 16 px is too small to show anything; 8192 keeps the picture within a few hundred MB.
  if (*size < 16 || *size > 8192)
    return cli::BadInput(kCommand, absl::StrCat("--size: must be in 16..8192, got ", *size));
  if (*z_max <= *z_min) return cli::BadInput(kCommand, "--z-max must be above --z-min");

  const int n = *size;
  const double px_per_m = n / (2.0 * *range);
  RgbImage img(n, n, {16, 16, 16});
  const auto plot = [&](double x, double y, std::array<std::uint8_t, 3> c) {
    // +y (azimuth 0) up, +x right.
    const int u = static_cast<int>(std::lround(n / 2.0 + x * px_per_m));
    const int v = static_cast<int>(std::lround(n / 2.0 - y * px_per_m));
    if (u < 0 || v < 0 || u >= n || v >= n) return;
    std::copy(c.begin(), c.end(), img.at(u, v));
  };
  constexpr double kRingStepM = 5.0;
  for (double r = kRingStepM; r <= *range * std::sqrt(2.0); r += kRingStepM) {
    const int steps = static_cast<int>(2 * std::numbers::pi * r * px_per_m * 2);
    for (int k = 0; k < steps; ++k) {
      const double a = 2 * std::numbers::pi * k / steps;
      plot(r * std::cos(a), r * std::sin(a), {70, 70, 70});
    }
  }
  size_t points = 0;
  for (const std::string& path : cl.GetAll("pcd")) {
    absl::StatusOr<PcdCloud> cloud = ReadPcd(path);
    if (!cloud.ok()) return cli::BadInput(kCommand, std::string(cloud.status().message()));
    for (const LidarPoint& p : cloud->points)
      plot(p.x, p.y, HeightColour((p.z - *z_min) / (*z_max - *z_min)));
    points += cloud->points.size();
  }
  for (int d = -4; d <= 4; ++d) {
    plot(d / px_per_m, 0, {255, 255, 255});
    plot(0, d / px_per_m, {255, 255, 255});
  }
  if (absl::Status s = WritePngRgb(cl.Get("out"), img); !s.ok())
    return cli::BadInput(kCommand, std::string(s.message()));
  std::printf("%zu points drawn to %s (%d x %d px, %.1f m across)\n", points, cl.Get("out").c_str(),
              n, n, 2 * *range);
  return cli::kExitOk;
}

}  // namespace linecal::tools

// Fuzzes the capture reader's manifest checks (station/capture): a scratch capture directory
// holds the reference station and car and small data files; each input becomes its
// manifest.json and the capture is read as `linecal calibrate` and the replay source read it.
// Invariants: no crash; a refusal is InvalidArgument or NotFound and names manifest.json or
// the file it refuses; an accepted capture has only sensors of the car and paths inside DIR.
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "absl/strings/match.h"
#include "station/capture/capture.h"

namespace {

namespace fs = std::filesystem;

const fs::path& Dir() {
  static const fs::path dir = [] {
    const fs::path base =
        fs::is_directory("/dev/shm") ? fs::path("/dev/shm") : fs::temp_directory_path();
    const fs::path d = base / ("linecal_manifest_fuzz_" + std::to_string(getpid()));
    fs::create_directories(d);
    const fs::path deploy = LINECAL_SOURCE_DIR "/deploy";
    const auto copy = fs::copy_options::overwrite_existing;
    fs::copy_file(deploy / "stations/reference.json", d / "station.json", copy);
    fs::copy_file(deploy / "cars/reference.json", d / "car.json", copy);
    fs::copy_file(deploy / "cars/Pandar64.csv", d / "Pandar64.csv", copy);
    // The files the seed manifests name: the reader checks that they exist and are not
    // empty, not what they hold.
    for (const char* f : {"front_camera/frame-000000.png", "roof_lidar/scan-000000.pcd",
                          "roof_lidar/packets.pcap", "front_radar/can.log"}) {
      fs::create_directories((d / f).parent_path());
      std::ofstream(d / f) << "x";
    }
    return d;
  }();
  return dir;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  {
    std::ofstream out(Dir() / "manifest.json", std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  }
  const absl::StatusOr<linecal::Capture> capture = linecal::ReadCapture(Dir().string());
  if (!capture.ok()) {
    const absl::StatusCode code = capture.status().code();
    if (code != absl::StatusCode::kInvalidArgument && code != absl::StatusCode::kNotFound)
      __builtin_trap();
    if (!absl::StrContains(capture.status().message(), ".json")) __builtin_trap();
    return 0;
  }
  for (const linecal::CaptureSensor& s : capture->manifest.sensors) {
    if (capture->car.FindSensor(s.name) == nullptr) __builtin_trap();
  }
  return 0;
}

// Fuzzes a configuration file reader (LINECAL_FUZZ_CONFIG: 0 linecald's config, 1 a station
// layout, 2 a car model; one target each, seeded with the files of deploy/). Each input is
// written to a scratch file and read as the daemon reads it. Invariants: no crash; a refusal
// is InvalidArgument (NotFound for a file the config names) and names the file.
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "absl/strings/match.h"
#include "daemon/core/daemon_config.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"

namespace {

namespace fs = std::filesystem;

// Beside deploy/cars/Pandar64.csv is where a car model's relative angle file names resolve;
// a scratch directory per process, with a copy of it.
const fs::path& Scratch() {
  static const fs::path path = [] {
    const fs::path base =
        fs::is_directory("/dev/shm") ? fs::path("/dev/shm") : fs::temp_directory_path();
    const fs::path dir = base / ("linecal_config_fuzz_" + std::to_string(getpid()));
    fs::create_directories(dir);
    fs::copy_file(LINECAL_SOURCE_DIR "/deploy/cars/Pandar64.csv", dir / "Pandar64.csv",
                  fs::copy_options::overwrite_existing);
    return dir / "input.json";
  }();
  return path;
}

template <typename T>
void Check(const absl::StatusOr<T>& result) {
  if (result.ok()) return;
  const absl::StatusCode code = result.status().code();
  if (code != absl::StatusCode::kInvalidArgument && code != absl::StatusCode::kNotFound)
    __builtin_trap();
  if (!absl::StrContains(result.status().message(), "input.json")) __builtin_trap();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  {
    std::ofstream out(Scratch(), std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  }
#if LINECAL_FUZZ_CONFIG == 0
  Check(linecal::ReadDaemonConfig(Scratch().string()));
#elif LINECAL_FUZZ_CONFIG == 1
  Check(linecal::ReadStationLayout(Scratch().string()));
#else
  Check(linecal::ReadCarModel(Scratch().string()));
#endif
  return 0;
}

// The console tests' station: a StationCore over the repository's reference station and car
// (deploy/), with its store and data root in a scratch folder, and the console's static files.
#ifndef LINECAL_TESTS_DAEMON_WEB_REFERENCE_CORE_H_
#define LINECAL_TESTS_DAEMON_WEB_REFERENCE_CORE_H_

#include <filesystem>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "daemon/core/station_core.h"

namespace linecal::testing_web {

inline const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
inline const std::string kStatic = std::string(LINECAL_SOURCE_DIR) + "/daemon/web/static";

// The core of the reference station and car with `dir`/station.db and `dir`/data.
inline absl::StatusOr<std::unique_ptr<StationCore>> ReferenceCore(
    const std::filesystem::path& dir) {
  StationCoreConfig config;
  config.station_path = kDeploy + "/stations/reference.json";
  config.car_model_paths = {kDeploy + "/cars/reference.json"};
  config.db_path = (dir / "station.db").string();
  config.data_root = (dir / "data").string();
  return StationCore::Create(config);
}

}  // namespace linecal::testing_web

#endif  // LINECAL_TESTS_DAEMON_WEB_REFERENCE_CORE_H_

#pragma once
// The reference car cut down to a few sensors, for daemon and client tests whose cycles must
// be short (the front camera and radar: a cycle of well under a second in Release).

#include <algorithm>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace linecal::testing_daemon {

// Writes the reference car cut down to the sensors `names` (in the car's order) to `path`,
// with car model id `id`.
inline void WriteCutDownCar(const std::string& path, const std::vector<std::string>& names,
                            const std::string& id = "reference") {
  std::ifstream in(std::string(LINECAL_SOURCE_DIR) + "/deploy/cars/reference.json");
  nlohmann::json car = nlohmann::json::parse(in);
  nlohmann::json kept = nlohmann::json::array();
  for (const nlohmann::json& s : car["sensors"]) {
    if (std::find(names.begin(), names.end(), s["name"].get<std::string>()) != names.end())
      kept.push_back(s);
  }
  car["sensors"] = kept;
  car["id"] = id;
  // Angle files are named relative to the car file: point them at the reference's.
  for (nlohmann::json& s : car["sensors"]) {
    if (s.contains("angles_file")) {
      s["angles_file"] =
          std::string(LINECAL_SOURCE_DIR) + "/deploy/cars/" + s["angles_file"].get<std::string>();
    }
  }
  std::ofstream(path) << car.dump(2);
}

// The front camera and front radar only.
inline void WriteTwoSensorCar(const std::string& path, const std::string& id = "reference") {
  WriteCutDownCar(path, {"front_camera", "front_radar"}, id);
}

}  // namespace linecal::testing_daemon

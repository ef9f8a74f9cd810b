#pragma once
// The reference car cut down to its front camera and front radar, for daemon and client tests
// whose cycles must be short: a cycle of well under a second in Release.

#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

namespace linecal::testing_daemon {

// Writes the cut-down car model to `path` with car model id `id`.
inline void WriteTwoSensorCar(const std::string& path, const std::string& id = "reference") {
  std::ifstream in(std::string(LINECAL_SOURCE_DIR) + "/deploy/cars/reference.json");
  nlohmann::json car = nlohmann::json::parse(in);
  nlohmann::json kept = nlohmann::json::array();
  for (const nlohmann::json& s : car["sensors"]) {
    if (s["name"] == "front_camera" || s["name"] == "front_radar") kept.push_back(s);
  }
  car["sensors"] = kept;
  car["id"] = id;
  std::ofstream(path) << car.dump(2);
}

}  // namespace linecal::testing_daemon

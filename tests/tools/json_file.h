#pragma once
// Reads a JSON file a `linecal` command wrote or a test prepared, for the tools tests.

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

namespace linecal::testing_tools {

// The parsed document at `path`; throws nlohmann::json::parse_error when the file is missing
// or not JSON, which fails the calling test with the parser's message.
inline nlohmann::json ReadJson(const std::filesystem::path& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

}  // namespace linecal::testing_tools

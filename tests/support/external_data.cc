#include "tests/support/external_data.h"

#include <cstdlib>
#include <filesystem>

namespace linecal::testing_support {
namespace {

// Defaults set by tests/support/CMakeLists.txt from the CMake cache.
const char* VariableName(ExternalRoot root) {
  return root == ExternalRoot::kData ? "LINECAL_EXTERNAL_DATA" : "LINECAL_EXTERNAL_SPEC";
}

std::string RootDir(ExternalRoot root) {
  const char* env = std::getenv(VariableName(root));
  if (env != nullptr && *env != '\0') return env;
  return root == ExternalRoot::kData ? LINECAL_EXTERNAL_DATA_DEFAULT
                                     : LINECAL_EXTERNAL_SPEC_DEFAULT;
}

}  // namespace

std::string ExternalPath(std::string_view relative, ExternalRoot root) {
  return (std::filesystem::path(RootDir(root)) / relative).lexically_normal().string();
}

std::string MissingExternalMessage(const std::string& path, ExternalRoot root) {
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) return "";
  return "external test data not found: " + path + " (set " + VariableName(root) + ", now '" +
         RootDir(root) + "'; docs/external-data.md)";
}

}  // namespace linecal::testing_support

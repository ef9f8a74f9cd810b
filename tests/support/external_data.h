#pragma once
// The one place where tests find data that is not part of the repository: real LiDAR
// recordings, the radar DBC, real photographs of calibration boards and the reference PDFs of
// the boards (docs/external-data.md). A clone without that folder still passes every test:
// the tests that need it are skipped, naming the missing path and the variable that moves it.
//
// Roots, each an environment variable first, else the CMake cache variable of the same name:
//   LINECAL_EXTERNAL_DATA   recordings and photos
//   LINECAL_EXTERNAL_SPEC   the boards' reference PDFs (patterns/)
//
// In a test body:
//   LINECAL_EXTERNAL_OR_SKIP(pcap, "lidar/vlp16/packets.pcap");
//   ... use pcap (a std::string) ...

#include <string>
#include <string_view>

#include "gtest/gtest.h"

namespace linecal::testing_support {

// Which root a relative path lives under.
enum class ExternalRoot { kData, kSpec };

// Absolute path of `relative` under the root (it need not exist). Cost: one getenv.
std::string ExternalPath(std::string_view relative, ExternalRoot root = ExternalRoot::kData);

// Empty when `path` exists; otherwise the skip message: the missing path, the variable that
// names the root and its current value.
std::string MissingExternalMessage(const std::string& path,
                                   ExternalRoot root = ExternalRoot::kData);

}  // namespace linecal::testing_support

// Declares `const std::string var` = the path of `relative` under the data root, or skips
// the test (GTEST_SKIP, so only in a test body or a void function of one) when it is missing.
#define LINECAL_EXTERNAL_OR_SKIP(var, relative) \
  LINECAL_EXTERNAL_IN_OR_SKIP(var, relative, ::linecal::testing_support::ExternalRoot::kData)

#define LINECAL_EXTERNAL_IN_OR_SKIP(var, relative, root)                            \
  const std::string var = ::linecal::testing_support::ExternalPath(relative, root); \
  if (const std::string missing_##var =                                             \
          ::linecal::testing_support::MissingExternalMessage(var, root);            \
      !missing_##var.empty())                                                       \
  GTEST_SKIP() << missing_##var

#pragma once
// A fresh, empty scratch directory per test: unique to the test process and the test, since
// ctest runs tests of one binary in parallel processes.

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>

namespace linecal::testing_daemon {

// TempDir()/<prefix>_<pid>_<test name>, removed first if it exists, then created.
inline std::filesystem::path FreshTestDir(const std::string& prefix) {
  const std::filesystem::path dir = std::filesystem::path(testing::TempDir()) /
                                    (prefix + "_" + std::to_string(::getpid()) + "_" +
                                     testing::UnitTest::GetInstance()->current_test_info()->name());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace linecal::testing_daemon

#pragma once
// A test's scratch file or directory under testing::TempDir(), removed when the test (or the
// fixture that owns it) ends, passed or failed. Tests that named a scratch path by their
// process id and never removed it left a copy of every capture, log and socket in /tmp on each
// run of the suite (300 entries after a day of runs on the development machine).

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>
#include <system_error>

namespace linecal::testing_support {

class ScopedPath {
 public:
  // TempDir()/<stem>_<pid><extension>: unique per process, since ctest runs every test in a
  // process of its own, in parallel. Whatever a killed run left there is removed first.
  explicit ScopedPath(const std::string& stem, const std::string& extension = "")
      : path_(std::filesystem::path(testing::TempDir()) /
              (stem + "_" + std::to_string(::getpid()) + extension)) {
    Remove();
  }
  ~ScopedPath() { Remove(); }
  ScopedPath(const ScopedPath&) = delete;
  ScopedPath& operator=(const ScopedPath&) = delete;

  const std::filesystem::path& path() const { return path_; }
  std::string string() const { return path_.string(); }

 private:
  // Errors are ignored: a scratch path that cannot be removed must not fail the test.
  void Remove() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  std::filesystem::path path_;
};

}  // namespace linecal::testing_support

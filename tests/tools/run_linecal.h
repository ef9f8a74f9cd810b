#pragma once
// Runs the built `linecal` binary from a test, capturing stdout, stderr and the exit code.

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace linecal::testing_tools {

struct LinecalRun {
  int exit_code = -1;  // -1: did not run or did not exit normally
  std::string out;
  std::string err;
};

// Runs `linecal <args>` (args are passed through the shell: quote paths with spaces).
inline LinecalRun RunLinecal(const std::string& args) {
  const std::string binary = std::string(LINECAL_BINARY_DIR) + "/bin/linecal";
  const std::filesystem::path err_path = std::filesystem::path(::testing::TempDir()) /
                                         ("linecal_stderr_" + std::to_string(::getpid()) + ".txt");
  const std::string command = binary + " " + args + " 2>'" + err_path.string() + "'";
  LinecalRun run;
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return run;
  char buffer[4096];
  std::size_t n;
  while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) run.out.append(buffer, n);
  const int status = pclose(pipe);
  run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream err(err_path);
  std::stringstream text;
  text << err.rdbuf();
  run.err = text.str();
  std::filesystem::remove(err_path);
  return run;
}

// " --station <source>/deploy/stations/reference.json --car <source>/deploy/cars/reference.json":
// the reference station and car as the flags of a linecal command.
inline std::string ReferenceStationAndCarFlags() {
  const std::string deploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
  return " --station " + deploy + "/stations/reference.json --car " + deploy +
         "/cars/reference.json";
}

}  // namespace linecal::testing_tools

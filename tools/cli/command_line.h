#pragma once
// A small declarative command-line parser for the linecal subcommands.
//
// Every subcommand declares its options; the parser handles `--help`, rejects unknown
// options, missing values and bad numbers with a one-line message naming the option and the
// value, and the caller maps that to exit code 2 (docs/interfaces.md).

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace linecal::cli {

// Exit codes fixed by docs/interfaces.md.
enum ExitCode : int {
  kExitOk = 0,        // success
  kExitNegative = 1,  // the work ran, the answer is negative (no board, out of tolerance)
  kExitBadInput = 2,  // bad usage or bad input
};

struct OptionSpec {
  std::string name;     // without the leading "--"
  std::string metavar;  // empty: a boolean flag that takes no value
  std::string help;
  bool required = false;
  bool repeated = false;  // may be given several times; GetAll() returns every value
  // A positional argument (given without "--name"); positionals are filled in the order
  // they are declared. Get(name) reads them like options.
  bool positional = false;
};

class CommandLine {
 public:
  // `usage`: the synopsis line(s) after "usage: "; `summary`: one paragraph.
  CommandLine(std::string usage, std::string summary, std::vector<OptionSpec> options);

  // Parses args (without the program and subcommand names). Returns an error whose message
  // names the offending option or value. `--help` sets help_requested() and succeeds.
  absl::Status Parse(const std::vector<std::string>& args);

  bool help_requested() const { return help_requested_; }
  std::string Help() const;

  bool Has(const std::string& name) const;
  // The value of a single-valued option, or `fallback` when it was not given.
  std::string Get(const std::string& name, const std::string& fallback = "") const;
  std::vector<std::string> GetAll(const std::string& name) const;
  // Numeric values, with errors that name the option and the value.
  absl::StatusOr<double> GetDouble(const std::string& name, double fallback) const;
  absl::StatusOr<int> GetInt(const std::string& name, int fallback) const;

 private:
  const OptionSpec* Find(const std::string& name) const;

  std::string usage_;
  std::string summary_;
  std::vector<OptionSpec> options_;
  std::map<std::string, std::vector<std::string>> values_;
  bool help_requested_ = false;
};

}  // namespace linecal::cli

namespace linecal::cli {

// The common opening of a subcommand: parses `args` into `cl`. Returns an exit code when the
// subcommand should stop now (0 after printing --help; 2 after printing
// "linecal <command>: <problem>" to stderr), or nullopt to go on.
std::optional<int> ParseOrExit(CommandLine& cl, const std::string& command,
                               const std::vector<std::string>& args);

// "1.5,-2,3" as numbers; an error naming `what` (a flag, "--lane") and the bad part, or the
// count when `count` > 0 and another count was given. O(length).
absl::StatusOr<std::vector<double>> ParseNumberList(const std::string& text,
                                                    const std::string& what, size_t count = 0);

// Prints "linecal <command>: <message>" to stderr and returns kExitBadInput.
int BadInput(const std::string& command, const std::string& message);

}  // namespace linecal::cli

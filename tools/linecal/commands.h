#pragma once
// The subcommands of `linecal`. Each takes the arguments after its own name and returns the
// process exit code (cli::ExitCode). The table in main.cc maps names to these functions.

#include <string>
#include <vector>

namespace linecal::tools {

using Args = std::vector<std::string>;


}  // namespace linecal::tools

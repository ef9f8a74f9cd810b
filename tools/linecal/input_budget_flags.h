#pragma once
// The --max-* options of the commands that read captures (`capture check`, `calibrate`): the
// input budget of docs/capture-format.md ("Input budget"), each defaulting to InputBudget's.
// Both commands take the same options, so that they can be given the same budget.

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "station/io/input_budget.h"
#include "tools/cli/command_line.h"

namespace linecal::tools {

// Option name and the field it sets, in InputBudget's order.
inline std::vector<std::pair<std::string, std::int64_t InputBudget::*>> InputBudgetFlagFields() {
  return {{"max-file-bytes", &InputBudget::max_file_bytes},
          {"max-image-pixels", &InputBudget::max_image_pixels},
          {"max-scan-points", &InputBudget::max_scan_points},
          {"max-can-lines", &InputBudget::max_can_lines},
          {"max-manifest-frames", &InputBudget::max_manifest_frames}};
}

// The option specs, with InputBudget's defaults in their help.
inline std::vector<cli::OptionSpec> InputBudgetOptions() {
  const InputBudget defaults;
  std::vector<cli::OptionSpec> specs;
  for (const auto& [name, field] : InputBudgetFlagFields()) {
    specs.push_back(
        {name, "N",
         absl::StrCat("input budget (docs/capture-format.md), default ", defaults.*field)});
  }
  return specs;
}

// The budget the options give; InvalidArgument "--max-image-pixels 'x': must be an integer
// >= 1" for a bad value. Cost: O(1).
inline absl::StatusOr<InputBudget> InputBudgetFromFlags(const cli::CommandLine& cl) {
  InputBudget budget;
  for (const auto& [name, field] : InputBudgetFlagFields()) {
    if (!cl.Has(name)) continue;
    const std::string text = cl.Get(name);
    std::int64_t value = 0;
    if (!absl::SimpleAtoi(text, &value) || value < 1) {
      return absl::InvalidArgumentError(
          absl::StrCat("--", name, " ", Snippet(text, 24), ": must be an integer >= 1"));
    }
    budget.*field = value;
  }
  return budget;
}

}  // namespace linecal::tools

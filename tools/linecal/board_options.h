#pragma once
// The command-line options that choose a board (docs/boards.md), shared by every subcommand that
// takes --board: --board NAME [--scale S] [--cols N --rows M] [--square METRES]
// [--spacing METRES --diameter METRES] [--asymmetric] [--light-circles] [--border-bits 1|2].

#include <vector>

#include "absl/status/statusor.h"
#include "detectors/boards/board.h"
#include "tools/cli/command_line.h"

namespace linecal::tools {

// The option specs to append to a subcommand's own. `board_required`: --board must be given.
std::vector<cli::OptionSpec> BoardOptionSpecs(bool board_required);

// The board the parsed options describe. Errors (InvalidArgument, one line naming the option
// and the value): an unknown board name (the message lists the names), --cols/--rows with a
// board other than checker and circle_grid, --square with one other than checker,
// --spacing/--diameter/--asymmetric/--light-circles with one other than circle_grid,
// --border-bits with one other than apriltag, a value that is not a number, and values
// ValidateBoardParams refuses.
absl::StatusOr<BoardParams> BoardParamsFromCommandLine(const cli::CommandLine& cl);

}  // namespace linecal::tools

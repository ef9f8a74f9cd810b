#pragma once
// The command-line options that choose a board (docs/boards.md), shared by every subcommand that
// takes --board: --board NAME [--scale S] [--cols N --rows M] [--square METRES] [--gap METRES]
// [--spacing METRES --diameter METRES] [--asymmetric | --hexagonal] [--light-circles]
// [--border-bits 1|2] [--marker METRES] [--legacy-pattern] [--dictionary NAME],
// or --target FILE (target_file.h).

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "detectors/boards/board.h"
#include "tools/cli/command_line.h"

namespace linecal::tools {

// The option specs to append to a subcommand's own: --board NAME or --target FILE (one of
// them is required, checked by BoardParamsFromCommandLine) and the board's parameters.
std::vector<cli::OptionSpec> BoardOptionSpecs();

// The board the parsed options describe. Errors (InvalidArgument, one line naming the option
// and the value): neither --board nor --target; an unknown board name (the message lists the
// names), --cols/--rows with a board other than checker, circle_grid and square_grid, --square
// with one other than checker and square_grid, --gap with one other than square_grid,
// --marker/--legacy-pattern/--dictionary with one other than charuco, a dictionary name that is
// not one of OpenCV's predefined ones (the message lists them),
// --spacing/--diameter/--asymmetric/--hexagonal/--light-circles with one other than
// circle_grid, --border-bits with one other than apriltag, a value that is not a number, and
// values ValidateBoardParams refuses. With --target: the file's errors (target_file.h), any
// board option but --diameter and --light-circles (which a Kalibr file cannot give), and those
// two for a board other than a circle grid.
absl::StatusOr<BoardParams> BoardParamsFromCommandLine(const cli::CommandLine& cl);

// What is wrong with the field of `p` that `e` names, with its value and range ("1 is outside
// [2, 100]"); for messages that name the field their own way (an option, a file's key).
std::string DescribeParamsError(BoardParamsError e, const BoardParams& p);

}  // namespace linecal::tools

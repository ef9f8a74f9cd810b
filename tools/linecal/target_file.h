#pragma once
// Boards given as a file instead of flags (`--target FILE`, docs/boards.md "Target files"):
// Kalibr's calibration target YAML, the file a Kalibr user already has beside their board.
//
//   target_type: 'checkerboard'   targetCols, targetRows (inner corners),
//                                 rowSpacingMeters = colSpacingMeters (the square side)
//   target_type: 'circlegrid'     targetCols, targetRows (circles), spacingMeters,
//                                 asymmetricGrid (OpenCV's asymmetric layout)
//   target_type: 'aprilgrid'      tagCols, tagRows, tagSize (m), tagSpacing (gap / tag),
//                                 tagStartId (default 0): linecal's AprilGrid (docs/boards.md
//                                 §5) at scale tagSize / 88 mm
//
// Kalibr's circle grid file gives no circle diameter: linecal takes half the spacing (the
// detector does not need it; `linecal pattern` draws it), and `--diameter` overrides it.

#include <string>

#include "absl/status/statusor.h"
#include "detectors/boards/board.h"

namespace linecal::tools {

// The board a Kalibr target YAML file describes. Errors (InvalidArgument, one line starting
// with the path and naming the key): the file missing or not YAML, target_type missing or not
// one of the three, a key missing or not a number, values linecal's board refuses (with the
// key and the range), and unequal row and column spacing.
absl::StatusOr<BoardParams> ReadKalibrTarget(const std::string& path);

}  // namespace linecal::tools

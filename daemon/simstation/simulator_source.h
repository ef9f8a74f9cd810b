#pragma once
// The simulator as a cycle's capture source (daemon/core/capture_source.h): the car simulated
// in the station for each cycle, with the cycle id as seed, and boards knocked out of place
// from a given cycle on (the station-health alarm's tests and demos). The daemon's one user
// of the simulator (docs/conventions.md, "Map of the tree").

#include <cstdint>
#include <memory>
#include <vector>

#include "absl/status/statusor.h"
#include "daemon/core/capture_source.h"
#include "station/io/json_reader.h"
#include "station/sim/simulator.h"

namespace linecal {

// simulator: a board that stands moved from cycle `from_cycle` on (a knocked board, for the
// station-health alarm's tests and demos; SimulatorOptions::moved_boards).
struct SimulatedBoardMove {
  MovedBoard move;
  int64_t from_cycle = 1;  // the first cycle id that sees the board moved
};

// Simulates the car into the directory with the cycle id as seed.
std::unique_ptr<CaptureSource> MakeSimulatorSource(std::vector<SimulatedBoardMove> moves);

// The station configuration's source.moved_boards: [{board, ypr_deg [3], xyz_m [3] (default
// 0), from_cycle (>= 1, default 1)}] within the bounds of SimulatorOptions::Validate; else
// InvalidArgument naming the entry's field.
absl::StatusOr<std::vector<SimulatedBoardMove>> ParseSimulatedMoves(const JsonField& source);

}  // namespace linecal

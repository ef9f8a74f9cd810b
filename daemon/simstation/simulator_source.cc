#include "daemon/simstation/simulator_source.h"

#include <utility>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

class SimulatorSource : public CaptureSource {
 public:
  explicit SimulatorSource(std::vector<SimulatedBoardMove> moves) : moves_(std::move(moves)) {}

  absl::StatusOr<AcquiredCapture> Acquire(const CaptureCycle& cycle) override {
    SimulatorOptions o;
    o.vin = cycle.vin;
    o.aligner = cycle.aligner;
    o.time_ns = cycle.started_ns;
    // Frames per sensor: camera frames and LiDAR rotations alike.
    o.camera_frames = cycle.frames;
    o.lidar.rotations = o.camera_frames;
    o.cancel = cycle.cancel;  // a cancel or a drain stops before the next sensor
    for (const SimulatedBoardMove& m : moves_) {
      if (cycle.id >= m.from_cycle) o.moved_boards.push_back(m.move);
    }
    absl::StatusOr<SimulationSummary> sim =
        SimulateCapture(*cycle.station, *cycle.car, o, static_cast<std::uint64_t>(cycle.id),
                        cycle.dir, [&](int, int, const std::string& sensor) {
                          cycle.event(EventType::kSensorAcquired, sensor, "", std::nullopt);
                        });
    if (absl::IsCancelled(sim.status())) return sim.status();
    if (!sim.ok()) {
      return absl::Status(sim.status().code(),
                          absl::StrCat("acquisition_failed: ", sim.status().message()));
    }
    return AcquiredCapture{};
  }

 private:
  const std::vector<SimulatedBoardMove> moves_;
};

}  // namespace

std::unique_ptr<CaptureSource> MakeSimulatorSource(std::vector<SimulatedBoardMove> moves) {
  return std::make_unique<SimulatorSource>(std::move(moves));
}

absl::StatusOr<std::vector<SimulatedBoardMove>> ParseSimulatedMoves(const JsonField& source) {
  absl::StatusOr<std::vector<JsonField>> entries = source.Array("moved_boards");
  if (!entries.ok()) return entries.status();
  std::vector<SimulatedBoardMove> moves;
  SimulatorOptions check;
  for (const JsonField& e : *entries) {
    if (absl::Status s = e.AllowOnlyKeys({"board", "ypr_deg", "xyz_m", "from_cycle"}); !s.ok())
      return s;
    SimulatedBoardMove m;
    absl::StatusOr<std::string> board = e.String("board");
    if (!board.ok()) return board.status();
    m.move.board_id = *board;
    absl::StatusOr<std::vector<double>> ypr = e.Numbers("ypr_deg", 3);
    if (!ypr.ok()) return ypr.status();
    m.move.yaw_deg = (*ypr)[0];
    m.move.pitch_deg = (*ypr)[1];
    m.move.roll_deg = (*ypr)[2];
    if (e.Has("xyz_m")) {
      absl::StatusOr<std::vector<double>> xyz = e.Numbers("xyz_m", 3);
      if (!xyz.ok()) return xyz.status();
      m.move.offset_m = Eigen::Vector3d((*xyz)[0], (*xyz)[1], (*xyz)[2]);
    }
    absl::StatusOr<std::int64_t> from = e.IntegerOr("from_cycle", 1);
    if (!from.ok()) return from.status();
    if (*from < 1) return e.Error("from_cycle", "must be >= 1");
    m.from_cycle = *from;
    check.moved_boards.push_back(m.move);
    if (absl::Status s = check.Validate(); !s.ok()) return e.Error(std::string(s.message()));
    moves.push_back(std::move(m));
  }
  return moves;
}

}  // namespace linecal

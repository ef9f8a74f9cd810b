#pragma once
// Radar CAN decoders: CAN frames → measurement cycles of detections (station/sensors/
// radar_format.h), for the live SocketCAN path and for recorded candump logs alike.
//
// ARS408-21: a cycle opens at a list status frame (0x600 clusters / 0x60A objects, per sensor
// id) and holds the general messages (0x701 / 0x60B) that follow, plus cluster quality (0x702)
// attached to its cluster; it closes at the next status frame of the same list or at the end
// of input. ESR: a scan opens at 0x4E0 and closes when all 64 track slots arrived, at the next
// 0x4E0, or at the end of input; slots with track status 0 (no target) give no detection.
// Detections carry their cycle's status-frame time. Frames from several buses must be
// separated by CanFrame::interface before decoding (the cycle state is per sensor id only).
//
// Frames that give nothing are skipped and counted by reason, never fatal.

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "station/io/candump.h"
#include "station/sensors/radar/radar_format.h"

namespace linecal {

enum class RadarModel { kArs408, kEsr };

// "ars408" / "esr" → model; nullopt otherwise.
std::optional<RadarModel> ParseRadarModel(std::string_view name);

enum class RadarSkipReason : int {
  kUnknownId = 0,     // not a message of the model (incl. 29-bit ids, other ARS408 messages)
  kRemote,            // remote request frame
  kErrorFrame,        // bus error frame
  kShort,             // payload shorter than the message's signals need
  kNoCycleHeader,     // before the first status frame of its list / scan
  kDuplicate,         // a second message for the same id in one cycle
  kUnmatchedQuality,  // 0x702 for a cluster id the cycle's 0x701 messages did not list
  kCount,
};

// "unknown_id", "remote", "error_frame", "short", "no_cycle_header", "duplicate",
// "unmatched_quality".
const char* RadarSkipReasonName(RadarSkipReason reason);

struct RadarDecodeStats {
  int64_t frames_read = 0;
  int64_t frames_decoded = 0;  // frames that contributed to a cycle
  std::array<int64_t, static_cast<int>(RadarSkipReason::kCount)> skipped{};
  int64_t cycles = 0;
  int64_t incomplete_cycles = 0;  // fewer (or more) messages than the status announced
  int64_t detections = 0;

  int64_t skipped_total() const;
  int64_t& skipped_for(RadarSkipReason reason) { return skipped[static_cast<int>(reason)]; }
  int64_t skipped_for(RadarSkipReason reason) const { return skipped[static_cast<int>(reason)]; }
};

// Streaming decoder: feed frames in time order, collect cycles as they close. Not thread-safe;
// one instance per bus. Memory: one open cycle per (sensor id, list).
class RadarDecoder {
 public:
  RadarDecoder(RadarModel model, const RadarConventions& conventions);

  // Consumes one frame; appends every cycle this frame closed to *closed. Cost: O(1)
  // amortised (O(detections) when a cycle closes).
  void Push(const CanFrame& frame, std::vector<RadarCycle>* closed);

  // Closes every open cycle (end of input) and appends them to *closed, oldest first.
  void Finish(std::vector<RadarCycle>* closed);

  const RadarDecodeStats& stats() const { return stats_; }

 private:
  struct OpenCycle {
    bool open = false;
    RadarCycle cycle;
    // Per id (ARS408 ids 0..255, ESR track numbers 1..64): −1 while unseen, else the index
    // of its detection (ARS408; quality messages attach through it) or ≥ 0 as "seen" (ESR).
    std::array<int16_t, 256> index_of_id{};
  };

  void PushArs408(const CanFrame& frame, std::vector<RadarCycle>* closed);
  void PushEsr(const CanFrame& frame, std::vector<RadarCycle>* closed);
  void Open(OpenCycle& slot, RadarCycle head);
  void Close(OpenCycle& slot, std::vector<RadarCycle>* closed);
  void Skip(RadarSkipReason reason) { ++stats_.skipped_for(reason); }

  RadarModel model_;
  RadarConventions conventions_;
  RadarDecodeStats stats_;
  // ARS408: [sensor id][0 clusters, 1 objects]; ESR: [0][0].
  std::array<std::array<OpenCycle, 2>, ars408::kMaxSensorId + 1> open_{};
};

struct RadarDecodeResult {
  std::vector<RadarCycle> cycles;  // in the order they closed
  RadarDecodeStats stats;
};

// Decodes a whole recording (frames in time order). Pure function; cost O(frames).
RadarDecodeResult DecodeRadarFrames(std::span<const CanFrame> frames, RadarModel model,
                                    const RadarConventions& conventions);

}  // namespace linecal

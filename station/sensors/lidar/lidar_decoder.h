#pragma once
// Decoders of LiDAR UDP packets (VLP-16, Pandar64, PandarXT-32) into points and full
// rotations. The packet layouts, beam geometry and frames are in
// station/sensors/lidar/lidar_format.h; this file only reads bytes.
//
// Every byte sequence is safe input: a packet that is not a valid packet of the decoder's
// model is skipped and counted under a reason, never trusted.
//
// Points. Each non-zero distance becomes a point unless its range is outside the options'
// [min_range_m, max_range_m]. In dual-return packets the second return is dropped when its
// distance equals the first one's (the sensor repeats a single echo in both blocks). Order:
// VLP-16 block by block, each block firing by firing, laser 0..15; Hesai column by column,
// each column channel by channel, return by return — the orders the sensors measure in
// (and nebula's, so reference decodes compare point for point).
//
// Rotations. A rotation is every point whose corrected azimuth (block azimuth + the beam's
// offset and firing delay) lies in [0°, 360°) between two passes of the block azimuth through
// 0° (detected as a drop of more than 180° between consecutive blocks). Beams with a
// calibrated azimuth offset cross 0° before or after their block does; their points are put
// in the rotation their own azimuth belongs to. A rotation is emitted once no later packet
// can add to it, and only when both its start and its end were seen: the partial rotations
// at the start and end of a recording are counted, not emitted.
//
// Time (LidarPoint::time_ns, ns since the epoch on the sensor's clock): the packet's time
// field plus the model's column and channel firing offsets. VLP-16 stamps count µs within the
// hour; the hour comes from `host_time_ns` (NearestTimeNs). Hesai stamps carry a UTC date;
// when the date bytes are invalid (an unsynchronised sensor) the second comes from
// `host_time_ns` instead and the packet is counted in packets_without_date.

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "station/sensors/lidar/lidar_format.h"
#include "station/sensors/lidar/lidar_point.h"

namespace linecal {

// Why a packet was skipped.
enum class LidarSkipReason {
  kTruncated = 0,  // shorter than the model's packet
  kOversized,      // longer than the model's packet (or between its two accepted sizes)
  kBadMagic,       // VLP-16 block flag not FF EE, Hesai start not EE FF
  kWrongModel,     // another model's packet: VLP-16 product id, Hesai laser/block count or
                   // protocol version
  kBadReturnMode,  // a return-mode byte the model does not send
  kBadField,       // a field out of range: azimuth ≥ 360°, Hesai distance unit 0, VLP-16
                   // azimuth step between blocks above kMaxBlockStepCentideg
};
inline constexpr int kLidarSkipReasonCount = 6;

// "truncated", "oversized", "bad_magic", "wrong_model", "bad_return_mode", "bad_field".
const char* LidarSkipReasonName(LidarSkipReason reason);

// Largest plausible rotation between two consecutive VLP-16 blocks, in 0.01°: at its fastest
// (1200 rpm) the sensor turns 0.8° per block; more means a corrupt azimuth field.
inline constexpr int kMaxBlockStepCentideg = 500;

struct LidarDecoderOptions {
  // Returns nearer than 0.3 m come from the sensor's own window and housing (and are below
  // both vendors' specified minimum range); 200 m is the Pandar64's specified maximum and
  // beyond the VLP-16's 131 m field. The reference decodes of the real recordings
  // (docs/external-data.md) used the same.
  double min_range_m = 0.3;
  double max_range_m = 200.0;

  // InvalidArgument naming the field unless 0 ≤ min_range_m ≤ max_range_m, both finite.
  absl::Status Validate() const;
};

struct LidarDecoderStats {
  std::int64_t packets = 0;  // given to AddPacket
  std::int64_t packets_decoded = 0;
  std::array<std::int64_t, kLidarSkipReasonCount> skipped{};  // indexed by LidarSkipReason
  std::int64_t packets_without_date = 0;  // Hesai packets whose date bytes were invalid
  std::int64_t points = 0;                // points put into rotations (emitted or not)
  std::int64_t scans = 0;                 // complete rotations emitted
  std::int64_t partial_rotations = 0;     // rotations with points, dropped as incomplete
  std::int64_t late_points = 0;  // points for a rotation already emitted (azimuth went back)

  std::int64_t skipped_total() const;
};

class LidarDecoder {
 public:
  // Fails with InvalidArgument when the table (ValidateBeamTable) or the options are bad.
  // Cost: O(channels) plus a shared 36000-entry sine table built once per process.
  static absl::StatusOr<LidarDecoder> Create(LidarBeamTable table,
                                             LidarDecoderOptions options = {});

  LidarModel model() const { return table_.model; }
  const LidarDecoderStats& stats() const { return stats_; }

  // Decodes one UDP payload (not retained). `host_time_ns`: when it was received (pcap record
  // or socket time, ns since the epoch), used only as described above. Appends the rotations
  // this packet completed to `completed` (usually none, at most two). Never fails: a bad
  // packet is counted in stats().skipped. Cost: O(points in the packet), allocation-free
  // except when a rotation's point buffer grows.
  void AddPacket(std::span<const std::uint8_t> payload, std::int64_t host_time_ns,
                 std::vector<LidarScan>* completed);

  // End of input: emits the rotation whose end was seen but that was still open for points
  // of the next one, and counts the unfinished one as partial. The decoder then starts over
  // as if new. Cost: O(1) besides moving the buffers.
  void Finish(std::vector<LidarScan>* completed);

 private:
  // Per-channel constants of the point conversion.
  struct Channel {
    double cos_elevation;
    double sin_elevation;
    double cos_offset;  // of the Hesai azimuth offset (1, 0 on the VLP-16)
    double sin_offset;
    double offset_centideg;
    double firing_fraction;
    std::int64_t time_offset_ns;
    std::uint16_t ring;
  };
  // The points of one rotation while it is being assembled.
  struct Rotation {
    std::int64_t index = 0;
    std::vector<LidarPoint> points;
  };

  LidarDecoder(LidarBeamTable table, LidarDecoderOptions options);

  bool DecodeVlp16(std::span<const std::uint8_t> p, std::int64_t host_time_ns,
                   std::vector<LidarScan>* completed);
  bool DecodeHesai(std::span<const std::uint8_t> p, std::int64_t host_time_ns,
                   std::vector<LidarScan>* completed);
  void Skip(LidarSkipReason reason);
  // Bookkeeping at each block azimuth, before its points: detects the pass through 0° and
  // then moves the rotations down by one (emitting the previous one if still open).
  void BeginColumnGroup(int azimuth_centideg, std::vector<LidarScan>* completed);
  // After a group's points: emits the previous rotation once no later point can reach it.
  void EndColumnGroup(int azimuth_centideg, std::vector<LidarScan>* completed);
  // Appends a point to the rotation that its corrected azimuth belongs to: -1, 0 or +1
  // relative to the current one.
  void Route(int rotation_delta, const LidarPoint& point);
  void Emit(Rotation& rotation, std::vector<LidarScan>* completed);
  void Drop(Rotation& rotation);

  LidarBeamTable table_;
  LidarDecoderOptions options_;
  LidarDecoderStats stats_;
  std::vector<Channel> channels_;
  // Smallest beam azimuth offset in 0.01° (≤ 0): a rotation can receive points until the block
  // azimuth of the next one passes -min_offset_centideg_.
  double min_offset_centideg_ = 0.0;

  bool have_azimuth_ = false;
  int last_azimuth_centideg_ = 0;
  Rotation previous_;  // still open for late beams while previous_open_
  bool previous_open_ = true;
  Rotation current_;
  Rotation next_;
};

}  // namespace linecal

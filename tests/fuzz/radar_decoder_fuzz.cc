// Fuzzes the ARS408 and ESR decoders with arbitrary frames, including ones ValidateCanFrame
// would refuse (len > 64, data past len): no crash, counts that add up, finite detections.
#include <cmath>
#include <cstdint>

#include "station/sensors/radar/radar_decoder.h"

namespace {

// Input: records of [flags][id high][id low][len][len data bytes]. Flags: bit 0 extended,
// bit 1 remote, bit 2 error, bit 3 CAN FD, bits 4-5 pick the conventions, bit 6 picks the
// model (the first record's flags decide both).
std::vector<linecal::CanFrame> Frames(const uint8_t* data, size_t size) {
  std::vector<linecal::CanFrame> frames;
  size_t i = 0;
  constexpr size_t kHeader = 4;
  while (i + kHeader <= size) {
    linecal::CanFrame f;
    f.interface = "can0";
    f.time = linecal::CanTime(std::chrono::microseconds(250 * frames.size()));
    f.extended = (data[i] & 1) != 0;
    f.remote = (data[i] & 2) != 0;
    f.error = (data[i] & 4) != 0;
    f.fd = (data[i] & 8) != 0;
    f.id = static_cast<uint32_t>(data[i + 1] << 8 | data[i + 2]);
    f.len = data[i + 3];
    i += kHeader;
    const size_t n = std::min({size_t{f.len}, f.data.size(), size - i});
    std::copy_n(data + i, n, f.data.begin());
    i += n;
    frames.push_back(f);
  }
  return frames;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::vector<linecal::CanFrame> frames = Frames(data, size);
  const uint8_t flags = size > 0 ? data[0] : 0;
  linecal::RadarConventions conventions;
  conventions.ars408_counter_byte_order =
      (flags & 0x10) != 0 ? linecal::ByteOrder::kLittleEndian : linecal::ByteOrder::kBigEndian;
  conventions.ars408_object_lat_left_positive = (flags & 0x20) == 0;
  conventions.esr_angle_clockwise_positive = (flags & 0x20) == 0;
  const linecal::RadarModel model =
      (flags & 0x40) != 0 ? linecal::RadarModel::kEsr : linecal::RadarModel::kArs408;
  const linecal::RadarDecodeResult r = linecal::DecodeRadarFrames(frames, model, conventions);
  const linecal::RadarDecodeStats& s = r.stats;
  if (s.frames_read != static_cast<int64_t>(frames.size())) __builtin_trap();
  if (s.frames_decoded + s.skipped_total() != s.frames_read) __builtin_trap();
  if (s.cycles != static_cast<int64_t>(r.cycles.size())) __builtin_trap();
  int64_t detections = 0;
  int64_t incomplete = 0;
  for (const linecal::RadarCycle& c : r.cycles) {
    detections += static_cast<int64_t>(c.detections.size());
    if (!c.complete()) ++incomplete;
    for (const linecal::RadarDetection& d : c.detections) {
      if (!std::isfinite(d.range_m) || d.range_m < 0 || !std::isfinite(d.azimuth_rad) ||
          !std::isfinite(d.range_rate_mps)) {
        __builtin_trap();
      }
      if (d.kind == linecal::RadarDetectionKind::kTrack && (d.id < 1 || d.id > 64)) {
        __builtin_trap();
      }
    }
  }
  if (detections != s.detections || incomplete != s.incomplete_cycles) __builtin_trap();
  return 0;
}

#include "station/sensors/lidar/lidar_decoder.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <utility>

#include "absl/strings/str_cat.h"
#include "station/io/byte_io.h"

namespace linecal {
namespace {

// Azimuth fields count 0.01° steps.
constexpr int kCentidegPerTurn = 36000;
constexpr double kRadPerCentideg = std::numbers::pi / 18000.0;
// A block azimuth that drops by more than half a turn has passed through 0°; smaller drops
// are jitter or reordering, not a new rotation.
constexpr int kWrapDropCentideg = kCentidegPerTurn / 2;
constexpr std::int64_t kNsPerUs = 1000;
constexpr std::int64_t kNsPerSecond = 1'000'000'000;

struct SinCos {
  double sin;
  double cos;
};

// sin and cos of every whole 0.01°: the block azimuths are whole 0.01° steps, so the
// per-point trigonometry reduces to one rotation by a small or fixed angle.
const std::vector<SinCos>& AzimuthTable() {
  static const std::vector<SinCos>* const table = [] {
    auto* t = new std::vector<SinCos>(kCentidegPerTurn);
    for (int i = 0; i < kCentidegPerTurn; ++i) {
      (*t)[i] = {std::sin(i * kRadPerCentideg), std::cos(i * kRadPerCentideg)};
    }
    return t;
  }();
  return *table;
}

// sin and cos of a small angle (|a| ≤ 0.15 rad: the VLP-16 firing interpolation stays below
// 1.6 · kMaxBlockStepCentideg / 2) by their Taylor series; the first omitted terms are below
// 1e-13.
SinCos SmallAngleSinCos(double a) {
  const double a2 = a * a;
  return {a * (1.0 - a2 / 6.0 * (1.0 - a2 / 20.0 * (1.0 - a2 / 42.0))),
          1.0 - a2 / 2.0 * (1.0 - a2 / 12.0 * (1.0 - a2 / 30.0))};
}

}  // namespace

const char* LidarSkipReasonName(LidarSkipReason reason) {
  switch (reason) {
    case LidarSkipReason::kTruncated:
      return "truncated";
    case LidarSkipReason::kOversized:
      return "oversized";
    case LidarSkipReason::kBadMagic:
      return "bad_magic";
    case LidarSkipReason::kWrongModel:
      return "wrong_model";
    case LidarSkipReason::kBadReturnMode:
      return "bad_return_mode";
    case LidarSkipReason::kBadField:
      return "bad_field";
  }
  return "unknown";
}

absl::Status LidarDecoderOptions::Validate() const {
  if (!std::isfinite(min_range_m) || min_range_m < 0.0) {
    return absl::InvalidArgumentError(absl::StrCat("min_range_m: ", min_range_m));
  }
  if (!std::isfinite(max_range_m) || max_range_m < min_range_m) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_range_m: ", max_range_m, " is below min_range_m ", min_range_m));
  }
  return absl::OkStatus();
}

std::int64_t LidarDecoderStats::skipped_total() const {
  std::int64_t n = 0;
  for (std::int64_t s : skipped) n += s;
  return n;
}

absl::StatusOr<LidarDecoder> LidarDecoder::Create(LidarBeamTable table,
                                                  LidarDecoderOptions options) {
  if (absl::Status s = ValidateBeamTable(table); !s.ok()) return s;
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  return LidarDecoder(std::move(table), options);
}

LidarDecoder::LidarDecoder(LidarBeamTable table, LidarDecoderOptions options)
    : table_(std::move(table)), options_(options) {
  AzimuthTable();
  for (std::size_t c = 0; c < table_.beams.size(); ++c) {
    const LidarBeam& b = table_.beams[c];
    Channel ch;
    ch.cos_elevation = std::cos(b.elevation_rad);
    ch.sin_elevation = std::sin(b.elevation_rad);
    ch.cos_offset = std::cos(b.azimuth_offset_rad);
    ch.sin_offset = std::sin(b.azimuth_offset_rad);
    ch.offset_centideg = b.azimuth_offset_rad / kRadPerCentideg;
    ch.firing_fraction = b.firing_fraction;
    ch.time_offset_ns = ChannelTimeOffsetNs(table_.model, static_cast<int>(c));
    ch.ring = b.ring;
    channels_.push_back(ch);
    min_offset_centideg_ = std::min(min_offset_centideg_, ch.offset_centideg);
  }
  previous_.index = -1;
  current_.index = 0;
  next_.index = 1;
}

void LidarDecoder::Skip(LidarSkipReason reason) { ++stats_.skipped[static_cast<int>(reason)]; }

void LidarDecoder::AddPacket(std::span<const std::uint8_t> payload, std::int64_t host_time_ns,
                             std::vector<LidarScan>* completed) {
  ++stats_.packets;
  const bool ok = table_.model == LidarModel::kVlp16
                      ? DecodeVlp16(payload, host_time_ns, completed)
                      : DecodeHesai(payload, host_time_ns, completed);
  if (ok) ++stats_.packets_decoded;
}

bool LidarDecoder::DecodeVlp16(std::span<const std::uint8_t> p, std::int64_t host_time_ns,
                               std::vector<LidarScan>* completed) {
  if (p.size() < vlp16::kPacketBytes) {
    Skip(LidarSkipReason::kTruncated);
    return false;
  }
  if (p.size() > vlp16::kPacketBytes) {
    Skip(LidarSkipReason::kOversized);
    return false;
  }
  const std::uint8_t* d = p.data();
  std::array<int, vlp16::kBlocks> azimuth{};
  for (int b = 0; b < vlp16::kBlocks; ++b) {
    const std::uint8_t* block = d + b * vlp16::kBlockBytes;
    if (LoadLe16(block) != vlp16::kBlockFlag) {
      Skip(LidarSkipReason::kBadMagic);
      return false;
    }
    azimuth[b] = LoadLe16(block + vlp16::kAzimuthOffsetInBlock);
  }
  if (d[vlp16::kProductIdOffset] != vlp16::kProductId) {
    Skip(LidarSkipReason::kWrongModel);
    return false;
  }
  const int returns = ReturnsForModeByte(LidarModel::kVlp16, d[vlp16::kReturnModeOffset]);
  if (returns == 0) {
    Skip(LidarSkipReason::kBadReturnMode);
    return false;
  }
  // A group is the block (single return) or block pair (dual) of two columns at one azimuth.
  const int groups = vlp16::kBlocks / returns;
  std::array<int, vlp16::kBlocks> step{};  // rotation to the next group, 0.01°
  for (int g = 0; g < groups; ++g) {
    if (azimuth[g * returns] >= kCentidegPerTurn) {
      Skip(LidarSkipReason::kBadField);
      return false;
    }
  }
  for (int g = 0; g + 1 < groups; ++g) {
    step[g] =
        (azimuth[(g + 1) * returns] - azimuth[g * returns] + kCentidegPerTurn) % kCentidegPerTurn;
    if (step[g] > kMaxBlockStepCentideg) {
      Skip(LidarSkipReason::kBadField);
      return false;
    }
  }
  // The last group has no successor in the packet: assume the same speed as before it.
  step[groups - 1] = step[groups - 2];

  const std::int64_t packet_time_ns =
      NearestTimeNs(static_cast<std::int64_t>(LoadLe32(d + vlp16::kTimestampOffset)) * kNsPerUs,
                    vlp16::kTimestampPeriodNs, host_time_ns);
  const int columns = 2 * groups;
  const double unit_m = vlp16::kDistanceUnitM;
  const std::vector<SinCos>& table = AzimuthTable();

  for (int g = 0; g < groups; ++g) {
    const int az = azimuth[g * returns];
    BeginColumnGroup(az, completed);
    const SinCos a = table[az];
    // Per measurement slot (firing f, laser l): the interpolated azimuth beyond the block's.
    std::array<SinCos, vlp16::kFiringsPerBlock * vlp16::kLasers> rot;
    std::array<double, vlp16::kFiringsPerBlock * vlp16::kLasers> extra_centideg;
    for (int f = 0; f < vlp16::kFiringsPerBlock; ++f) {
      for (int l = 0; l < vlp16::kLasers; ++l) {
        const double e = (f + channels_[l].firing_fraction) * step[g] * 0.5;
        extra_centideg[f * vlp16::kLasers + l] = e;
        rot[f * vlp16::kLasers + l] = SmallAngleSinCos(e * kRadPerCentideg);
      }
    }
    const std::uint8_t* first_block = d + g * returns * vlp16::kBlockBytes;
    for (int r = 0; r < returns; ++r) {
      const std::uint8_t* block = first_block + r * vlp16::kBlockBytes;
      for (int f = 0; f < vlp16::kFiringsPerBlock; ++f) {
        const std::int64_t column_time_ns =
            packet_time_ns + ColumnTimeOffsetNs(LidarModel::kVlp16, 2 * g + f, columns);
        for (int l = 0; l < vlp16::kLasers; ++l) {
          const int slot = f * vlp16::kLasers + l;
          const std::size_t at = vlp16::kDataOffsetInBlock + slot * vlp16::kMeasurementBytes;
          const std::uint16_t raw = LoadLe16(block + at);
          if (raw == 0) continue;
          if (r == 1 && raw == LoadLe16(first_block + at)) continue;
          const double range = raw * unit_m;
          if (range < options_.min_range_m || range > options_.max_range_m) continue;
          const Channel& ch = channels_[l];
          const SinCos& b = rot[slot];
          const double s = a.sin * b.cos + a.cos * b.sin;
          const double c = a.cos * b.cos - a.sin * b.sin;
          const double xy = range * ch.cos_elevation;
          LidarPoint pt;
          pt.x = static_cast<float>(xy * s);
          pt.y = static_cast<float>(xy * c);
          pt.z = static_cast<float>(range * ch.sin_elevation);
          pt.intensity = block[at + 2];
          pt.ring = ch.ring;
          pt.time_ns = column_time_ns + ch.time_offset_ns;
          Route(az + extra_centideg[slot] >= kCentidegPerTurn ? 1 : 0, pt);
        }
      }
    }
    EndColumnGroup(az, completed);
  }
  return true;
}

bool LidarDecoder::DecodeHesai(std::span<const std::uint8_t> p, std::int64_t host_time_ns,
                               std::vector<LidarScan>* completed) {
  const bool xt32 = table_.model == LidarModel::kPandarXt32;
  const LidarModelInfo& info = GetLidarModelInfo(table_.model);
  if (p.size() < info.packet_bytes) {
    Skip(LidarSkipReason::kTruncated);
    return false;
  }
  if (p.size() != info.packet_bytes && p.size() != info.packet_bytes_alt) {
    Skip(LidarSkipReason::kOversized);
    return false;
  }
  const std::uint8_t* d = p.data();
  if (d[0] != kHesaiMagic0 || d[1] != kHesaiMagic1) {
    Skip(LidarSkipReason::kBadMagic);
    return false;
  }
  const HesaiLayout& layout = GetHesaiLayout(table_.model);
  bool model_ok =
      d[layout.laser_count_offset] == info.channels && d[layout.block_count_offset] == info.blocks;
  if (xt32) {
    model_ok = model_ok && d[pandarxt32::kProtocolMajorOffset] == pandarxt32::kProtocolMajor &&
               d[pandarxt32::kProtocolMinorOffset] == pandarxt32::kProtocolMinor;
  }
  if (!model_ok) {
    Skip(LidarSkipReason::kWrongModel);
    return false;
  }
  const int returns = ReturnsForModeByte(table_.model, d[layout.return_mode_offset]);
  if (returns == 0) {
    Skip(LidarSkipReason::kBadReturnMode);
    return false;
  }
  const int unit_mm = d[layout.distance_unit_offset];
  if (unit_mm == 0) {
    Skip(LidarSkipReason::kBadField);
    return false;
  }
  const int groups = info.blocks / returns;
  for (int g = 0; g < groups; ++g) {
    if (LoadLe16(d + layout.header_bytes + g * returns * layout.block_bytes) >= kCentidegPerTurn) {
      Skip(LidarSkipReason::kBadField);
      return false;
    }
  }

  const std::int64_t in_second_ns =
      static_cast<std::int64_t>(LoadLe32(d + layout.timestamp_offset)) * kNsPerUs;
  const std::optional<std::int64_t> utc_s =
      HesaiUtcSeconds(std::span<const std::uint8_t, 6>(d + layout.date_time_offset, 6));
  std::int64_t packet_time_ns;
  if (utc_s) {
    packet_time_ns = *utc_s * kNsPerSecond + in_second_ns;
  } else {
    packet_time_ns = NearestTimeNs(in_second_ns, kNsPerSecond, host_time_ns);
    ++stats_.packets_without_date;
  }

  const double unit_m = unit_mm * 1e-3;
  const std::vector<SinCos>& table = AzimuthTable();
  const int channel_count = info.channels;
  for (int g = 0; g < groups; ++g) {
    const std::uint8_t* first_block = d + layout.header_bytes + g * returns * layout.block_bytes;
    const int az = LoadLe16(first_block);
    BeginColumnGroup(az, completed);
    const SinCos a = table[az];
    const std::int64_t column_time_ns =
        packet_time_ns + ColumnTimeOffsetNs(table_.model, g, groups);
    for (int c = 0; c < channel_count; ++c) {
      const Channel& ch = channels_[c];
      const std::size_t at = 2 + c * layout.unit_bytes;
      const double corrected = az + ch.offset_centideg;
      const int delta = corrected >= kCentidegPerTurn ? 1 : (corrected < 0.0 ? -1 : 0);
      const double s = a.sin * ch.cos_offset + a.cos * ch.sin_offset;
      const double co = a.cos * ch.cos_offset - a.sin * ch.sin_offset;
      for (int r = 0; r < returns; ++r) {
        const std::uint8_t* unit = first_block + r * layout.block_bytes + at;
        const std::uint16_t raw = LoadLe16(unit);
        if (raw == 0) continue;
        if (r == 1 && raw == LoadLe16(first_block + at)) continue;
        const double range = raw * unit_m;
        if (range < options_.min_range_m || range > options_.max_range_m) continue;
        const double xy = range * ch.cos_elevation;
        LidarPoint pt;
        pt.x = static_cast<float>(xy * s);
        pt.y = static_cast<float>(xy * co);
        pt.z = static_cast<float>(range * ch.sin_elevation);
        pt.intensity = unit[2];
        pt.ring = ch.ring;
        pt.time_ns = column_time_ns + ch.time_offset_ns;
        Route(delta, pt);
      }
    }
    EndColumnGroup(az, completed);
  }
  return true;
}

void LidarDecoder::BeginColumnGroup(int azimuth_centideg, std::vector<LidarScan>* completed) {
  const bool wrapped =
      have_azimuth_ && last_azimuth_centideg_ - azimuth_centideg > kWrapDropCentideg;
  have_azimuth_ = true;
  last_azimuth_centideg_ = azimuth_centideg;
  if (!wrapped) return;
  if (previous_open_) Emit(previous_, completed);
  // The buffers move down one rotation; the emptied one is reused for the new next_.
  std::swap(previous_, current_);
  std::swap(current_, next_);
  next_.points.clear();
  next_.index = current_.index + 1;
  previous_open_ = true;
}

void LidarDecoder::EndColumnGroup(int azimuth_centideg, std::vector<LidarScan>* completed) {
  // From here on every beam's corrected azimuth is ≥ 0: nothing more for the previous
  // rotation (as long as the block azimuth keeps increasing).
  if (previous_open_ && azimuth_centideg + min_offset_centideg_ >= 0.0) {
    Emit(previous_, completed);
    previous_open_ = false;
  }
}

void LidarDecoder::Route(int rotation_delta, const LidarPoint& point) {
  Rotation* target = rotation_delta < 0 ? &previous_ : (rotation_delta > 0 ? &next_ : &current_);
  if (rotation_delta < 0 && !previous_open_) {
    ++stats_.late_points;
    return;
  }
  target->points.push_back(point);
  ++stats_.points;
}

void LidarDecoder::Emit(Rotation& rotation, std::vector<LidarScan>* completed) {
  // Rotation 0 began with the first packet seen, mid-turn: its start is unknown.
  if (rotation.index < 1) {
    Drop(rotation);
    return;
  }
  LidarScan scan;
  scan.rotation = rotation.index;
  if (!rotation.points.empty()) {
    scan.stamp_ns = std::min_element(rotation.points.begin(), rotation.points.end(),
                                     [](const LidarPoint& a, const LidarPoint& b) {
                                       return a.time_ns < b.time_ns;
                                     })
                        ->time_ns;
  }
  const std::size_t capacity_hint = rotation.points.size();
  scan.points = std::move(rotation.points);
  // Size the next buffer like this one so the next rotation does not regrow it.
  rotation.points = std::vector<LidarPoint>();
  rotation.points.reserve(capacity_hint);
  ++stats_.scans;
  completed->push_back(std::move(scan));
}

void LidarDecoder::Drop(Rotation& rotation) {
  if (!rotation.points.empty()) ++stats_.partial_rotations;
  rotation.points.clear();
}

void LidarDecoder::Finish(std::vector<LidarScan>* completed) {
  if (previous_open_) Emit(previous_, completed);
  Drop(current_);
  Drop(next_);
  have_azimuth_ = false;
  previous_open_ = true;
  previous_.index = -1;
  current_.index = 0;
  next_.index = 1;
}

}  // namespace linecal

#include "station/sensors/lidar/lidar_format.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "station/io/byte_io.h"

namespace linecal {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr std::int64_t kNsPerUs = 1000;
constexpr std::int64_t kNsPerSecond = 1'000'000'000;
constexpr std::int64_t kSecondsPerDay = 86400;
// Azimuth fields count 0.01° steps: one turn is 36000.
constexpr int kCentidegPerTurn = 36000;

// Velodyne and Hesai both send to UDP port 2368 by factory default.
constexpr std::uint16_t kDefaultLidarPort = 2368;

constexpr LidarModelInfo kModels[] = {
    {LidarModel::kVlp16, "vlp16", vlp16::kLasers, vlp16::kBlocks, vlp16::kFiringsPerBlock,
     vlp16::kPacketBytes, vlp16::kPacketBytes, vlp16::kDistanceUnitM, vlp16::kFiringPeriodNs,
     kDefaultLidarPort},
    {LidarModel::kPandar64, "pandar64", pandar64::kChannels, pandar64::kBlocks, 1,
     pandar64::kPacketBytes, pandar64::kPacketBytesWithSequence, pandar64::kDistanceUnitMm * 1e-3,
     pandar64::kColumnPeriodNs, kDefaultLidarPort},
    {LidarModel::kPandarXt32, "pandarxt32", pandarxt32::kChannels, pandarxt32::kBlocks, 1,
     pandarxt32::kPacketBytes, pandarxt32::kPacketBytes, pandarxt32::kDistanceUnitMm * 1e-3,
     pandarxt32::kColumnPeriodNs, kDefaultLidarPort},
};

// Pandar64 channel firing times relative to their column, in ns (Pandar64 user manual,
// "laser firing time offsets", channels 1..64; the same table as Hesai's and nebula's
// drivers). Channels fire in groups, so the values are not monotonic.
constexpr std::array<std::int32_t, pandar64::kChannels> kPandar64ChannelOffsetNs = {
    -23180, -21876, -20572, -19268, -17964, -16660, -11444, -46796, -7532,  -36956, -50732,
    -54668, -40892, -44828, -31052, -34988, -48764, -52700, -38924, -42860, -29084, -33020,
    -46796, -25148, -36956, -50732, -27116, -40892, -44828, -31052, -34988, -48764, -25148,
    -38924, -42860, -29084, -33020, -52700, -6228,  -54668, -15356, -27116, -10140, -23180,
    -4924,  -21876, -14052, -17964, -8836,  -19268, -3620,  -20572, -12748, -16660, -7532,
    -11444, -6228,  -15356, -10140, -4924,  -3620,  -14052, -8836,  -12748};

std::int64_t FloorDiv(std::int64_t a, std::int64_t b) {
  std::int64_t q = a / b;
  if ((a % b != 0) && ((a < 0) != (b < 0))) --q;
  return q;
}

// Days since 1970-01-01 of a proleptic Gregorian date (the "days from civil" construction:
// count from 0000-03-01 so that the leap day ends the year).
std::int64_t DaysFromCivil(std::int64_t y, int m, int d) {
  y -= m <= 2 ? 1 : 0;
  const std::int64_t era = FloorDiv(y, 400);
  const std::int64_t yoe = y - era * 400;                          // [0, 399]
  const int mp = (m + 9) % 12;                                     // March = 0
  const std::int64_t doy = (153 * mp + 2) / 5 + d - 1;             // [0, 365]
  const std::int64_t doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;  // [0, 146096]
  constexpr std::int64_t kDaysFrom0000To1970 = 719468;
  return era * 146097 + doe - kDaysFrom0000To1970;
}

struct CivilDate {
  std::int64_t year;
  int month;
  int day;
};

// The inverse of DaysFromCivil.
CivilDate CivilFromDays(std::int64_t z) {
  z += 719468;
  const std::int64_t era = FloorDiv(z, 146097);
  const std::int64_t doe = z - era * 146097;
  const std::int64_t yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
  const std::int64_t doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
  const std::int64_t mp = (5 * doy + 2) / 153;
  const int d = static_cast<int>(doy - (153 * mp + 2) / 5 + 1);
  const int m = static_cast<int>(mp < 10 ? mp + 3 : mp - 9);
  return {yoe + era * 400 + (m <= 2 ? 1 : 0), m, d};
}

int DaysInMonth(std::int64_t year, int month) {
  static constexpr int kDays[] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  const bool leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
  return month == 2 && leap ? 29 : kDays[month - 1];
}

// Hesai year bytes: see HesaiUtcSeconds. Writers use 1900-based years, as the recorded
// Pandar64 does, so they can write 1970 (byte 70) to 2155 (byte 255).
constexpr int kHesaiYearBase = 1900;
constexpr int kHesaiFirstYear = 1970;
constexpr int kHesaiLastYear = 2155;

void ComputeRings(LidarBeamTable& table) {
  std::vector<int> order(table.beams.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return table.beams[a].elevation_rad < table.beams[b].elevation_rad;
  });
  for (std::size_t r = 0; r < order.size(); ++r) {
    table.beams[order[r]].ring = static_cast<std::uint16_t>(r);
  }
}

double FiringFraction(LidarModel model, int channel) {
  if (model != LidarModel::kVlp16) return 0.0;
  return static_cast<double>(channel * vlp16::kLaserPeriodNs) / vlp16::kFiringPeriodNs;
}

std::optional<double> ParseDouble(absl::string_view s) {
  s = absl::StripAsciiWhitespace(s);
  double v = 0.0;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size() || !std::isfinite(v)) return std::nullopt;
  return v;
}

}  // namespace

const LidarModelInfo& GetLidarModelInfo(LidarModel model) {
  for (const LidarModelInfo& info : kModels) {
    if (info.model == model) return info;
  }
  return kModels[0];  // unreachable for valid enumerators
}

const HesaiLayout& GetHesaiLayout(LidarModel model) {
  static constexpr HesaiLayout kPandar64 = {
      pandar64::kHeaderBytes,      pandar64::kBlockBytes,       pandar64::kUnitBytes,
      pandar64::kLaserCountOffset, pandar64::kBlockCountOffset, pandar64::kDistanceUnitOffset,
      pandar64::kReturnModeOffset, pandar64::kMotorSpeedOffset, pandar64::kDateTimeOffset,
      pandar64::kTimestampOffset,  pandar64::kDistanceUnitMm};
  static constexpr HesaiLayout kXt32 = {
      pandarxt32::kHeaderBytes,      pandarxt32::kBlockBytes,       pandarxt32::kUnitBytes,
      pandarxt32::kLaserCountOffset, pandarxt32::kBlockCountOffset, pandarxt32::kDistanceUnitOffset,
      pandarxt32::kReturnModeOffset, pandarxt32::kMotorSpeedOffset, pandarxt32::kDateTimeOffset,
      pandarxt32::kTimestampOffset,  pandarxt32::kDistanceUnitMm};
  return model == LidarModel::kPandarXt32 ? kXt32 : kPandar64;
}

std::optional<LidarModel> LidarModelFromName(std::string_view name) {
  for (const LidarModelInfo& info : kModels) {
    if (name == info.name) return info.model;
  }
  return std::nullopt;
}

int ReturnsForModeByte(LidarModel model, std::uint8_t mode_byte) {
  switch (mode_byte) {
    case 0x37:  // strongest
    case 0x38:  // last
      return 1;
    case 0x39:  // last + strongest
      return 2;
    case 0x33:  // first (Hesai only)
      return model == LidarModel::kVlp16 ? 0 : 1;
    case 0x3B:  // last + first (Hesai only)
    case 0x3C:  // first + strongest (Hesai only)
      return model == LidarModel::kVlp16 ? 0 : 2;
    default:
      return 0;
  }
}

std::int64_t ColumnTimeOffsetNs(LidarModel model, int column, int columns_per_packet) {
  const int from_last = columns_per_packet - 1 - column;
  switch (model) {
    case LidarModel::kVlp16:
      return column * vlp16::kFiringPeriodNs;
    case LidarModel::kPandar64:
      return pandar64::kLastColumnOffsetNs - from_last * pandar64::kColumnPeriodNs;
    case LidarModel::kPandarXt32:
      return pandarxt32::kLastColumnOffsetNs - from_last * pandarxt32::kColumnPeriodNs;
  }
  return 0;
}

std::int64_t ChannelTimeOffsetNs(LidarModel model, int channel) {
  switch (model) {
    case LidarModel::kVlp16:
      return channel * vlp16::kLaserPeriodNs;
    case LidarModel::kPandar64:
      return kPandar64ChannelOffsetNs[channel];
    case LidarModel::kPandarXt32:
      return pandarxt32::kChannelBaseNs + channel * pandarxt32::kChannelPeriodNs;
  }
  return 0;
}

std::int64_t NearestTimeNs(std::int64_t remainder_ns, std::int64_t period_ns,
                           std::int64_t host_time_ns) {
  const std::int64_t r = remainder_ns - FloorDiv(remainder_ns, period_ns) * period_ns;
  std::int64_t t = FloorDiv(host_time_ns, period_ns) * period_ns + r;
  // Of the candidates one period apart, take the one nearest the host time.
  if (t - host_time_ns > period_ns / 2) t -= period_ns;
  if (host_time_ns - t > period_ns / 2) t += period_ns;
  return t;
}

std::optional<std::int64_t> HesaiUtcSeconds(std::span<const std::uint8_t, 6> date_time) {
  const int y = date_time[0];
  const std::int64_t year = y >= kHesaiFirstYear - kHesaiYearBase ? kHesaiYearBase + y : 2000 + y;
  const int month = date_time[1];
  const int day = date_time[2];
  const int hour = date_time[3];
  const int minute = date_time[4];
  const int second = date_time[5];
  // Second 60 is a leap second.
  if (month < 1 || month > 12 || day < 1 || day > DaysInMonth(year, month) || hour > 23 ||
      minute > 59 || second > 60) {
    return std::nullopt;
  }
  return DaysFromCivil(year, month, day) * kSecondsPerDay + hour * 3600 + minute * 60 + second;
}

double BeamAzimuthRad(const LidarBeam& beam, double column_azimuth_rad, double column_step_rad) {
  return column_azimuth_rad + beam.azimuth_offset_rad + beam.firing_fraction * column_step_rad;
}

Eigen::Vector3d LidarPointFromPolar(double range_m, double azimuth_rad, double elevation_rad) {
  const double xy = range_m * std::cos(elevation_rad);
  return {xy * std::sin(azimuth_rad), xy * std::cos(azimuth_rad),
          range_m * std::sin(elevation_rad)};
}

Eigen::Matrix3d LidarBaseRotation() {
  Eigen::Matrix3d r;
  // Columns: x_lidar, y_lidar, z_lidar expressed in the car frame.
  r << 0, 1, 0,  //
      -1, 0, 0,  //
      0, 0, 1;
  return r;
}

absl::StatusOr<LidarBeamTable> DefaultBeamTable(LidarModel model) {
  if (model != LidarModel::kVlp16) {
    return absl::FailedPreconditionError(
        absl::StrCat(GetLidarModelInfo(model).name,
                     " has per-unit angles: give its angle correction file (--angles)"));
  }
  LidarBeamTable table;
  table.model = model;
  for (int l = 0; l < vlp16::kLasers; ++l) {
    LidarBeam beam;
    beam.elevation_rad = vlp16::kElevationDeg[l] * kDegToRad;
    beam.firing_fraction = FiringFraction(model, l);
    table.beams.push_back(beam);
  }
  ComputeRings(table);
  return table;
}

absl::StatusOr<LidarBeamTable> ParseAngleCorrectionCsv(LidarModel model, std::string_view text,
                                                       std::string_view source_name) {
  const int channels = GetLidarModelInfo(model).channels;
  // Debian's Abseil has its own string_view type.
  const absl::string_view source(source_name.data(), source_name.size());
  LidarBeamTable table;
  table.model = model;
  bool header_seen = false;
  int line_number = 0;
  auto error = [&](const std::string& what) {
    return absl::InvalidArgumentError(absl::StrCat(source, ":", line_number, ": ", what));
  };
  for (absl::string_view line : absl::StrSplit(absl::string_view(text.data(), text.size()), '\n')) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (absl::StripAsciiWhitespace(line).empty()) continue;
    const std::vector<absl::string_view> fields = absl::StrSplit(line, ',');
    if (fields.size() != 3) {
      return error(absl::StrCat("expected 3 comma-separated fields, found ", fields.size()));
    }
    if (!header_seen) {
      if (!absl::EqualsIgnoreCase(absl::StripAsciiWhitespace(fields[1]), "elevation") ||
          !absl::EqualsIgnoreCase(absl::StripAsciiWhitespace(fields[2]), "azimuth")) {
        return error("expected the header 'Channel,Elevation,Azimuth'");
      }
      header_seen = true;
      continue;
    }
    const int expected = static_cast<int>(table.beams.size()) + 1;
    if (expected > channels) {
      return error(
          absl::StrCat("more than ", channels, " channels for ", GetLidarModelInfo(model).name));
    }
    const std::optional<double> n = ParseDouble(fields[0]);
    const std::optional<double> elevation_deg = ParseDouble(fields[1]);
    const std::optional<double> azimuth_deg = ParseDouble(fields[2]);
    if (!n || *n != expected) {
      return error(absl::StrCat("channel '", absl::StripAsciiWhitespace(fields[0]), "', expected ",
                                expected));
    }
    // Beyond ±90° elevation or ±180° azimuth offset an angle is no calibration: a typo.
    if (!elevation_deg || std::abs(*elevation_deg) > 90.0) {
      return error(absl::StrCat("elevation '", absl::StripAsciiWhitespace(fields[1]),
                                "' is not a number of degrees in [-90, 90]"));
    }
    if (!azimuth_deg || std::abs(*azimuth_deg) > 180.0) {
      return error(absl::StrCat("azimuth '", absl::StripAsciiWhitespace(fields[2]),
                                "' is not a number of degrees in [-180, 180]"));
    }
    LidarBeam beam;
    beam.elevation_rad = *elevation_deg * kDegToRad;
    beam.azimuth_offset_rad = *azimuth_deg * kDegToRad;
    beam.firing_fraction = FiringFraction(model, expected - 1);
    table.beams.push_back(beam);
  }
  if (!header_seen) {
    return absl::InvalidArgumentError(absl::StrCat(source, ": empty angle correction file"));
  }
  if (static_cast<int>(table.beams.size()) != channels) {
    return absl::InvalidArgumentError(absl::StrCat(source, ": found ", table.beams.size(),
                                                   " channels, ", GetLidarModelInfo(model).name,
                                                   " has ", channels));
  }
  ComputeRings(table);
  return table;
}

absl::StatusOr<LidarBeamTable> ReadAngleCorrectionCsv(LidarModel model,
                                                      const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot read ", path.string()));
  std::ostringstream text;
  text << in.rdbuf();
  return ParseAngleCorrectionCsv(model, text.str(), path.string());
}

absl::Status ValidateBeamTable(const LidarBeamTable& table) {
  const int channels = GetLidarModelInfo(table.model).channels;
  if (static_cast<int>(table.beams.size()) != channels) {
    return absl::InvalidArgumentError(
        absl::StrCat("beam table has ", table.beams.size(), " beams, the model has ", channels));
  }
  std::vector<bool> ring_used(channels, false);
  for (int c = 0; c < channels; ++c) {
    const LidarBeam& b = table.beams[c];
    if (!std::isfinite(b.elevation_rad) || !std::isfinite(b.azimuth_offset_rad) ||
        !std::isfinite(b.firing_fraction) || std::abs(b.elevation_rad) > std::numbers::pi / 2 ||
        std::abs(b.azimuth_offset_rad) > std::numbers::pi) {
      return absl::InvalidArgumentError(absl::StrCat("beam ", c, ": angle out of range"));
    }
    if (b.ring >= channels || ring_used[b.ring]) {
      return absl::InvalidArgumentError(
          absl::StrCat("beam ", c, ": ring ", b.ring, " is not a free ring below ", channels));
    }
    ring_used[b.ring] = true;
  }
  return absl::OkStatus();
}

absl::Status LidarEncodeSettings::Validate() const {
  if (GetLidarModelInfo(model).model != model) {
    return absl::InvalidArgumentError("model: unknown");
  }
  if (return_mode != LidarReturnMode::kStrongest && return_mode != LidarReturnMode::kLast &&
      return_mode != LidarReturnMode::kDual) {
    return absl::InvalidArgumentError("return_mode: not 0x37, 0x38 or 0x39");
  }
  if (model != LidarModel::kVlp16) {
    // Hesai packets carry a calendar date with a one-byte year.
    const std::int64_t first_s = DaysFromCivil(kHesaiFirstYear, 1, 1) * kSecondsPerDay;
    const std::int64_t end_s = DaysFromCivil(kHesaiLastYear + 1, 1, 1) * kSecondsPerDay;
    // One second of margin: the packet time precedes column 0 by less than that.
    if (first_column_time_ns < (first_s + 1) * kNsPerSecond ||
        first_column_time_ns >= (end_s - 3600) * kNsPerSecond) {
      return absl::InvalidArgumentError(
          absl::StrCat("first_column_time_ns: ", first_column_time_ns,
                       " is outside the years a Hesai date can hold (", kHesaiFirstYear, "-",
                       kHesaiLastYear, ")"));
    }
  }
  return absl::OkStatus();
}

int ColumnsPerPacket(LidarModel model, int returns) {
  const LidarModelInfo& info = GetLidarModelInfo(model);
  return info.blocks * info.columns_per_block / returns;
}

namespace {

// Writes the packet time of a Hesai packet: date/time bytes and µs within the second.
void WriteHesaiTime(std::int64_t packet_time_ns, std::uint8_t* date_time, std::uint8_t* timestamp) {
  const std::int64_t us = FloorDiv(packet_time_ns, kNsPerUs);
  const std::int64_t seconds = FloorDiv(us, 1'000'000);
  const std::int64_t days = FloorDiv(seconds, kSecondsPerDay);
  const std::int64_t in_day = seconds - days * kSecondsPerDay;
  const CivilDate date = CivilFromDays(days);
  date_time[0] = static_cast<std::uint8_t>(date.year - kHesaiYearBase);
  date_time[1] = static_cast<std::uint8_t>(date.month);
  date_time[2] = static_cast<std::uint8_t>(date.day);
  date_time[3] = static_cast<std::uint8_t>(in_day / 3600);
  date_time[4] = static_cast<std::uint8_t>(in_day % 3600 / 60);
  date_time[5] = static_cast<std::uint8_t>(in_day % 60);
  StoreLe32(timestamp, static_cast<std::uint32_t>(us - seconds * 1'000'000));
}

std::uint16_t EncodeRange(double range_m, double unit_m) {
  const double counts = std::round(range_m / unit_m);
  // Beyond the 16-bit field the sensor sees nothing: it sends 0, "no return".
  if (counts > 65535.0) return 0;
  return static_cast<std::uint16_t>(counts);
}

}  // namespace

absl::StatusOr<std::vector<std::vector<std::uint8_t>>> EncodeLidarPackets(
    const LidarEncodeSettings& settings, std::span<const LidarColumn> columns) {
  if (absl::Status s = settings.Validate(); !s.ok()) return s;
  const LidarModelInfo& info = GetLidarModelInfo(settings.model);
  const int returns = settings.return_mode == LidarReturnMode::kDual ? 2 : 1;
  const int per_packet = ColumnsPerPacket(settings.model, returns);
  if (columns.size() % per_packet != 0) {
    return absl::InvalidArgumentError(absl::StrCat(columns.size(), " columns: ", info.name,
                                                   " packets hold ", per_packet,
                                                   " columns each in this return mode"));
  }
  const std::size_t echoes_per_column = static_cast<std::size_t>(returns) * info.channels;
  for (std::size_t k = 0; k < columns.size(); ++k) {
    const LidarColumn& c = columns[k];
    if (c.echoes.size() != echoes_per_column) {
      return absl::InvalidArgumentError(absl::StrCat("column ", k, ": ", c.echoes.size(),
                                                     " echoes, expected ", echoes_per_column));
    }
    if (c.azimuth_centideg >= kCentidegPerTurn) {
      return absl::InvalidArgumentError(
          absl::StrCat("column ", k, ": azimuth ", c.azimuth_centideg, " is not below 36000"));
    }
    for (const LidarEcho& e : c.echoes) {
      if (!std::isfinite(e.range_m) || e.range_m < 0.0) {
        return absl::InvalidArgumentError(
            absl::StrCat("column ", k, ": range ", e.range_m, " is not a distance"));
      }
    }
  }

  std::vector<std::vector<std::uint8_t>> packets;
  const std::size_t packet_count = columns.size() / per_packet;
  packets.reserve(packet_count);
  const std::uint8_t mode = static_cast<std::uint8_t>(settings.return_mode);
  for (std::size_t p = 0; p < packet_count; ++p) {
    const LidarColumn* cols = columns.data() + p * per_packet;
    const std::int64_t first_column_ns =
        settings.first_column_time_ns +
        static_cast<std::int64_t>(p * per_packet) * info.column_period_ns;
    const std::int64_t packet_time_ns =
        first_column_ns - ColumnTimeOffsetNs(settings.model, 0, per_packet);
    const std::uint32_t sequence = settings.first_udp_sequence + static_cast<std::uint32_t>(p);
    std::vector<std::uint8_t> out;

    if (settings.model == LidarModel::kVlp16) {
      out.assign(vlp16::kPacketBytes, 0);
      for (int b = 0; b < vlp16::kBlocks; ++b) {
        std::uint8_t* block = out.data() + b * vlp16::kBlockBytes;
        // Single return: block b holds columns 2b and 2b+1. Dual: blocks 2q and 2q+1 hold
        // returns 0 and 1 of columns 2q and 2q+1.
        const int first_column = returns == 1 ? 2 * b : 2 * (b / 2);
        const int r = returns == 1 ? 0 : b % 2;
        StoreLe16(block, vlp16::kBlockFlag);
        StoreLe16(block + vlp16::kAzimuthOffsetInBlock, cols[first_column].azimuth_centideg);
        for (int f = 0; f < vlp16::kFiringsPerBlock; ++f) {
          const LidarColumn& col = cols[first_column + f];
          for (int l = 0; l < vlp16::kLasers; ++l) {
            const LidarEcho& e = col.echoes[r * vlp16::kLasers + l];
            std::uint8_t* m = block + vlp16::kDataOffsetInBlock +
                              (f * vlp16::kLasers + l) * vlp16::kMeasurementBytes;
            StoreLe16(m, EncodeRange(e.range_m, info.distance_unit_m));
            m[2] = e.intensity;
          }
        }
      }
      const std::int64_t in_hour_ns =
          packet_time_ns -
          FloorDiv(packet_time_ns, vlp16::kTimestampPeriodNs) * vlp16::kTimestampPeriodNs;
      StoreLe32(out.data() + vlp16::kTimestampOffset,
                static_cast<std::uint32_t>(in_hour_ns / kNsPerUs));
      out[vlp16::kReturnModeOffset] = mode;
      out[vlp16::kProductIdOffset] = vlp16::kProductId;
    } else {
      const bool xt32 = settings.model == LidarModel::kPandarXt32;
      const HesaiLayout& layout = GetHesaiLayout(settings.model);
      out.assign(xt32 ? pandarxt32::kPacketBytes
                      : (settings.pandar64_udp_sequence ? pandar64::kPacketBytesWithSequence
                                                        : pandar64::kPacketBytes),
                 0);
      out[0] = kHesaiMagic0;
      out[1] = kHesaiMagic1;
      out[layout.laser_count_offset] = static_cast<std::uint8_t>(info.channels);
      out[layout.block_count_offset] = static_cast<std::uint8_t>(info.blocks);
      out[layout.distance_unit_offset] = layout.distance_unit_mm;
      out[layout.return_mode_offset] = mode;
      StoreLe16(out.data() + layout.motor_speed_offset, settings.motor_rpm);
      WriteHesaiTime(packet_time_ns, out.data() + layout.date_time_offset,
                     out.data() + layout.timestamp_offset);
      if (xt32) {
        out[pandarxt32::kProtocolMajorOffset] = pandarxt32::kProtocolMajor;
        out[pandarxt32::kProtocolMinorOffset] = pandarxt32::kProtocolMinor;
        out[pandarxt32::kReturnCountOffset] = static_cast<std::uint8_t>(returns);
        StoreLe32(out.data() + pandarxt32::kUdpSequenceOffset, sequence);
      } else {
        // The factory byte of the recorded Pandar64 (docs/external-data.md).
        out[pandar64::kFactoryOffset] = 0x42;
        if (settings.pandar64_udp_sequence) {
          StoreLe32(out.data() + pandar64::kUdpSequenceOffset, sequence);
        }
      }
      for (int b = 0; b < info.blocks; ++b) {
        std::uint8_t* block = out.data() + layout.header_bytes + b * layout.block_bytes;
        const LidarColumn& col = cols[b / returns];
        const int r = b % returns;
        StoreLe16(block, col.azimuth_centideg);
        for (int c = 0; c < info.channels; ++c) {
          const LidarEcho& e = col.echoes[r * info.channels + c];
          std::uint8_t* u = block + 2 + c * layout.unit_bytes;
          StoreLe16(u, EncodeRange(e.range_m, layout.distance_unit_mm * 1e-3));
          u[2] = e.intensity;
        }
      }
    }
    packets.push_back(std::move(out));
  }
  return packets;
}

}  // namespace linecal

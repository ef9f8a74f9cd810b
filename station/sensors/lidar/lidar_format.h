#pragma once
// UDP packet formats of the LiDARs the station calibrates, their beam geometry, and encoders
// that write vendor packets (the simulator's LiDAR output). The decoders are in
// station/sensors/lidar/lidar_decoder.h; both sides share the facts here.
//
// Models (docs/sensors.md, checked against the real recordings of
// docs/external-data.md):
// - Velodyne VLP-16: 1206-byte payload, 12 blocks of 2 firing sequences × 16 lasers.
// - Hesai Pandar64: 1194-byte payload (1198 with a trailing UDP sequence number), 6 blocks
//   × 64 channels.
// - Hesai PandarXT-32 (protocol 6.1): 1080-byte payload, 8 blocks × 32 channels.
//
// Vocabulary. A *column* is one firing of every channel at one azimuth (the unit the sensor
// repeats while it spins). A packet holds `blocks` data blocks; a VLP-16 block holds two
// columns that share one azimuth field, a Hesai block one column. In dual-return mode two
// consecutive blocks hold the two returns of the same columns.
//
// LiDAR frame (docs/conventions.md: "as the vendor defines it"), the same for all three models,
// as both vendors' manuals define it:
//   origin  the sensor's origin on the rotation axis (VLP-16: 37.7 mm above its base, per
//           its manual; Hesai: as their manuals draw it)
//   +z      up along the rotation axis (towards the top cap)
//   +y      azimuth 0, the direction the manuals' top views mark as 0°
//   +x      azimuth 90°, i.e. to the right when looking along +y (x × y = z)
// Azimuth α grows clockwise seen from above; elevation ω grows upwards. A return at range R:
//   x = R cos ω sin α,   y = R cos ω cos α,   z = R sin ω          (LidarPointFromPolar)
// Many ROS drivers rotate this to x forward, y left; we do not (see LidarBaseRotation).

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace linecal {

enum class LidarModel { kVlp16, kPandar64, kPandarXt32 };

// Fixed facts of one model's packets.
struct LidarModelInfo {
  LidarModel model;
  const char* name;          // the CLI's --model value: "vlp16", "pandar64", "pandarxt32"
  int channels;              // lasers / channels per column
  int blocks;                // data blocks per packet
  int columns_per_block;     // VLP-16: 2 firing sequences share a block's azimuth; Hesai: 1
  std::size_t packet_bytes;  // UDP payload size
  // Another accepted payload size: Pandar64 firmware that appends a 4-byte UDP sequence
  // number sends 1198 bytes. Equal to packet_bytes for the other models.
  std::size_t packet_bytes_alt;
  double distance_unit_m;          // metres per distance count
  std::int64_t column_period_ns;   // time between consecutive columns
  std::uint16_t default_udp_port;  // where the sensor sends data by factory default
};

// O(1). The table is static; the reference stays valid for the program's lifetime.
const LidarModelInfo& GetLidarModelInfo(LidarModel model);
// Parses a --model value ("vlp16", "pandar64", "pandarxt32"); nullopt for anything else.
std::optional<LidarModel> LidarModelFromName(std::string_view name);

// ---------------------------------------------------------------------------------------
// Packet layouts (byte offsets into the UDP payload; multi-byte fields are little-endian).

namespace vlp16 {
inline constexpr std::size_t kPacketBytes = 1206;
inline constexpr int kBlocks = 12;
inline constexpr std::size_t kBlockBytes = 100;
inline constexpr int kLasers = 16;
inline constexpr int kFiringsPerBlock = 2;
inline constexpr std::size_t kMeasurementBytes = 3;  // u16 distance, u8 reflectivity
// Each block opens with the bytes FF EE (read little-endian: 0xEEFF), then a u16 azimuth.
inline constexpr std::uint16_t kBlockFlag = 0xEEFF;
inline constexpr std::size_t kAzimuthOffsetInBlock = 2;
inline constexpr std::size_t kDataOffsetInBlock = 4;
inline constexpr std::size_t kTimestampOffset = 1200;  // u32 µs since the top of the hour
inline constexpr std::int64_t kTimestampPeriodNs = 3'600'000'000'000;  // that counter's period
inline constexpr std::size_t kReturnModeOffset = 1204;
inline constexpr std::size_t kProductIdOffset = 1205;
inline constexpr std::uint8_t kProductId = 0x22;  // VLP-16 (0x24 would be the Puck Hi-Res)
inline constexpr double kDistanceUnitM = 0.002;
// Firing timing (VLP-16 manual): one laser every 2.304 µs, a firing sequence of 16 lasers
// and an idle gap every 55.296 µs; the packet time stamps the first firing of block 0.
inline constexpr std::int64_t kLaserPeriodNs = 2304;
inline constexpr std::int64_t kFiringPeriodNs = 55296;
// Laser elevations in degrees, laser 0..15 (VLP-16 manual; VLP16.yaml of the recording).
inline constexpr std::array<double, kLasers> kElevationDeg = {-15, 1, -13, 3,  -11, 5,  -9, 7,
                                                              -7,  9, -5,  11, -3,  13, -1, 15};
}  // namespace vlp16

namespace pandar64 {
inline constexpr std::size_t kPacketBytes = 1194;
inline constexpr std::size_t kPacketBytesWithSequence = 1198;
inline constexpr std::size_t kHeaderBytes = 8;
inline constexpr int kBlocks = 6;
inline constexpr int kChannels = 64;
inline constexpr std::size_t kUnitBytes = 3;  // u16 distance, u8 reflectivity
inline constexpr std::size_t kBlockBytes = 2 + kChannels * kUnitBytes;
// Header: EE FF, laser count, block count, reserved, distance unit (mm), 2 reserved.
inline constexpr std::size_t kLaserCountOffset = 2;
inline constexpr std::size_t kBlockCountOffset = 3;
inline constexpr std::size_t kDistanceUnitOffset = 5;
// Tail (22 bytes from 1172): 5 reserved, high-temperature flag, 2 reserved, motor speed
// u16 (rpm), timestamp u32 (µs within the second), return mode, factory info, date/time.
inline constexpr std::size_t kTailOffset = kHeaderBytes + kBlocks * kBlockBytes;
inline constexpr std::size_t kMotorSpeedOffset = kTailOffset + 8;
inline constexpr std::size_t kTimestampOffset = kTailOffset + 10;
inline constexpr std::size_t kReturnModeOffset = kTailOffset + 14;
inline constexpr std::size_t kFactoryOffset = kTailOffset + 15;
inline constexpr std::size_t kDateTimeOffset = kTailOffset + 16;  // year, month, day, h, m, s
inline constexpr std::size_t kUdpSequenceOffset = kPacketBytes;
inline constexpr std::uint8_t kDistanceUnitMm = 4;
// Timing (Pandar64 manual): columns every 55.56 µs; the packet time stamps a point 42.58 µs
// after the last column, and each channel fires at its own offset within the column.
inline constexpr std::int64_t kColumnPeriodNs = 55560;
inline constexpr std::int64_t kLastColumnOffsetNs = -42580;
}  // namespace pandar64

namespace pandarxt32 {
inline constexpr std::size_t kPacketBytes = 1080;
inline constexpr std::size_t kHeaderBytes = 12;
inline constexpr int kBlocks = 8;
inline constexpr int kChannels = 32;
inline constexpr std::size_t kUnitBytes = 4;  // u16 distance, u8 reflectivity, u8 reserved
inline constexpr std::size_t kBlockBytes = 2 + kChannels * kUnitBytes;
// Header: EE FF, protocol major, minor, 2 reserved, laser count, block count, reserved,
// distance unit (mm), return count, flags.
inline constexpr std::size_t kProtocolMajorOffset = 2;
inline constexpr std::size_t kProtocolMinorOffset = 3;
inline constexpr std::uint8_t kProtocolMajor = 6;
inline constexpr std::uint8_t kProtocolMinor = 1;
inline constexpr std::size_t kLaserCountOffset = 6;
inline constexpr std::size_t kBlockCountOffset = 7;
inline constexpr std::size_t kDistanceUnitOffset = 9;
inline constexpr std::size_t kReturnCountOffset = 10;
// Tail (24 bytes from 1052): 10 reserved, return mode, motor speed u16, date/time (year −
// 1900, month, day, h, m, s), timestamp u32 (µs within the second), factory info; then the
// u32 UDP sequence number.
inline constexpr std::size_t kTailOffset = kHeaderBytes + kBlocks * kBlockBytes;
inline constexpr std::size_t kReturnModeOffset = kTailOffset + 10;
inline constexpr std::size_t kMotorSpeedOffset = kTailOffset + 11;
inline constexpr std::size_t kDateTimeOffset = kTailOffset + 13;
inline constexpr std::size_t kTimestampOffset = kTailOffset + 19;
inline constexpr std::size_t kFactoryOffset = kTailOffset + 23;
inline constexpr std::size_t kUdpSequenceOffset = kTailOffset + 24;
inline constexpr std::uint8_t kDistanceUnitMm = 4;
// Timing (PandarXT-32 manual, protocol 6.1): columns every 50 µs; the last column fires
// 5.632 µs after the packet time, channel c 0.368 + 1.512·c µs after its column.
inline constexpr std::int64_t kColumnPeriodNs = 50000;
inline constexpr std::int64_t kLastColumnOffsetNs = 5632;
inline constexpr std::int64_t kChannelBaseNs = 368;
inline constexpr std::int64_t kChannelPeriodNs = 1512;
}  // namespace pandarxt32

// Both Hesai headers open with the bytes EE FF.
inline constexpr std::uint8_t kHesaiMagic0 = 0xEE;
inline constexpr std::uint8_t kHesaiMagic1 = 0xFF;

// Where a Hesai model keeps the fields both Hesai formats share (the constants above, in one
// place for the encoder and the decoder).
struct HesaiLayout {
  std::size_t header_bytes;
  std::size_t block_bytes;
  std::size_t unit_bytes;
  std::size_t laser_count_offset;
  std::size_t block_count_offset;
  std::size_t distance_unit_offset;
  std::size_t return_mode_offset;
  std::size_t motor_speed_offset;
  std::size_t date_time_offset;
  std::size_t timestamp_offset;
  std::uint8_t distance_unit_mm;  // what the sensors send
};

// The layout of kPandar64 or kPandarXt32 (the Pandar64's for the VLP-16, which has none).
// O(1); the reference stays valid for the program's lifetime.
const HesaiLayout& GetHesaiLayout(LidarModel model);

// Return modes as the packets write them (the same byte values on all three models).
enum class LidarReturnMode : std::uint8_t {
  kStrongest = 0x37,
  kLast = 0x38,
  kDual = 0x39,  // last and strongest (the second strongest when they coincide)
};

// Returns per column that a return-mode byte announces: 1 or 2, or 0 when `model` does not
// send that byte. VLP-16: 0x37, 0x38 single, 0x39 dual. Hesai adds 0x33 (first) single and
// 0x3B (last + first), 0x3C (first + strongest) dual. Cost: O(1).
int ReturnsForModeByte(LidarModel model, std::uint8_t mode_byte);

// Time of column `column` (0-based) of a packet relative to the packet's time field, for a
// packet of `columns_per_packet` columns. Negative on Hesai (the time field stamps the end of
// the packet). Cost: O(1).
std::int64_t ColumnTimeOffsetNs(LidarModel model, int column, int columns_per_packet);
// When channel `channel` fires relative to its column's time. Cost: O(1).
std::int64_t ChannelTimeOffsetNs(LidarModel model, int channel);

// The time nearest `host_time_ns` whose remainder modulo `period_ns` is `remainder_ns`.
// Packet time fields that count only within a period (VLP-16: µs since the top of the hour;
// a Hesai packet without a valid date: µs within the second) are completed from the host's
// receive or pcap record time (ns since the epoch) this way; host and sensor clocks may then
// differ by up to half a period. Requires period_ns > 0. Cost: O(1).
std::int64_t NearestTimeNs(std::int64_t remainder_ns, std::int64_t period_ns,
                           std::int64_t host_time_ns);

// Hesai date/time bytes (year, month 1-12, day 1-31, hour, minute, second) as seconds since
// the epoch (UTC). The year byte counts from 1900 in recorded Pandar64 packets and from 2000
// in some firmware: values ≥ 70 are read as 1900 + y (1970-2155), smaller ones as 2000 + y
// (2000-2069). nullopt when a field is out of range. Cost: O(1).
std::optional<std::int64_t> HesaiUtcSeconds(std::span<const std::uint8_t, 6> date_time);

// ---------------------------------------------------------------------------------------
// Beam geometry.

struct LidarBeam {
  double elevation_rad = 0.0;
  // Added to the column azimuth (Hesai per-unit calibration; 0 on the VLP-16).
  double azimuth_offset_rad = 0.0;
  // Fraction of the rotation between two columns that has passed when this beam fires; the
  // decoder adds it to the azimuth (VLP-16: laser · 2.304 / 55.296). 0 on Hesai, whose
  // calibrated offsets already include the firing delay.
  double firing_fraction = 0.0;
  std::uint16_t ring = 0;  // 0 = lowest elevation (ties: lower channel first)
};

struct LidarBeamTable {
  LidarModel model = LidarModel::kVlp16;
  std::vector<LidarBeam> beams;  // index = channel number in the packet, 0-based
};

// The azimuth the decoders assign to a beam, in radians (not wrapped): the column azimuth,
// plus the beam's offset, plus firing_fraction times the rotation to the next column
// (`column_step_rad`). This is the direction a simulator must cast a ray in. Cost: O(1).
double BeamAzimuthRad(const LidarBeam& beam, double column_azimuth_rad, double column_step_rad);

// p_lidar of a return (see the frame above). Cost: O(1).
Eigen::Vector3d LidarPointFromPolar(double range_m, double azimuth_rad, double elevation_rad);

// R_base of a LiDAR (docs/conventions.md "mounting angles"): maps y_lidar (azimuth 0) to x_car,
// x_lidar to −y_car and z_lidar to z_car, so that a LiDAR mounted upright with azimuth 0
// looking forward has yaw = pitch = roll = 0. Columns are the LiDAR axes in the car frame.
Eigen::Matrix3d LidarBaseRotation();

// The built-in table: the VLP-16 elevations above. Hesai units need their own correction
// file: FailedPrecondition naming the model. Cost: O(channels).
absl::StatusOr<LidarBeamTable> DefaultBeamTable(LidarModel model);

// Parses an angle correction file: a header line (any first column name, then "Elevation"
// and "Azimuth"; Hesai writes "Laser id" or "Channel"), then one line per channel
// "n,elevation_deg,azimuth_offset_deg" with n = 1..channels in order. Blank lines and a
// trailing '\r' are accepted. InvalidArgument "<source_name>:<line>: <problem>" for a bad
// line, a wrong channel number or count, or an angle outside ±90° (elevation) / ±180°
// (azimuth). firing_fraction comes from the model, rings from the elevations.
// Cost: O(text size + channels log channels).
absl::StatusOr<LidarBeamTable> ParseAngleCorrectionCsv(LidarModel model, std::string_view text,
                                                       std::string_view source_name);
// Reads and parses a correction file; NotFound naming the path when it cannot be read.
absl::StatusOr<LidarBeamTable> ReadAngleCorrectionCsv(LidarModel model,
                                                      const std::filesystem::path& path);

// Checks a table: one beam per channel of its model, finite angles, rings a permutation of
// 0..channels-1. InvalidArgument naming the channel. Cost: O(channels).
absl::Status ValidateBeamTable(const LidarBeamTable& table);

// ---------------------------------------------------------------------------------------
// Encoders: columns → vendor packets.

struct LidarEcho {
  double range_m = 0.0;  // 0: no return
  std::uint8_t intensity = 0;
};

struct LidarColumn {
  // The azimuth field, 0.01° steps, 0..35999. On the VLP-16 only even columns' azimuths
  // are sent (a block's two columns share its field); the decoder puts the odd column
  // halfway to the next block, so a simulator must space columns evenly.
  std::uint16_t azimuth_centideg = 0;
  // returns × channels echoes, return-major: echoes[r * channels + c]. Dual return: r = 0
  // is sent in the even block of a pair, r = 1 in the odd one.
  std::vector<LidarEcho> echoes;
};

struct LidarEncodeSettings {
  LidarModel model = LidarModel::kVlp16;
  LidarReturnMode return_mode = LidarReturnMode::kStrongest;
  // Time of column 0 (ns since the epoch); column k fires k · column_period_ns later. The
  // packets' time fields have 1 µs resolution: decoded times are up to 1 µs earlier.
  std::int64_t first_column_time_ns = 0;
  std::uint32_t first_udp_sequence = 0;  // Hesai: the first packet's sequence number
  bool pandar64_udp_sequence = true;     // Pandar64: append it (1198-byte payloads)
  std::uint16_t motor_rpm = 600;         // written to Hesai tails (600 rpm = 10 Hz)

  // InvalidArgument naming the field (for Hesai, a time outside the years 1970-2155 that
  // the date bytes can hold).
  absl::Status Validate() const;
};

// Columns per packet for a model and number of returns (1 or 2). Cost: O(1).
int ColumnsPerPacket(LidarModel model, int returns);

// Encodes columns into packets, ColumnsPerPacket columns each, in order. InvalidArgument
// when the settings are invalid, the column count is not a multiple of ColumnsPerPacket, a
// column has the wrong number of echoes or an azimuth ≥ 36000, or a range is negative or
// not finite. Ranges are rounded to the model's distance unit; ranges beyond the 16-bit
// distance field are sent as "no return", as the sensor does. Cost: O(columns · channels).
absl::StatusOr<std::vector<std::vector<std::uint8_t>>> EncodeLidarPackets(
    const LidarEncodeSettings& settings, std::span<const LidarColumn> columns);

}  // namespace linecal

#pragma once
// CAN message formats of the automotive radars the station calibrates, and their encoders.
//
// - A generic DBC signal (start|length, byte order, sign, factor, offset) with one bit
//   extract/insert pair used by every decoder and encoder here.
// - Continental ARS408-21: cluster list (0x600 status, 0x701 general, 0x702 quality) and
//   object list (0x60A status, 0x60B general); sensor id n (0..7) adds n·0x10 to every id.
// - Delphi ESR 2.5: status 0x4E0 and 64 track messages 0x500..0x53F, as in opendbc's ESR.dbc
//   (tests/station/sensors parse that file and compare it with the constants here).
// - RadarDetection / RadarCycle: what a radar reports in one measurement cycle, in the radar
//   frame of docs/conventions.md (x along the boresight, y left, z up); the simulator encodes
//   them into frames here and station/sensors/radar/radar_decoder turns frames back into them.
//
// Conventions that public sources disagree on are options (RadarConventions).

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "station/io/candump.h"

namespace linecal {

// ---------------------------------------------------------------------------------------
// Generic DBC signals.

// DBC byte order: `@0` is Motorola (big-endian), `@1` Intel (little-endian).
enum class ByteOrder { kBigEndian, kLittleEndian };

// One signal as a DBC file writes it: `SG_ NAME : start|length@order sign (factor,offset)`.
// Bit numbering is DBC's: bit b of byte k is number 8k + b (b = 0 is the byte's LSB). For
// big-endian signals `start_bit` is the signal's most significant bit and the signal runs
// towards the LSB of that byte, then on from the MSB of the next byte; for little-endian
// signals `start_bit` is the least significant bit and the signal runs upwards.
struct CanSignal {
  const char* name;  // the DBC name, for error messages and the DBC cross-check
  int start_bit;
  int length;  // 1..63 bits
  ByteOrder byte_order;
  bool is_signed;  // two's complement
  double factor;
  double offset;
};

// The number of payload bytes a signal needs (1 + index of the last byte it touches).
// Requires 0 <= start_bit < 512 and 1 <= length <= 63. Cost: O(1).
int SignalBytesNeeded(const CanSignal& signal);

// The raw value (sign-extended when is_signed), or nullopt when the payload is shorter than
// SignalBytesNeeded. Cost: O(length / 8).
std::optional<int64_t> ExtractRaw(std::span<const uint8_t> payload, const CanSignal& signal);

// raw · factor + offset, or nullopt as ExtractRaw.
std::optional<double> ExtractPhysical(std::span<const uint8_t> payload, const CanSignal& signal);

// Writes a raw value into the signal's bits, leaving the other bits alone. OutOfRange naming
// the signal when the value does not fit its bits or the payload is too short.
absl::Status InsertRaw(std::span<uint8_t> payload, const CanSignal& signal, int64_t raw);

// Rounds (value − offset) / factor to the nearest raw value and inserts it. OutOfRange naming
// the signal and the value when it is not finite or not representable. The decoded value then
// differs from `value` by at most factor / 2.
absl::Status InsertPhysical(std::span<uint8_t> payload, const CanSignal& signal, double value);

// ---------------------------------------------------------------------------------------
// Conventions public sources disagree on.

struct RadarConventions {
  // ARS408 MeasCounter (0x600 bytes 2-3, 0x60A bytes 1-2). Continental's DBC writes every
  // ARS408 signal as Motorola, including this one (23|16@0, 15|16@0), so big-endian is the
  // default; some open drivers read it little-endian.
  ByteOrder ars408_counter_byte_order = ByteOrder::kBigEndian;
  // ARS408 object DistLat (0x60B). Default true: positive to the left, the radar frame's +y,
  // as the cluster DistLat (whose sign the worked example of docs/sensors.md fixes) and as the
  // ISO 8855 coordinate system Continental documents for both lists; some drivers negate it.
  bool ars408_object_lat_left_positive = true;
  // ESR CAN_TX_TRACK_ANGLE. Default true: positive clockwise seen from above (to the right),
  // as Delphi's ESR documentation describes it and public decoders that negate it before
  // forming y = r·sin(angle) assume; so azimuth_rad (counter-clockwise) = −angle.
  bool esr_angle_clockwise_positive = true;
};

// ---------------------------------------------------------------------------------------
// What a radar reports, in the radar frame (x boresight, y left, z up; azimuth counter-
// clockwise from x seen from above).

enum class RadarDetectionKind { kCluster, kObject, kTrack };

// "cluster", "object", "track".
const char* RadarDetectionKindName(RadarDetectionKind kind);

// ARS408 cluster quality (0x702), raw codes of Continental's tables.
struct Ars408ClusterQuality {
  int dist_long_rms = 0;  // 0..31, index into the standard-deviation table
  int dist_lat_rms = 0;   // 0..31
  int pdh0 = 0;           // 0..7, false-alarm probability class
  int ambig_state = 0;    // 0..7, Doppler ambiguity state
  int invalid_state = 0;  // 0..31, 0 = valid
};

struct RadarDetection {
  int id = 0;  // ARS408 cluster/object id 0..255; ESR track number 1..64 (DBC TargetN)
  RadarDetectionKind kind = RadarDetectionKind::kCluster;
  double range_m = 0;
  double azimuth_rad = 0;
  double range_rate_mps = 0;       // positive moving away
  std::optional<double> rcs_dbsm;  // ARS408 only (the ESR track messages carry none)
  std::optional<Ars408ClusterQuality> cluster_quality;  // ARS408 clusters with a 0x702 message

  double x_m() const;  // range·cos(azimuth)
  double y_m() const;  // range·sin(azimuth)
};

// One measurement cycle of one sensor: a cluster list, an object list or an ESR scan.
struct RadarCycle {
  CanTime time{};     // time of the cycle's status frame (0x600 / 0x60A / 0x4E0)
  int sensor_id = 0;  // ARS408 sensor id 0..7; 0 for the ESR
  RadarDetectionKind kind = RadarDetectionKind::kCluster;
  uint32_t counter = 0;  // ARS408 MeasCounter or ESR scan index
  // Messages the status announced (ARS408 NofClusters / NofObjects; ESR: 64 track slots) and
  // those that arrived. A cycle is complete when they match.
  int messages_expected = 0;
  int messages_received = 0;
  std::vector<RadarDetection> detections;  // ESR: only slots whose track status is not 0

  bool complete() const { return messages_expected == messages_received; }
};

// Time between consecutive frames the encoders below write: one 8-byte classic frame at the
// ARS408's and ESR's 500 kbit/s takes ~0.23–0.27 ms on the bus (111–135 bits with stuffing).
inline constexpr std::chrono::microseconds kRadarFrameSpacing{250};

// ---------------------------------------------------------------------------------------
// Continental ARS408-21.

namespace ars408 {
// Message ids for sensor id 0; sensor id n adds n·kSensorIdStride.
inline constexpr uint32_t kClusterStatusId = 0x600;
inline constexpr uint32_t kClusterGeneralId = 0x701;
inline constexpr uint32_t kClusterQualityId = 0x702;
inline constexpr uint32_t kObjectStatusId = 0x60A;
inline constexpr uint32_t kObjectGeneralId = 0x60B;
inline constexpr uint32_t kSensorIdStride = 0x10;
inline constexpr int kMaxSensorId = 7;  // 3-bit SensorID in RadarCfg

// Signals (docs/sensors.md; Continental ARS408 DBC). Status messages:
inline constexpr CanSignal kNofClustersNear{
    "Cluster_NofClustersNear", 7, 8, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kNofClustersFar{
    "Cluster_NofClustersFar", 15, 8, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kClusterMeasCounter{
    "Cluster_MeasCounter", 23, 16, ByteOrder::kBigEndian, false, 1, 0};
// The same 16 bits (bytes 2-3) read little-endian (RadarConventions).
inline constexpr CanSignal kClusterMeasCounterLe{
    "Cluster_MeasCounter", 16, 16, ByteOrder::kLittleEndian, false, 1, 0};
inline constexpr CanSignal kClusterInterfaceVersion{
    "Cluster_InterfaceVersion", 39, 4, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kNofObjects{"Obj_NofObjects", 7, 8, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kObjectMeasCounter{
    "Obj_MeasCounter", 15, 16, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kObjectMeasCounterLe{
    "Obj_MeasCounter", 8, 16, ByteOrder::kLittleEndian, false, 1, 0};
inline constexpr CanSignal kObjectInterfaceVersion{
    "Obj_InterfaceVersion", 31, 4, ByteOrder::kBigEndian, false, 1, 0};
// Cluster general (0x701).
inline constexpr CanSignal kClusterIdSignal{"Cluster_ID", 7, 8, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kClusterDistLong{
    "Cluster_DistLong", 15, 13, ByteOrder::kBigEndian, false, 0.2, -500};
inline constexpr CanSignal kClusterDistLat{
    "Cluster_DistLat", 17, 10, ByteOrder::kBigEndian, false, 0.2, -102.3};
inline constexpr CanSignal kClusterVrelLong{
    "Cluster_VrelLong", 39, 10, ByteOrder::kBigEndian, false, 0.25, -128};
inline constexpr CanSignal kClusterVrelLat{
    "Cluster_VrelLat", 45, 9, ByteOrder::kBigEndian, false, 0.25, -64};
inline constexpr CanSignal kClusterDynProp{
    "Cluster_DynProp", 50, 3, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kClusterRcs{"Cluster_RCS", 63,  8,  ByteOrder::kBigEndian,
                                       false,         0.5, -64};
// Cluster quality (0x702); its first byte is the cluster id, as in every per-cluster message.
inline constexpr CanSignal kQualityClusterId{"Cluster_ID", 7, 8, ByteOrder::kBigEndian,
                                             false,        1, 0};
inline constexpr CanSignal kClusterDistLongRms{
    "Cluster_DistLong_rms", 15, 5, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kClusterDistLatRms{
    "Cluster_DistLat_rms", 10, 5, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kClusterPdh0{"Cluster_PdH0", 26, 3, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kClusterAmbigState{
    "Cluster_AmbigState", 34, 3, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kClusterInvalidState{
    "Cluster_InvalidState", 39, 5, ByteOrder::kBigEndian, false, 1, 0};
// Object general (0x60B).
inline constexpr CanSignal kObjectIdSignal{"Obj_ID", 7, 8, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kObjectDistLong{"Obj_DistLong", 15,  13,  ByteOrder::kBigEndian,
                                           false,          0.2, -500};
inline constexpr CanSignal kObjectDistLat{"Obj_DistLat", 18,  11,    ByteOrder::kBigEndian,
                                          false,         0.2, -204.6};
inline constexpr CanSignal kObjectVrelLong{"Obj_VrelLong", 39,   10,  ByteOrder::kBigEndian,
                                           false,          0.25, -128};
inline constexpr CanSignal kObjectVrelLat{"Obj_VrelLat", 45,   9,  ByteOrder::kBigEndian,
                                          false,         0.25, -64};
inline constexpr CanSignal kObjectDynProp{"Obj_DynProp", 50, 3, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kObjectRcs{"Obj_RCS", 63, 8, ByteOrder::kBigEndian, false, 0.5, -64};
}  // namespace ars408

enum class Ars408Message {
  kClusterStatus,
  kClusterGeneral,
  kClusterQuality,
  kObjectStatus,
  kObjectGeneral
};

// Which ARS408 message a frame id is, and of which sensor id; nullopt for any other id.
// Only 11-bit ids qualify (the caller checks CanFrame::extended). Cost: O(1).
struct Ars408Id {
  Ars408Message message;
  int sensor_id;
};
std::optional<Ars408Id> ClassifyArs408Id(uint32_t id);

// List status (0x600 clusters / 0x60A objects), physical values.
struct Ars408ListStatus {
  int near_count = 0;  // clusters: NofClustersNear; objects: NofObjects
  int far_count = 0;   // clusters: NofClustersFar; objects: always 0
  uint32_t meas_counter = 0;
  int interface_version = 0;
};

// One cluster (0x701) or object (0x60B), physical values in the message's own units and signs.
struct Ars408Target {
  int id = 0;
  double dist_long_m = 0;
  double dist_lat_m = 0;  // clusters: positive left; objects: see RadarConventions
  double vrel_long_mps = 0;
  double vrel_lat_mps = 0;
  int dyn_prop = 0;  // dynamic property code 0..7
  double rcs_dbsm = 0;
};

// Decoders: nullopt when the payload is shorter than the message's signals need.
std::optional<Ars408ListStatus> DecodeArs408ListStatus(std::span<const uint8_t> payload,
                                                       RadarDetectionKind kind,
                                                       const RadarConventions& conventions);
std::optional<Ars408Target> DecodeArs408Target(std::span<const uint8_t> payload,
                                               RadarDetectionKind kind);
// The cluster id and its quality.
std::optional<std::pair<int, Ars408ClusterQuality>> DecodeArs408ClusterQuality(
    std::span<const uint8_t> payload);

// Message ↔ detection in the radar frame. Range rate is the line-of-sight component of the
// relative velocity; an encoded detection gets a purely radial velocity.
RadarDetection Ars408TargetToDetection(const Ars408Target& target, RadarDetectionKind kind,
                                       const RadarConventions& conventions);
Ars408Target Ars408TargetFromDetection(const RadarDetection& detection,
                                       const RadarConventions& conventions);

// Encoders: one 8-byte (quality: 5-byte) classic frame with the sensor's id on `interface`.
// InvalidArgument for a sensor id outside 0..7 or a kind other than cluster/object;
// OutOfRange naming the signal for an unrepresentable value (e.g. > 255 targets, DistLong
// beyond 1138.2 m).
absl::StatusOr<CanFrame> EncodeArs408ListStatus(const Ars408ListStatus& status,
                                                RadarDetectionKind kind, int sensor_id,
                                                const RadarConventions& conventions);
absl::StatusOr<CanFrame> EncodeArs408Target(const Ars408Target& target, RadarDetectionKind kind,
                                            int sensor_id);
absl::StatusOr<CanFrame> EncodeArs408ClusterQuality(int cluster_id,
                                                    const Ars408ClusterQuality& quality,
                                                    int sensor_id);

// A whole cycle as the sensor sends it: the status frame (all clusters are reported as
// near-scan clusters), one general frame per detection, then one quality frame per cluster
// that has cluster_quality. Frame times start at cycle.time, kRadarFrameSpacing apart; the
// interface name is `interface`. Errors as above, naming the detection index.
absl::StatusOr<std::vector<CanFrame>> EncodeArs408Cycle(const RadarCycle& cycle,
                                                        const std::string& interface,
                                                        const RadarConventions& conventions);

// ---------------------------------------------------------------------------------------
// Delphi ESR 2.5 (ESR.dbc).

namespace esr {
inline constexpr uint32_t kStatusId = 0x4E0;      // ESR_Status (BO_ 1248)
inline constexpr uint32_t kFirstTrackId = 0x500;  // Target1 (BO_ 1280)
inline constexpr int kTrackCount = 64;            // Target1..Target64 = 0x500..0x53F

// ESR_Status (0x4E0).
inline constexpr CanSignal kScanIndex{
    "CAN_TX_SCAN_INDEX", 31, 16, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kRollingCount1{
    "CAN_TX_ROLLING_COUNT_1", 6, 2, ByteOrder::kLittleEndian, false, 1, 0};
inline constexpr CanSignal kDspTimestamp{
    "CAN_TX_DSP_TIMESTAMP", 5, 7, ByteOrder::kBigEndian, false, 2, 0};
inline constexpr CanSignal kCommError{
    "CAN_TX_COMM_ERROR", 14, 1, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kRadiusCurvatureCalc{
    "CAN_TX_RADIUS_CURVATURE_CALC", 13, 14, ByteOrder::kBigEndian, true, 1, 0};
inline constexpr CanSignal kYawRateCalc{
    "CAN_TX_YAW_RATE_CALC", 47, 12, ByteOrder::kBigEndian, true, 0.0625, 0};
inline constexpr CanSignal kVehicleSpeedCalc{
    "CAN_TX_VEHICLE_SPEED_CALC", 50, 11, ByteOrder::kBigEndian, false, 0.0625, 0};

// Track messages (every TargetN has the same layout).
inline constexpr CanSignal kTrackLatRate{
    "CAN_TX_TRACK_LAT_RATE", 7, 6, ByteOrder::kBigEndian, true, 0.25, 0};
inline constexpr CanSignal kTrackGroupingChanged{
    "CAN_TX_TRACK_GROUPING_CHANGED", 1, 1, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kTrackOncoming{
    "CAN_TX_TRACK_ONCOMING", 0, 1, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kTrackStatus{
    "CAN_TX_TRACK_STATUS", 15, 3, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kTrackAngle{
    "CAN_TX_TRACK_ANGLE", 12, 10, ByteOrder::kBigEndian, true, 0.1, 0};
inline constexpr CanSignal kTrackRange{
    "CAN_TX_TRACK_RANGE", 18, 11, ByteOrder::kBigEndian, false, 0.1, 0};
inline constexpr CanSignal kTrackBridgeObject{
    "CAN_TX_TRACK_BRIDGE_OBJECT", 39, 1, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kTrackRollingCount{
    "CAN_TX_TRACK_ROLLING_COUNT", 38, 1, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kTrackWidth{
    "CAN_TX_TRACK_WIDTH", 37, 4, ByteOrder::kBigEndian, false, 0.5, 0};
inline constexpr CanSignal kTrackRangeAccel{
    "CAN_TX_TRACK_RANGE_ACCEL", 33, 10, ByteOrder::kBigEndian, true, 0.05, 0};
inline constexpr CanSignal kTrackMedRangeMode{
    "CAN_TX_TRACK_MED_RANGE_MODE", 55, 2, ByteOrder::kBigEndian, false, 1, 0};
inline constexpr CanSignal kTrackRangeRate{
    "CAN_TX_TRACK_RANGE_RATE", 53, 14, ByteOrder::kBigEndian, true, 0.01, 0};

// Every signal of the two message kinds, for the DBC cross-check and generic dumps.
inline constexpr CanSignal kStatusSignals[] = {
    kScanIndex,           kRollingCount1, kDspTimestamp,    kCommError,
    kRadiusCurvatureCalc, kYawRateCalc,   kVehicleSpeedCalc};
inline constexpr CanSignal kTrackSignals[] = {
    kTrackLatRate, kTrackGroupingChanged, kTrackOncoming,     kTrackStatus,
    kTrackAngle,   kTrackRange,           kTrackBridgeObject, kTrackRollingCount,
    kTrackWidth,   kTrackRangeAccel,      kTrackMedRangeMode, kTrackRangeRate};

// CAN_TX_TRACK_STATUS codes.
enum TrackStatus : int {
  kNoTarget = 0,
  kNewTarget = 1,
  kNewUpdatedTarget = 2,
  kUpdatedTarget = 3,
  kCoastedTarget = 4,
  kMergedTarget = 5,
  kInvalidCoastedTarget = 6,
  kNewCoastedTarget = 7,
};
}  // namespace esr

struct EsrStatus {
  uint32_t scan_index = 0;
  int rolling_count = 0;       // 0..3
  double dsp_timestamp_s = 0;  // 0..0.254 s, 2 ms steps
  bool comm_error = false;
  double radius_curvature_m = 0;
  double yaw_rate_radps = 0;
  double vehicle_speed_mps = 0;
};

// One track message, physical values with the ESR's own signs.
struct EsrTrack {
  int number = 1;  // 1..64: TargetN, id 0x500 + N − 1
  int status = esr::kNoTarget;
  double range_m = 0;
  double angle_rad = 0;  // sign: RadarConventions::esr_angle_clockwise_positive
  double range_rate_mps = 0;
  double range_accel_mps2 = 0;
  double width_m = 0;
  double lat_rate_mps = 0;
  int med_range_mode = 0;
  int rolling_count = 0;
  bool oncoming = false;
  bool grouping_changed = false;
  bool bridge_object = false;
};

// nullopt when the payload is shorter than 8 bytes.
std::optional<EsrStatus> DecodeEsrStatus(std::span<const uint8_t> payload);
// `number` from the frame id (the caller checks 0x500..0x53F). nullopt for a short payload.
std::optional<EsrTrack> DecodeEsrTrack(std::span<const uint8_t> payload, int number);

RadarDetection EsrTrackToDetection(const EsrTrack& track, const RadarConventions& conventions);
// Status kUpdatedTarget; the detection id is the track number (1..64).
EsrTrack EsrTrackFromDetection(const RadarDetection& detection,
                               const RadarConventions& conventions);

// 8-byte classic frames. InvalidArgument for a track number outside 1..64; OutOfRange naming
// the signal for an unrepresentable value (range > 204.7 m, |angle| > 51.2°, ...).
absl::StatusOr<CanFrame> EncodeEsrStatus(const EsrStatus& status);
absl::StatusOr<CanFrame> EncodeEsrTrack(const EsrTrack& track);

// A whole scan: the status frame (scan index = cycle.counter) then all 64 track frames, the
// slots without a detection with status kNoTarget. Detection ids must be distinct, 1..64.
// Frame times as EncodeArs408Cycle.
absl::StatusOr<std::vector<CanFrame>> EncodeEsrScan(const RadarCycle& cycle,
                                                    const std::string& interface,
                                                    const RadarConventions& conventions);

}  // namespace linecal

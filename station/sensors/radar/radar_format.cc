#include "station/sensors/radar/radar_format.h"

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

uint64_t LowMask(int bits) { return bits >= 64 ? ~uint64_t{0} : (uint64_t{1} << bits) - 1; }

int64_t MinRaw(const CanSignal& s) { return s.is_signed ? -(int64_t{1} << (s.length - 1)) : 0; }
int64_t MaxRaw(const CanSignal& s) {
  return s.is_signed ? (int64_t{1} << (s.length - 1)) - 1 : static_cast<int64_t>(LowMask(s.length));
}

// The shortest payload that holds all `signals`.
int MessageBytes(std::initializer_list<CanSignal> signals) {
  int bytes = 0;
  for (const CanSignal& s : signals) bytes = std::max(bytes, SignalBytesNeeded(s));
  return bytes;
}

int RoundToInt(std::optional<double> v) { return static_cast<int>(std::lround(*v)); }

CanFrame MakeFrame(uint32_t id, int len, const std::string& interface, CanTime time) {
  CanFrame frame;
  frame.id = id;
  frame.len = static_cast<uint8_t>(len);
  frame.interface = interface;
  frame.time = time;
  return frame;
}

std::span<uint8_t> Payload(CanFrame& frame) { return {frame.data.data(), frame.len}; }

// Inserts (signal, value) pairs, stopping at the first error.
absl::Status InsertAll(CanFrame& frame,
                       std::initializer_list<std::pair<const CanSignal&, double>> values) {
  for (const auto& [signal, value] : values) {
    if (absl::Status s = InsertPhysical(Payload(frame), signal, value); !s.ok()) return s;
  }
  return absl::OkStatus();
}

// The signals of a cluster (0x701) or object (0x60B) general message.
struct TargetSignals {
  const CanSignal& id;
  const CanSignal& dist_long;
  const CanSignal& dist_lat;
  const CanSignal& vrel_long;
  const CanSignal& vrel_lat;
  const CanSignal& dyn_prop;
  const CanSignal& rcs;
};
const TargetSignals kClusterSignals{ars408::kClusterIdSignal, ars408::kClusterDistLong,
                                    ars408::kClusterDistLat,  ars408::kClusterVrelLong,
                                    ars408::kClusterVrelLat,  ars408::kClusterDynProp,
                                    ars408::kClusterRcs};
const TargetSignals kObjectSignals{ars408::kObjectIdSignal, ars408::kObjectDistLong,
                                   ars408::kObjectDistLat,  ars408::kObjectVrelLong,
                                   ars408::kObjectVrelLat,  ars408::kObjectDynProp,
                                   ars408::kObjectRcs};
const TargetSignals& SignalsOf(RadarDetectionKind kind) {
  return kind == RadarDetectionKind::kObject ? kObjectSignals : kClusterSignals;
}

const CanSignal& CounterSignal(RadarDetectionKind kind, const RadarConventions& c) {
  const bool big = c.ars408_counter_byte_order == ByteOrder::kBigEndian;
  if (kind == RadarDetectionKind::kObject) {
    return big ? ars408::kObjectMeasCounter : ars408::kObjectMeasCounterLe;
  }
  return big ? ars408::kClusterMeasCounter : ars408::kClusterMeasCounterLe;
}

absl::Status CheckArs408Kind(RadarDetectionKind kind, int sensor_id) {
  if (kind == RadarDetectionKind::kTrack) {
    return absl::InvalidArgumentError("ARS408 lists hold clusters or objects, not tracks");
  }
  if (sensor_id < 0 || sensor_id > ars408::kMaxSensorId) {
    return absl::InvalidArgumentError(
        absl::StrCat("ARS408 sensor id ", sensor_id, " outside 0..", ars408::kMaxSensorId));
  }
  return absl::OkStatus();
}

uint32_t Ars408FrameId(uint32_t base, int sensor_id) {
  return base + ars408::kSensorIdStride * static_cast<uint32_t>(sensor_id);
}

double LateralSign(RadarDetectionKind kind, const RadarConventions& c) {
  return kind == RadarDetectionKind::kObject && !c.ars408_object_lat_left_positive ? -1.0 : 1.0;
}

double EsrAngleSign(const RadarConventions& c) {
  return c.esr_angle_clockwise_positive ? -1.0 : 1.0;
}

constexpr double kDegPerRad = 180.0 / std::numbers::pi;

// ARS408 DynProp code 4: "unknown" (a detection carries no dynamic property).
constexpr int kDynPropUnknown = 4;

}  // namespace

// ---------------------------------------------------------------------------------------
// Generic signals.

int SignalBytesNeeded(const CanSignal& s) {
  if (s.byte_order == ByteOrder::kLittleEndian) return (s.start_bit + s.length - 1) / 8 + 1;
  const int first_byte_bits = s.start_bit % 8 + 1;
  const int first_byte = s.start_bit / 8;
  if (s.length <= first_byte_bits) return first_byte + 1;
  return first_byte + 1 + (s.length - first_byte_bits + 7) / 8;
}

std::optional<int64_t> ExtractRaw(std::span<const uint8_t> payload, const CanSignal& s) {
  if (static_cast<int>(payload.size()) < SignalBytesNeeded(s)) return std::nullopt;
  uint64_t bits = 0;
  int pos = s.start_bit;
  if (s.byte_order == ByteOrder::kBigEndian) {
    // From the MSB down: the rest of the current byte, then on from the next byte's MSB.
    int remaining = s.length;
    while (remaining > 0) {
      const int available = pos % 8 + 1;
      const int n = std::min(remaining, available);
      const uint64_t chunk = (payload[pos / 8] >> (available - n)) & LowMask(n);
      bits = bits << n | chunk;
      remaining -= n;
      pos = (pos / 8 + 1) * 8 + 7;
    }
  } else {
    int got = 0;
    while (got < s.length) {
      const int n = std::min(s.length - got, 8 - pos % 8);
      const uint64_t chunk = (payload[pos / 8] >> (pos % 8)) & LowMask(n);
      bits |= chunk << got;
      got += n;
      pos = (pos / 8 + 1) * 8;
    }
  }
  if (s.is_signed && ((bits >> (s.length - 1)) & 1) != 0) {
    // Sign extension in unsigned arithmetic (bits - 2^length overflows int64 for 63-bit
    // signals); the conversion to int64 is two's complement (C++20).
    return static_cast<int64_t>(bits | ~LowMask(s.length));
  }
  return static_cast<int64_t>(bits);
}

std::optional<double> ExtractPhysical(std::span<const uint8_t> payload, const CanSignal& s) {
  const std::optional<int64_t> raw = ExtractRaw(payload, s);
  if (!raw) return std::nullopt;
  return static_cast<double>(*raw) * s.factor + s.offset;
}

absl::Status InsertRaw(std::span<uint8_t> payload, const CanSignal& s, int64_t raw) {
  if (raw < MinRaw(s) || raw > MaxRaw(s)) {
    return absl::OutOfRangeError(
        absl::StrCat(s.name, ": raw value ", raw, " outside ", MinRaw(s), "..", MaxRaw(s)));
  }
  if (static_cast<int>(payload.size()) < SignalBytesNeeded(s)) {
    return absl::OutOfRangeError(absl::StrCat(s.name, ": needs ", SignalBytesNeeded(s),
                                              " payload bytes, frame has ", payload.size()));
  }
  const uint64_t bits = static_cast<uint64_t>(raw) & LowMask(s.length);
  int pos = s.start_bit;
  if (s.byte_order == ByteOrder::kBigEndian) {
    int remaining = s.length;
    while (remaining > 0) {
      const int available = pos % 8 + 1;
      const int n = std::min(remaining, available);
      const int shift = available - n;
      const uint64_t chunk = (bits >> (remaining - n)) & LowMask(n);
      uint8_t& byte = payload[pos / 8];
      byte = static_cast<uint8_t>((byte & ~(LowMask(n) << shift)) | chunk << shift);
      remaining -= n;
      pos = (pos / 8 + 1) * 8 + 7;
    }
  } else {
    int done = 0;
    while (done < s.length) {
      const int n = std::min(s.length - done, 8 - pos % 8);
      const int shift = pos % 8;
      const uint64_t chunk = (bits >> done) & LowMask(n);
      uint8_t& byte = payload[pos / 8];
      byte = static_cast<uint8_t>((byte & ~(LowMask(n) << shift)) | chunk << shift);
      done += n;
      pos = (pos / 8 + 1) * 8;
    }
  }
  return absl::OkStatus();
}

absl::Status InsertPhysical(std::span<uint8_t> payload, const CanSignal& s, double value) {
  const double raw = std::round((value - s.offset) / s.factor);
  if (!std::isfinite(raw) || raw < static_cast<double>(MinRaw(s)) ||
      raw > static_cast<double>(MaxRaw(s))) {
    return absl::OutOfRangeError(
        absl::StrCat(s.name, ": value ", value, " outside ",
                     static_cast<double>(MinRaw(s)) * s.factor + s.offset, "..",
                     static_cast<double>(MaxRaw(s)) * s.factor + s.offset));
  }
  return InsertRaw(payload, s, static_cast<int64_t>(raw));
}

// ---------------------------------------------------------------------------------------
// Detections.

const char* RadarDetectionKindName(RadarDetectionKind kind) {
  switch (kind) {
    case RadarDetectionKind::kCluster:
      return "cluster";
    case RadarDetectionKind::kObject:
      return "object";
    case RadarDetectionKind::kTrack:
      return "track";
  }
  return "unknown";
}

double RadarDetection::x_m() const { return range_m * std::cos(azimuth_rad); }
double RadarDetection::y_m() const { return range_m * std::sin(azimuth_rad); }

// ---------------------------------------------------------------------------------------
// ARS408.

std::optional<Ars408Id> ClassifyArs408Id(uint32_t id) {
  const int sensor_id = static_cast<int>((id >> 4) & 0xF);
  if (sensor_id > ars408::kMaxSensorId) return std::nullopt;
  switch (id - ars408::kSensorIdStride * static_cast<uint32_t>(sensor_id)) {
    case ars408::kClusterStatusId:
      return Ars408Id{Ars408Message::kClusterStatus, sensor_id};
    case ars408::kClusterGeneralId:
      return Ars408Id{Ars408Message::kClusterGeneral, sensor_id};
    case ars408::kClusterQualityId:
      return Ars408Id{Ars408Message::kClusterQuality, sensor_id};
    case ars408::kObjectStatusId:
      return Ars408Id{Ars408Message::kObjectStatus, sensor_id};
    case ars408::kObjectGeneralId:
      return Ars408Id{Ars408Message::kObjectGeneral, sensor_id};
    default:
      return std::nullopt;
  }
}

std::optional<Ars408ListStatus> DecodeArs408ListStatus(std::span<const uint8_t> payload,
                                                       RadarDetectionKind kind,
                                                       const RadarConventions& conventions) {
  const bool objects = kind == RadarDetectionKind::kObject;
  const CanSignal& near = objects ? ars408::kNofObjects : ars408::kNofClustersNear;
  const CanSignal& version =
      objects ? ars408::kObjectInterfaceVersion : ars408::kClusterInterfaceVersion;
  const std::optional<int64_t> near_count = ExtractRaw(payload, near);
  const std::optional<int64_t> counter = ExtractRaw(payload, CounterSignal(kind, conventions));
  const std::optional<int64_t> interface_version = ExtractRaw(payload, version);
  std::optional<int64_t> far_count = 0;
  if (!objects) far_count = ExtractRaw(payload, ars408::kNofClustersFar);
  if (!near_count || !counter || !interface_version || !far_count) return std::nullopt;
  return Ars408ListStatus{static_cast<int>(*near_count), static_cast<int>(*far_count),
                          static_cast<uint32_t>(*counter), static_cast<int>(*interface_version)};
}

std::optional<Ars408Target> DecodeArs408Target(std::span<const uint8_t> payload,
                                               RadarDetectionKind kind) {
  const TargetSignals& s = SignalsOf(kind);
  // Every signal of the message lies in its 8 bytes; one length check covers them all.
  if (static_cast<int>(payload.size()) < SignalBytesNeeded(s.rcs)) return std::nullopt;
  Ars408Target t;
  t.id = RoundToInt(ExtractPhysical(payload, s.id));
  t.dist_long_m = *ExtractPhysical(payload, s.dist_long);
  t.dist_lat_m = *ExtractPhysical(payload, s.dist_lat);
  t.vrel_long_mps = *ExtractPhysical(payload, s.vrel_long);
  t.vrel_lat_mps = *ExtractPhysical(payload, s.vrel_lat);
  t.dyn_prop = RoundToInt(ExtractPhysical(payload, s.dyn_prop));
  t.rcs_dbsm = *ExtractPhysical(payload, s.rcs);
  return t;
}

std::optional<std::pair<int, Ars408ClusterQuality>> DecodeArs408ClusterQuality(
    std::span<const uint8_t> payload) {
  if (static_cast<int>(payload.size()) < SignalBytesNeeded(ars408::kClusterInvalidState)) {
    return std::nullopt;
  }
  Ars408ClusterQuality q;
  q.dist_long_rms = RoundToInt(ExtractPhysical(payload, ars408::kClusterDistLongRms));
  q.dist_lat_rms = RoundToInt(ExtractPhysical(payload, ars408::kClusterDistLatRms));
  q.pdh0 = RoundToInt(ExtractPhysical(payload, ars408::kClusterPdh0));
  q.ambig_state = RoundToInt(ExtractPhysical(payload, ars408::kClusterAmbigState));
  q.invalid_state = RoundToInt(ExtractPhysical(payload, ars408::kClusterInvalidState));
  return std::pair{RoundToInt(ExtractPhysical(payload, ars408::kQualityClusterId)), q};
}

RadarDetection Ars408TargetToDetection(const Ars408Target& t, RadarDetectionKind kind,
                                       const RadarConventions& conventions) {
  const double sign = LateralSign(kind, conventions);
  const double x = t.dist_long_m;
  const double y = sign * t.dist_lat_m;
  const double vx = t.vrel_long_mps;
  const double vy = sign * t.vrel_lat_mps;
  RadarDetection d;
  d.id = t.id;
  d.kind = kind;
  d.range_m = std::hypot(x, y);
  d.azimuth_rad = std::atan2(y, x);
  // Line-of-sight component of the relative velocity; at the origin the direction is
  // undefined and the longitudinal velocity is the best stand-in.
  d.range_rate_mps = d.range_m > 0 ? (vx * x + vy * y) / d.range_m : vx;
  d.rcs_dbsm = t.rcs_dbsm;
  return d;
}

Ars408Target Ars408TargetFromDetection(const RadarDetection& d,
                                       const RadarConventions& conventions) {
  const double sign = LateralSign(d.kind, conventions);
  Ars408Target t;
  t.id = d.id;
  t.dist_long_m = d.x_m();
  t.dist_lat_m = sign * d.y_m();
  t.vrel_long_mps = d.range_rate_mps * std::cos(d.azimuth_rad);
  t.vrel_lat_mps = sign * d.range_rate_mps * std::sin(d.azimuth_rad);
  t.dyn_prop = kDynPropUnknown;
  t.rcs_dbsm = d.rcs_dbsm.value_or(0);
  return t;
}

absl::StatusOr<CanFrame> EncodeArs408ListStatus(const Ars408ListStatus& status,
                                                RadarDetectionKind kind, int sensor_id,
                                                const RadarConventions& conventions) {
  if (absl::Status s = CheckArs408Kind(kind, sensor_id); !s.ok()) return s;
  const CanSignal& counter = CounterSignal(kind, conventions);
  absl::Status s;
  CanFrame frame;
  if (kind == RadarDetectionKind::kObject) {
    if (status.far_count != 0) {
      return absl::InvalidArgumentError("the ARS408 object list has no far count");
    }
    frame = MakeFrame(Ars408FrameId(ars408::kObjectStatusId, sensor_id),
                      MessageBytes({ars408::kNofObjects, ars408::kObjectMeasCounter,
                                    ars408::kObjectInterfaceVersion}),
                      "", {});
    s = InsertAll(frame, {{ars408::kNofObjects, status.near_count},
                          {counter, status.meas_counter},
                          {ars408::kObjectInterfaceVersion, status.interface_version}});
  } else {
    frame = MakeFrame(Ars408FrameId(ars408::kClusterStatusId, sensor_id),
                      MessageBytes({ars408::kNofClustersNear, ars408::kNofClustersFar,
                                    ars408::kClusterMeasCounter, ars408::kClusterInterfaceVersion}),
                      "", {});
    s = InsertAll(frame, {{ars408::kNofClustersNear, status.near_count},
                          {ars408::kNofClustersFar, status.far_count},
                          {counter, status.meas_counter},
                          {ars408::kClusterInterfaceVersion, status.interface_version}});
  }
  if (!s.ok()) return s;
  return frame;
}

absl::StatusOr<CanFrame> EncodeArs408Target(const Ars408Target& t, RadarDetectionKind kind,
                                            int sensor_id) {
  if (absl::Status s = CheckArs408Kind(kind, sensor_id); !s.ok()) return s;
  const TargetSignals& sig = SignalsOf(kind);
  const uint32_t base =
      kind == RadarDetectionKind::kObject ? ars408::kObjectGeneralId : ars408::kClusterGeneralId;
  CanFrame frame = MakeFrame(Ars408FrameId(base, sensor_id), SignalBytesNeeded(sig.rcs), "", {});
  if (absl::Status s = InsertAll(frame, {{sig.id, t.id},
                                         {sig.dist_long, t.dist_long_m},
                                         {sig.dist_lat, t.dist_lat_m},
                                         {sig.vrel_long, t.vrel_long_mps},
                                         {sig.vrel_lat, t.vrel_lat_mps},
                                         {sig.dyn_prop, t.dyn_prop},
                                         {sig.rcs, t.rcs_dbsm}});
      !s.ok()) {
    return s;
  }
  return frame;
}

absl::StatusOr<CanFrame> EncodeArs408ClusterQuality(int cluster_id, const Ars408ClusterQuality& q,
                                                    int sensor_id) {
  if (absl::Status s = CheckArs408Kind(RadarDetectionKind::kCluster, sensor_id); !s.ok()) {
    return s;
  }
  CanFrame frame = MakeFrame(Ars408FrameId(ars408::kClusterQualityId, sensor_id),
                             SignalBytesNeeded(ars408::kClusterInvalidState), "", {});
  if (absl::Status s = InsertAll(frame, {{ars408::kQualityClusterId, cluster_id},
                                         {ars408::kClusterDistLongRms, q.dist_long_rms},
                                         {ars408::kClusterDistLatRms, q.dist_lat_rms},
                                         {ars408::kClusterPdh0, q.pdh0},
                                         {ars408::kClusterAmbigState, q.ambig_state},
                                         {ars408::kClusterInvalidState, q.invalid_state}});
      !s.ok()) {
    return s;
  }
  return frame;
}

absl::StatusOr<std::vector<CanFrame>> EncodeArs408Cycle(const RadarCycle& cycle,
                                                        const std::string& interface,
                                                        const RadarConventions& conventions) {
  std::vector<CanFrame> frames;
  Ars408ListStatus status;
  status.near_count = static_cast<int>(cycle.detections.size());
  status.meas_counter = cycle.counter;
  absl::StatusOr<CanFrame> head =
      EncodeArs408ListStatus(status, cycle.kind, cycle.sensor_id, conventions);
  if (!head.ok()) return head.status();
  frames.push_back(*std::move(head));
  for (size_t i = 0; i < cycle.detections.size(); ++i) {
    const RadarDetection& d = cycle.detections[i];
    if (d.kind != cycle.kind) {
      return absl::InvalidArgumentError(absl::StrCat("detection ", i, " is a ",
                                                     RadarDetectionKindName(d.kind), " in a ",
                                                     RadarDetectionKindName(cycle.kind), " list"));
    }
    if (!d.rcs_dbsm) {
      return absl::InvalidArgumentError(
          absl::StrCat("detection ", i, " has no rcs_dbsm (ARS408 frames always carry one)"));
    }
    absl::StatusOr<CanFrame> frame =
        EncodeArs408Target(Ars408TargetFromDetection(d, conventions), cycle.kind, cycle.sensor_id);
    if (!frame.ok()) {
      return absl::OutOfRangeError(absl::StrCat("detection ", i, ": ", frame.status().message()));
    }
    frames.push_back(*std::move(frame));
  }
  for (size_t i = 0; i < cycle.detections.size(); ++i) {
    const RadarDetection& d = cycle.detections[i];
    if (!d.cluster_quality) continue;
    absl::StatusOr<CanFrame> frame =
        EncodeArs408ClusterQuality(d.id, *d.cluster_quality, cycle.sensor_id);
    if (!frame.ok()) {
      return absl::OutOfRangeError(absl::StrCat("detection ", i, ": ", frame.status().message()));
    }
    frames.push_back(*std::move(frame));
  }
  for (size_t i = 0; i < frames.size(); ++i) {
    frames[i].interface = interface;
    frames[i].time = cycle.time + kRadarFrameSpacing * static_cast<int64_t>(i);
  }
  return frames;
}

// ---------------------------------------------------------------------------------------
// ESR.

std::optional<EsrStatus> DecodeEsrStatus(std::span<const uint8_t> payload) {
  // The status signals span all 8 bytes (the vehicle speed ends in byte 7).
  if (static_cast<int>(payload.size()) < SignalBytesNeeded(esr::kVehicleSpeedCalc)) {
    return std::nullopt;
  }
  EsrStatus s;
  s.scan_index = static_cast<uint32_t>(*ExtractRaw(payload, esr::kScanIndex));
  s.rolling_count = RoundToInt(ExtractPhysical(payload, esr::kRollingCount1));
  constexpr double kSecondsPerMs = 1e-3;
  s.dsp_timestamp_s = *ExtractPhysical(payload, esr::kDspTimestamp) * kSecondsPerMs;
  s.comm_error = *ExtractRaw(payload, esr::kCommError) != 0;
  s.radius_curvature_m = *ExtractPhysical(payload, esr::kRadiusCurvatureCalc);
  s.yaw_rate_radps = *ExtractPhysical(payload, esr::kYawRateCalc) / kDegPerRad;
  s.vehicle_speed_mps = *ExtractPhysical(payload, esr::kVehicleSpeedCalc);
  return s;
}

std::optional<EsrTrack> DecodeEsrTrack(std::span<const uint8_t> payload, int number) {
  // Every track signal lies in the 8 bytes; the range accel/rate end in byte 7.
  constexpr int kTrackBytes = 8;
  if (static_cast<int>(payload.size()) < kTrackBytes) return std::nullopt;
  EsrTrack t;
  t.number = number;
  t.status = RoundToInt(ExtractPhysical(payload, esr::kTrackStatus));
  t.range_m = *ExtractPhysical(payload, esr::kTrackRange);
  t.angle_rad = *ExtractPhysical(payload, esr::kTrackAngle) / kDegPerRad;
  t.range_rate_mps = *ExtractPhysical(payload, esr::kTrackRangeRate);
  t.range_accel_mps2 = *ExtractPhysical(payload, esr::kTrackRangeAccel);
  t.width_m = *ExtractPhysical(payload, esr::kTrackWidth);
  t.lat_rate_mps = *ExtractPhysical(payload, esr::kTrackLatRate);
  t.med_range_mode = RoundToInt(ExtractPhysical(payload, esr::kTrackMedRangeMode));
  t.rolling_count = RoundToInt(ExtractPhysical(payload, esr::kTrackRollingCount));
  t.oncoming = *ExtractRaw(payload, esr::kTrackOncoming) != 0;
  t.grouping_changed = *ExtractRaw(payload, esr::kTrackGroupingChanged) != 0;
  t.bridge_object = *ExtractRaw(payload, esr::kTrackBridgeObject) != 0;
  return t;
}

RadarDetection EsrTrackToDetection(const EsrTrack& t, const RadarConventions& conventions) {
  RadarDetection d;
  d.id = t.number;
  d.kind = RadarDetectionKind::kTrack;
  d.range_m = t.range_m;
  d.azimuth_rad = EsrAngleSign(conventions) * t.angle_rad;
  d.range_rate_mps = t.range_rate_mps;
  return d;
}

EsrTrack EsrTrackFromDetection(const RadarDetection& d, const RadarConventions& conventions) {
  EsrTrack t;
  t.number = d.id;
  t.status = esr::kUpdatedTarget;
  t.range_m = d.range_m;
  t.angle_rad = EsrAngleSign(conventions) * d.azimuth_rad;
  t.range_rate_mps = d.range_rate_mps;
  return t;
}

absl::StatusOr<CanFrame> EncodeEsrStatus(const EsrStatus& s) {
  CanFrame frame = MakeFrame(esr::kStatusId, kCanMaxDataBytes, "", {});
  constexpr double kMsPerSecond = 1e3;
  if (absl::Status st = InsertAll(frame, {{esr::kScanIndex, s.scan_index},
                                          {esr::kRollingCount1, s.rolling_count},
                                          {esr::kDspTimestamp, s.dsp_timestamp_s * kMsPerSecond},
                                          {esr::kCommError, s.comm_error ? 1 : 0},
                                          {esr::kRadiusCurvatureCalc, s.radius_curvature_m},
                                          {esr::kYawRateCalc, s.yaw_rate_radps * kDegPerRad},
                                          {esr::kVehicleSpeedCalc, s.vehicle_speed_mps}});
      !st.ok()) {
    return st;
  }
  return frame;
}

absl::StatusOr<CanFrame> EncodeEsrTrack(const EsrTrack& t) {
  if (t.number < 1 || t.number > esr::kTrackCount) {
    return absl::InvalidArgumentError(
        absl::StrCat("ESR track number ", t.number, " outside 1..", esr::kTrackCount));
  }
  CanFrame frame =
      MakeFrame(esr::kFirstTrackId + static_cast<uint32_t>(t.number - 1), kCanMaxDataBytes, "", {});
  if (absl::Status s = InsertAll(frame, {{esr::kTrackStatus, t.status},
                                         {esr::kTrackRange, t.range_m},
                                         {esr::kTrackAngle, t.angle_rad * kDegPerRad},
                                         {esr::kTrackRangeRate, t.range_rate_mps},
                                         {esr::kTrackRangeAccel, t.range_accel_mps2},
                                         {esr::kTrackWidth, t.width_m},
                                         {esr::kTrackLatRate, t.lat_rate_mps},
                                         {esr::kTrackMedRangeMode, t.med_range_mode},
                                         {esr::kTrackRollingCount, t.rolling_count},
                                         {esr::kTrackOncoming, t.oncoming ? 1 : 0},
                                         {esr::kTrackGroupingChanged, t.grouping_changed ? 1 : 0},
                                         {esr::kTrackBridgeObject, t.bridge_object ? 1 : 0}});
      !s.ok()) {
    return s;
  }
  return frame;
}

absl::StatusOr<std::vector<CanFrame>> EncodeEsrScan(const RadarCycle& cycle,
                                                    const std::string& interface,
                                                    const RadarConventions& conventions) {
  if (cycle.kind != RadarDetectionKind::kTrack) {
    return absl::InvalidArgumentError("an ESR scan holds tracks");
  }
  std::vector<EsrTrack> slots(esr::kTrackCount);
  for (int n = 1; n <= esr::kTrackCount; ++n) slots[n - 1].number = n;
  for (size_t i = 0; i < cycle.detections.size(); ++i) {
    const RadarDetection& d = cycle.detections[i];
    if (d.kind != RadarDetectionKind::kTrack || d.id < 1 || d.id > esr::kTrackCount) {
      return absl::InvalidArgumentError(
          absl::StrCat("detection ", i, ": an ESR track with id 1..64 expected, got a ",
                       RadarDetectionKindName(d.kind), " with id ", d.id));
    }
    if (slots[d.id - 1].status != esr::kNoTarget) {
      return absl::InvalidArgumentError(
          absl::StrCat("detection ", i, ": track id ", d.id, " twice"));
    }
    slots[d.id - 1] = EsrTrackFromDetection(d, conventions);
  }
  std::vector<CanFrame> frames;
  EsrStatus status;
  status.scan_index = cycle.counter;
  absl::StatusOr<CanFrame> head = EncodeEsrStatus(status);
  if (!head.ok()) return head.status();
  frames.push_back(*std::move(head));
  for (const EsrTrack& t : slots) {
    absl::StatusOr<CanFrame> frame = EncodeEsrTrack(t);
    if (!frame.ok()) {
      return absl::OutOfRangeError(
          absl::StrCat("track ", t.number, ": ", frame.status().message()));
    }
    frames.push_back(*std::move(frame));
  }
  for (size_t i = 0; i < frames.size(); ++i) {
    frames[i].interface = interface;
    frames[i].time = cycle.time + kRadarFrameSpacing * static_cast<int64_t>(i);
  }
  return frames;
}

}  // namespace linecal

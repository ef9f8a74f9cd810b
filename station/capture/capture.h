#pragma once
// Captures: a directory holding everything needed to recompute one calibration cycle
// offline (docs/capture-format.md is the specification, with a version history).
//
//   DIR/manifest.json      format name and version, VIN, car model, time, aligner, sensors
//   DIR/station.json       the station layout used (linecal.station)
//   DIR/car.json           the car model used (linecal.car), plus any angle files it names
//   DIR/<sensor>/...       raw data per sensor: PNG frames, PCD scans, pcap packets, candump log
//   DIR/ground_truth.json  simulated captures only; never read by calibration code
//
// Paths inside the manifest are relative to DIR and may not leave it.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "station/model/aligner.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"

namespace linecal {

inline constexpr char kCaptureFormat[] = "linecal.capture";
// The version this build writes; ReadCapture reads every version up to it.
inline constexpr int kCaptureVersion = 1;
inline constexpr char kCaptureManifestFile[] = "manifest.json";
inline constexpr char kCaptureStationFile[] = "station.json";
inline constexpr char kCaptureCarFile[] = "car.json";
inline constexpr char kCaptureGroundTruthFile[] = "ground_truth.json";

// One recorded file and when its data was taken (ns since the Unix epoch; for a pcap or
// a CAN log, the time recording started).
struct CaptureFile {
  std::string path;  // relative to the capture directory
  std::int64_t t_ns = 0;
};

struct CaptureSensor {
  std::string name;  // a sensor of the car model
  SensorKind kind = SensorKind::kCamera;
  std::vector<CaptureFile> frames;     // cameras: PNG images; LiDARs: PCD scans
  std::optional<CaptureFile> packets;  // LiDARs: the raw UDP packets as pcap
  std::optional<CaptureFile> can_log;  // radars: the CAN traffic as a candump -l log
};

struct CaptureManifest {
  int version = kCaptureVersion;
  std::string vin;
  std::string car_model;  // the car model id (must equal car.json's id)
  std::int64_t time_ns = 0;
  std::string origin;  // "station" (recorded by linecald) or "simulator"
  AlignerMeasurement aligner;
  std::vector<CaptureSensor> sensors;

  const CaptureSensor* FindSensor(const std::string& name) const;
};

struct Capture {
  std::string dir;
  CaptureManifest manifest;
  StationLayout station;
  CarModel car;

  // The absolute (well, DIR-joined) path of a file of the manifest.
  std::string PathOf(const CaptureFile& f) const;
};

// Reads and validates a capture: the manifest's fields and types, the VIN (ISO 3779, without
// the check digit), the station and car files, every sensor against the car model (exists,
// same kind, the data its kind needs), every file (inside DIR, exists, non-empty), frame times
// non-decreasing, and every sensor target in the station layout. Errors are InvalidArgument
// (NotFound for a missing directory or manifest) whose message names the offending path and
// field: "cap/manifest.json: sensors[1].frames[0].path: no such file 'front/f0.png'".
absl::StatusOr<Capture> ReadCapture(const std::string& dir);

// Writes manifest.json, station.json and car.json into `dir` (which must exist), each
// atomically. LiDAR angle files named by the car model are copied into DIR and the written
// car.json refers to the copies. The raw data files must already be in place.
absl::Status WriteCapture(const std::string& dir, const CaptureManifest& manifest,
                          const StationLayout& station, const CarModel& car);

nlohmann::json CaptureManifestToJson(const CaptureManifest& manifest);

}  // namespace linecal

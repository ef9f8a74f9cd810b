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
// Paths inside the manifest are relative to DIR and may not leave it, neither by name ("..",
// absolute) nor through a symbolic link (every component is resolved).

#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "station/io/candump.h"
#include "station/io/image_io.h"
#include "station/io/input_budget.h"
#include "station/model/aligner.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/sensors/lidar/pcd.h"

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
  // The budget ReadCapture checked the manifest against; the ReadCapture* data readers below
  // apply it to every file, so that checking and calibrating a capture refuse the same files.
  InputBudget budget;

  // The absolute (well, DIR-joined) path of a file of the manifest.
  std::string PathOf(const CaptureFile& f) const;
};

// Reads and validates a capture: the manifest's fields and types, the VIN (ISO 3779, without
// the check digit), the station and car files, every sensor against the car model (exists,
// same kind, the data its kind needs), every file (inside DIR after resolving symbolic links,
// exists, non-empty, at most budget.max_file_bytes), at most budget.max_manifest_frames frame
// entries, frame times non-decreasing, and every sensor target in the station layout. The
// manifest, station.json, car.json and the LiDAR angle files must resolve inside DIR too.
// Errors are InvalidArgument (NotFound for a missing directory or manifest) whose message
// names the offending path and field:
//   "cap/manifest.json: sensors[1].frames[0].path: no such file 'front/f0.png'".
// The data files' contents are not read here (CheckCaptureData reads them).
absl::StatusOr<Capture> ReadCapture(const std::string& dir, const InputBudget& budget = {});

// The containment rule of captures (and of the daemon's data root): `rel`, joined to `root`
// and with every symbolic link of every component resolved (std::filesystem::weakly_canonical),
// must be `root` itself or below it, compared component by component (so /data/cap2 is not
// inside /data/cap). Returns the resolved path; InvalidArgument "<display>: resolves outside
// <what>" (the target is not named) or when `root` cannot be resolved. Cost: a few stat calls
// per component.
absl::StatusOr<std::filesystem::path> ResolveInside(const std::filesystem::path& root,
                                                    const std::filesystem::path& rel,
                                                    const std::string& display,
                                                    const std::string& what);

// The data readers of a capture: the file `f` of `capture`, read under capture.budget
// (station/io/input_budget.h). Calibration and `linecal capture check` use these, so that
// they accept and refuse the same files. Errors as ReadImage8, ReadPcd and ReadCandumpLog
// under a budget, naming the file.
absl::StatusOr<Image8> ReadCaptureImage(const Capture& capture, const CaptureFile& f);
absl::StatusOr<PcdCloud> ReadCaptureScan(const Capture& capture, const CaptureFile& f);
absl::StatusOr<std::vector<CanFrame>> ReadCaptureCanLog(const Capture& capture,
                                                        const CaptureFile& f);

// Reads every data file of the capture as calibration would, with the same readers: every
// camera frame decoded (its size must match the car model's intrinsics), every LiDAR scan
// read, every radar CAN log parsed (pcap packets are not read by calibration, so only their
// size is checked, by ReadCapture). InvalidArgument "<dir>/manifest.json: sensors[i].frames[k]:
// <the reader's error>" for the first bad file. Cost: decoding every file once, one at a time.
absl::Status CheckCaptureData(const Capture& capture);

// Writes manifest.json, station.json and car.json into `dir` (which must exist), each
// atomically. LiDAR angle files named by the car model are copied into DIR and the written
// car.json refers to the copies. The raw data files must already be in place.
absl::Status WriteCapture(const std::string& dir, const CaptureManifest& manifest,
                          const StationLayout& station, const CarModel& car);

nlohmann::json CaptureManifestToJson(const CaptureManifest& manifest);

}  // namespace linecal

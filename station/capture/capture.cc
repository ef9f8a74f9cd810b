#include "station/capture/capture.h"

#include <filesystem>
#include <set>

#include "absl/strings/str_cat.h"
#include "station/io/json_reader.h"
#include "station/model/vin.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

// A manifest path must stay inside the capture: relative, no "..", no empty components.
bool IsContainedRelativePath(const std::string& p) {
  if (p.empty() || p.front() == '/') return false;
  for (const fs::path& part : fs::path(p)) {
    if (part == ".." || part.empty()) return false;
  }
  return true;
}

// What the entries of a manifest are checked against: the capture directory with its symbolic
// links resolved, the budget, and the frame entries counted so far.
struct EntryContext {
  fs::path dir;           // as given, for opening files
  fs::path resolved_dir;  // fs::canonical(dir), for the containment check
  const InputBudget* budget = nullptr;
  std::int64_t frames = 0;
};

absl::StatusOr<CaptureFile> ReadFileEntry(const JsonField& f, const EntryContext& ctx) {
  if (auto s = f.AllowOnlyKeys({"path", "t_ns"}); !s.ok()) return s;
  absl::StatusOr<std::string> path = f.String("path");
  if (!path.ok()) return path.status();
  if (!IsContainedRelativePath(*path)) {
    return f.Error("path",
                   absl::StrCat("'", *path, "' must be a relative path inside the capture"));
  }
  if (absl::StatusOr<fs::path> r =
          ResolveInside(ctx.resolved_dir, *path, absl::StrCat("'", *path, "'"), "the capture");
      !r.ok()) {
    return f.Error("path", std::string(r.status().message()));
  }
  std::error_code ec;
  const fs::path full = ctx.dir / *path;
  if (!fs::is_regular_file(full, ec))
    return f.Error("path", absl::StrCat("no such file '", *path, "'"));
  const std::uintmax_t size = fs::file_size(full, ec);
  if (size == 0) return f.Error("path", absl::StrCat("file '", *path, "' is empty"));
  if (size > static_cast<std::uintmax_t>(ctx.budget->max_file_bytes)) {
    return f.Error("path",
                   absl::StrCat("'", *path, "': ",
                                OverBudgetText(static_cast<std::int64_t>(size), "bytes",
                                               ctx.budget->max_file_bytes, "max_file_bytes")));
  }
  absl::StatusOr<std::int64_t> t = f.Integer("t_ns");
  if (!t.ok()) return t.status();
  if (*t < 0) return f.Error("t_ns", "must be >= 0");
  return CaptureFile{*path, *t};
}

absl::StatusOr<CaptureSensor> ReadSensorEntry(const JsonField& f, EntryContext& ctx,
                                              const CarModel& car) {
  if (auto s = f.AllowOnlyKeys({"name", "kind", "frames", "packets", "can_log"}); !s.ok()) return s;
  CaptureSensor c;
  absl::StatusOr<std::string> name = f.String("name");
  if (!name.ok()) return name.status();
  c.name = *name;
  const SensorModel* model = car.FindSensor(c.name);
  if (model == nullptr) {
    return f.Error("name", absl::StrCat("car model '", car.id, "' has no sensor '", c.name, "'"));
  }
  absl::StatusOr<std::string> kind = f.String("kind");
  if (!kind.ok()) return kind.status();
  if (*kind != SensorKindName(model->kind)) {
    return f.Error("kind", absl::StrCat("'", *kind, "' but the car model says '", c.name, "' is a ",
                                        SensorKindName(model->kind)));
  }
  c.kind = model->kind;
  if (f.Has("frames")) {
    absl::StatusOr<std::vector<JsonField>> frames = f.Array("frames");
    if (!frames.ok()) return frames.status();
    // Counted before any entry is looked at: a manifest of thousands of frames is refused at once.
    ctx.frames += static_cast<std::int64_t>(frames->size());
    if (ctx.frames > ctx.budget->max_manifest_frames) {
      return f.Error("frames", OverBudgetText(ctx.frames, "frames", ctx.budget->max_manifest_frames,
                                              "max_manifest_frames"));
    }
    for (const JsonField& fr : *frames) {
      absl::StatusOr<CaptureFile> file = ReadFileEntry(fr, ctx);
      if (!file.ok()) return file.status();
      if (!c.frames.empty() && file->t_ns < c.frames.back().t_ns) {
        return fr.Error("t_ns", "frame times must not decrease");
      }
      c.frames.push_back(*file);
    }
  }
  for (const auto& [key, slot] :
       {std::pair{"packets", &c.packets}, std::pair{"can_log", &c.can_log}}) {
    if (!f.Has(key)) continue;
    absl::StatusOr<JsonField> entry = f.Object(key);
    if (!entry.ok()) return entry.status();
    absl::StatusOr<CaptureFile> file = ReadFileEntry(*entry, ctx);
    if (!file.ok()) return file.status();
    *slot = *file;
  }
  switch (c.kind) {
    case SensorKind::kCamera:
      if (c.frames.empty()) return f.Error("frames", "a camera needs at least one frame");
      if (c.packets || c.can_log) return f.Error("a camera has frames only");
      break;
    case SensorKind::kLidar:
      if (c.frames.empty() && !c.packets) return f.Error("a LiDAR needs scans (frames) or packets");
      if (c.can_log) return f.Error("can_log", "a LiDAR has no CAN log");
      break;
    case SensorKind::kRadar:
      if (!c.can_log) return f.Error("can_log", "missing (a radar needs its CAN log)");
      if (!c.frames.empty() || c.packets) return f.Error("a radar has a CAN log only");
      break;
  }
  return c;
}

// The capture's own files (manifest, station.json, car.json) must resolve inside it as well.
absl::Status CheckOwnFile(const fs::path& resolved_dir, const fs::path& dir, const char* name) {
  const absl::StatusOr<fs::path> r =
      ResolveInside(resolved_dir, name, (dir / name).string(), "the capture");
  return r.status();
}

// The LiDAR angle files car.json names (ReadCarModel made them absolute) must be in the capture.
absl::Status CheckAngleFiles(const fs::path& resolved_dir, const fs::path& dir,
                             const CarModel& car) {
  for (const SensorModel& s : car.sensors) {
    if (s.angles_file.empty()) continue;
    const absl::StatusOr<fs::path> r = ResolveInside(
        resolved_dir, s.angles_file,
        absl::StrCat((dir / kCaptureCarFile).string(), ": sensor '", s.name, "': angles_file"),
        "the capture");
    if (!r.ok()) return r.status();
  }
  return absl::OkStatus();
}

// One data file of a check: the reader's error under "<dir>/manifest.json: sensors[i].<key>".
absl::Status Located(const Capture& c, size_t sensor, const std::string& key,
                     const absl::Status& s) {
  if (s.ok()) return s;
  return absl::InvalidArgumentError(absl::StrCat(c.dir, "/", kCaptureManifestFile, ": sensors[",
                                                 sensor, "].", key, ": ", s.message()));
}

}  // namespace

absl::StatusOr<fs::path> ResolveInside(const fs::path& root, const fs::path& rel,
                                       const std::string& display, const std::string& what) {
  std::error_code ec;
  const fs::path resolved_root = fs::canonical(root, ec);
  if (ec) {
    return absl::InvalidArgumentError(
        absl::StrCat(root.string(), ": cannot resolve: ", ec.message()));
  }
  // Joining an absolute `rel` gives `rel` itself, which the check below then judges.
  const fs::path resolved = fs::weakly_canonical(resolved_root / rel, ec);
  if (ec) {
    return absl::InvalidArgumentError(absl::StrCat(display, ": cannot resolve: ", ec.message()));
  }
  auto r = resolved_root.begin();
  auto p = resolved.begin();
  for (; r != resolved_root.end(); ++r, ++p) {
    if (p == resolved.end() || *p != *r) {
      return absl::InvalidArgumentError(absl::StrCat(display, ": resolves outside ", what));
    }
  }
  return resolved;
}

absl::StatusOr<Image8> ReadCaptureImage(const Capture& capture, const CaptureFile& f) {
  return ReadImage8(capture.PathOf(f), capture.budget);
}

absl::StatusOr<PcdCloud> ReadCaptureScan(const Capture& capture, const CaptureFile& f) {
  return ReadPcd(capture.PathOf(f), capture.budget);
}

absl::StatusOr<std::vector<CanFrame>> ReadCaptureCanLog(const Capture& capture,
                                                        const CaptureFile& f) {
  return ReadCandumpLog(capture.PathOf(f), capture.budget);
}

absl::Status CheckCaptureData(const Capture& c) {
  for (size_t i = 0; i < c.manifest.sensors.size(); ++i) {
    const CaptureSensor& s = c.manifest.sensors[i];
    const SensorModel* model = c.car.FindSensor(s.name);
    for (size_t k = 0; k < s.frames.size(); ++k) {
      const std::string key = absl::StrCat("frames[", k, "]");
      if (s.kind == SensorKind::kLidar) {
        const absl::Status e = Located(c, i, key, ReadCaptureScan(c, s.frames[k]).status());
        if (!e.ok()) return e;
        continue;
      }
      absl::StatusOr<Image8> img = ReadCaptureImage(c, s.frames[k]);
      if (!img.ok()) return Located(c, i, key, img.status());
      if (model == nullptr || !model->intrinsics) continue;
      const CameraIntrinsics& in = *model->intrinsics;
      if (img->width != in.width || img->height != in.height) {
        return Located(c, i, key,
                       absl::InvalidArgumentError(absl::StrCat("image is ", img->width, "x",
                                                               img->height, ", the car model says ",
                                                               in.width, "x", in.height)));
      }
    }
    if (s.can_log) {
      const absl::Status e = Located(c, i, "can_log", ReadCaptureCanLog(c, *s.can_log).status());
      if (!e.ok()) return e;
    }
  }
  return absl::OkStatus();
}

const CaptureSensor* CaptureManifest::FindSensor(const std::string& name) const {
  for (const CaptureSensor& s : sensors) {
    if (s.name == name) return &s;
  }
  return nullptr;
}

std::string Capture::PathOf(const CaptureFile& f) const {
  return (fs::path(dir) / f.path).string();
}

absl::StatusOr<Capture> ReadCapture(const std::string& dir, const InputBudget& budget) {
  if (absl::Status s = budget.Validate(); !s.ok()) return s;
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    return absl::NotFoundError(absl::StrCat(dir, ": not a capture directory"));
  const fs::path root_dir(dir);
  const fs::path resolved_dir = fs::canonical(root_dir, ec);
  if (ec) return absl::NotFoundError(absl::StrCat(dir, ": cannot resolve: ", ec.message()));
  for (const char* own : {kCaptureManifestFile, kCaptureStationFile, kCaptureCarFile}) {
    if (absl::Status s = CheckOwnFile(resolved_dir, root_dir, own); !s.ok()) return s;
  }
  const std::string manifest_path = (root_dir / kCaptureManifestFile).string();
  absl::StatusOr<JsonDocument> doc = JsonDocument::FromFile(manifest_path);
  if (!doc.ok()) return doc.status();
  absl::StatusOr<JsonField> root = doc->Root();
  if (!root.ok()) return root.status();
  absl::StatusOr<std::string> format = root->String("format");
  if (!format.ok()) return format.status();
  if (*format != kCaptureFormat) {
    return root->Error("format",
                       absl::StrCat("expected '", kCaptureFormat, "', got '", *format, "'"));
  }
  absl::StatusOr<std::int64_t> version = root->Integer("version");
  if (!version.ok()) return version.status();
  if (*version < 1 || *version > kCaptureVersion) {
    return root->Error("version", absl::StrCat("unsupported version ", *version,
                                               " (this build reads 1..", kCaptureVersion, ")"));
  }
  if (auto s = root->AllowOnlyKeys(
          {"format", "version", "vin", "car_model", "time_ns", "origin", "aligner", "sensors"});
      !s.ok()) {
    return s;
  }
  Capture c;
  c.dir = dir;
  c.budget = budget;
  CaptureManifest& m = c.manifest;
  m.version = static_cast<int>(*version);
  absl::StatusOr<std::string> vin = root->String("vin");
  if (!vin.ok()) return vin.status();
  if (absl::Status s = ValidateVin(*vin, /*check_digit=*/false); !s.ok())
    return root->Error("vin", std::string(s.message()));
  m.vin = *vin;
  absl::StatusOr<std::string> car_model = root->String("car_model");
  if (!car_model.ok()) return car_model.status();
  m.car_model = *car_model;
  absl::StatusOr<std::int64_t> time = root->Integer("time_ns");
  if (!time.ok()) return time.status();
  m.time_ns = *time;
  absl::StatusOr<std::string> origin = root->String("origin");
  if (!origin.ok()) return origin.status();
  if (*origin != "station" && *origin != "simulator") {
    return root->Error("origin",
                       absl::StrCat("must be 'station' or 'simulator', got '", *origin, "'"));
  }
  m.origin = *origin;
  absl::StatusOr<AlignerMeasurement> aligner = ReadAligner(*root, "aligner");
  if (!aligner.ok()) return aligner.status();
  m.aligner = *aligner;

  absl::StatusOr<StationLayout> station =
      ReadStationLayout((root_dir / kCaptureStationFile).string());
  if (!station.ok()) return station.status();
  c.station = std::move(*station);
  absl::StatusOr<CarModel> car = ReadCarModel((root_dir / kCaptureCarFile).string());
  if (!car.ok()) return car.status();
  c.car = std::move(*car);
  if (c.car.id != m.car_model) {
    return root->Error("car_model", absl::StrCat("'", m.car_model, "' but ", kCaptureCarFile,
                                                 " is car model '", c.car.id, "'"));
  }
  if (absl::Status s = CheckAngleFiles(resolved_dir, root_dir, c.car); !s.ok()) return s;
  if (absl::Status s = CheckTargetsExist(c.car, c.station); !s.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat((root_dir / kCaptureCarFile).string(), ": ", s.message()));
  }

  absl::StatusOr<std::vector<JsonField>> sensors = root->Array("sensors");
  if (!sensors.ok()) return sensors.status();
  std::set<std::string> names;
  EntryContext ctx{root_dir, resolved_dir, &c.budget, 0};
  for (const JsonField& f : *sensors) {
    absl::StatusOr<CaptureSensor> s = ReadSensorEntry(f, ctx, c.car);
    if (!s.ok()) return s.status();
    if (!names.insert(s->name).second)
      return f.Error("name", absl::StrCat("sensor '", s->name, "' listed twice"));
    m.sensors.push_back(std::move(*s));
  }
  return c;
}

nlohmann::json CaptureManifestToJson(const CaptureManifest& m) {
  const auto file_json = [](const CaptureFile& f) {
    return nlohmann::json{{"path", f.path}, {"t_ns", f.t_ns}};
  };
  nlohmann::json sensors = nlohmann::json::array();
  for (const CaptureSensor& s : m.sensors) {
    nlohmann::json j = {{"name", s.name}, {"kind", SensorKindName(s.kind)}};
    if (!s.frames.empty()) {
      nlohmann::json frames = nlohmann::json::array();
      for (const CaptureFile& f : s.frames) frames.push_back(file_json(f));
      j["frames"] = std::move(frames);
    }
    if (s.packets) j["packets"] = file_json(*s.packets);
    if (s.can_log) j["can_log"] = file_json(*s.can_log);
    sensors.push_back(std::move(j));
  }
  return {{"format", kCaptureFormat},
          {"version", m.version},
          {"vin", m.vin},
          {"car_model", m.car_model},
          {"time_ns", m.time_ns},
          {"origin", m.origin},
          {"aligner", AlignerToJson(m.aligner)},
          {"sensors", sensors}};
}

absl::Status WriteCapture(const std::string& dir, const CaptureManifest& manifest,
                          const StationLayout& station, const CarModel& car) {
  const fs::path root_dir(dir);
  std::error_code ec;
  if (!fs::is_directory(root_dir, ec))
    return absl::NotFoundError(absl::StrCat(dir, ": no such directory"));
  // Angle files travel with the capture so that it stays self-contained.
  CarModel copy = car;
  for (SensorModel& s : copy.sensors) {
    if (s.angles_file.empty()) continue;
    const std::string name =
        absl::StrCat(s.name, "-angles", fs::path(s.angles_file).extension().string());
    fs::copy_file(s.angles_file, root_dir / name, fs::copy_options::overwrite_existing, ec);
    if (ec)
      return absl::InternalError(
          absl::StrCat(s.angles_file, ": cannot copy into ", dir, ": ", ec.message()));
    s.angles_file = name;
  }
  if (absl::Status st =
          WriteJsonFile((root_dir / kCaptureStationFile).string(), StationLayoutToJson(station));
      !st.ok()) {
    return st;
  }
  if (absl::Status st = WriteJsonFile((root_dir / kCaptureCarFile).string(), CarModelToJson(copy));
      !st.ok())
    return st;
  // The manifest last: a capture without one is visibly incomplete.
  return WriteJsonFile((root_dir / kCaptureManifestFile).string(), CaptureManifestToJson(manifest));
}

}  // namespace linecal

// linecal capture check DIR: validates a capture (docs/capture-format.md).
#include <cstdio>
#include <string>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "station/capture/capture.h"
#include "station/io/image_io.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"

namespace linecal::tools {
namespace {

// Decodes every camera frame: a frame must be a readable image of the size the car model's
// intrinsics give. Errors name the frame's manifest path.
absl::Status CheckCameraFrames(const Capture& c) {
  for (size_t i = 0; i < c.manifest.sensors.size(); ++i) {
    const CaptureSensor& s = c.manifest.sensors[i];
    if (s.kind != SensorKind::kCamera) continue;
    const CameraIntrinsics& in = *c.car.FindSensor(s.name)->intrinsics;
    for (size_t k = 0; k < s.frames.size(); ++k) {
      absl::StatusOr<Image8> img = ReadImage8(c.PathOf(s.frames[k]));
      const std::string where = absl::StrCat(c.dir, "/", kCaptureManifestFile, ": sensors[", i, "].frames[", k, "]");
      if (!img.ok()) return absl::InvalidArgumentError(absl::StrCat(where, ": ", img.status().message()));
      if (img->width != in.width || img->height != in.height) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": image is ", img->width, "x", img->height,
                                                       ", the car model says ", in.width, "x", in.height));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace

int RunCaptureCheck(const Args& args) {
  cli::CommandLine cl("linecal capture check DIR [--json]",
                      "Validates a capture directory: manifest, station and car files, every sensor's "
                      "data files (camera frames are decoded). Exit 0 when valid, 2 with the offending "
                      "path and field otherwise.",
                      {{"DIR", "", "the capture directory", /*required=*/true, /*repeated=*/false,
                        /*positional=*/true},
                       {"json", "", "print the summary as JSON"}});
  if (auto code = cli::ParseOrExit(cl, "capture check", args)) return *code;
  absl::StatusOr<Capture> c = ReadCapture(cl.Get("DIR"));
  if (!c.ok()) return cli::BadInput("capture check", std::string(c.status().message()));
  if (absl::Status s = CheckCameraFrames(*c); !s.ok()) return cli::BadInput("capture check", std::string(s.message()));

  const CaptureManifest& m = c->manifest;
  if (cl.Has("json")) {
    nlohmann::json sensors = nlohmann::json::array();
    for (const CaptureSensor& s : m.sensors) {
      sensors.push_back({{"name", s.name},
                         {"kind", SensorKindName(s.kind)},
                         {"frames", s.frames.size()},
                         {"packets", s.packets.has_value()},
                         {"can_log", s.can_log.has_value()}});
    }
    const nlohmann::json out = {{"valid", true},           {"version", m.version}, {"vin", m.vin},
                                {"car_model", m.car_model}, {"origin", m.origin},   {"station", c->station.name},
                                {"sensors", sensors}};
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    std::printf("capture %s: valid (format v%d, %s)\n", c->dir.c_str(), m.version, m.origin.c_str());
    std::printf("  VIN %s, car model %s, station %s\n", m.vin.c_str(), m.car_model.c_str(), c->station.name.c_str());
    for (const CaptureSensor& s : m.sensors) {
      std::printf("  %-20s %-7s %zu frame(s)%s%s\n", s.name.c_str(), SensorKindName(s.kind), s.frames.size(),
                  s.packets ? ", packets" : "", s.can_log ? ", CAN log" : "");
    }
  }
  return cli::kExitOk;
}

}  // namespace linecal::tools

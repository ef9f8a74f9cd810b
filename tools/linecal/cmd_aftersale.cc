// linecal aftersale: camera calibration in a workshop from lane lines (docs/aftersale.md).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "station/aftersale/document.h"
#include "station/aftersale/overlay.h"
#include "station/io/image_io.h"
#include "station/io/json_reader.h"
#include "station/solvers/lane_calibration.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"
#include "tools/linecal/detection_overlay.h"

namespace linecal::tools {
namespace {

namespace fs = std::filesystem;
constexpr char kCommand[] = "aftersale";
constexpr double kDeg = std::numbers::pi / 180.0;

// "u,v,u,v,..." as points; `what` names the flag or field in errors.
absl::StatusOr<std::vector<Eigen::Vector2d>> ParsePoints(const std::string& text,
                                                         const std::string& what) {
  absl::StatusOr<std::vector<double>> v = cli::ParseNumberList(text, what);
  if (!v.ok()) return v.status();
  if (v->size() % 2 != 0)
    return absl::InvalidArgumentError(absl::StrCat(what, ": an odd count of numbers (U,V pairs)"));
  std::vector<Eigen::Vector2d> points;
  for (size_t i = 0; i < v->size(); i += 2) points.emplace_back((*v)[i], (*v)[i + 1]);
  return points;
}

// The input file; its image is relative to the file, so that a directory of inputs can move.
absl::Status ReadInputFile(const std::string& path, AftersaleRequest* r) {
  absl::StatusOr<JsonDocument> doc = JsonDocument::FromFile(path);
  if (!doc.ok()) return doc.status();
  absl::StatusOr<JsonField> root = doc->Root();
  if (!root.ok()) return root.status();
  if (absl::Status s = ReadAftersaleInput(*root, r); !s.ok()) return s;
  if (!r->image.empty() && !fs::path(r->image).is_absolute()) {
    r->image = (fs::path(path).parent_path() / r->image).string();
  }
  return absl::OkStatus();
}

absl::Status ReadFlags(const cli::CommandLine& cl, AftersaleRequest* r) {
  if (cl.Has("name")) r->name = cl.Get("name");
  if (cl.Has("image")) r->image = cl.Get("image");
  if (cl.Has("model")) {
    const std::string m = cl.Get("model");
    if (m != "pinhole" && m != "fisheye")
      return absl::InvalidArgumentError("--model: must be pinhole or fisheye, got '" + m + "'");
    r->model = m == "fisheye" ? CameraModelType::kFisheye : CameraModelType::kPinhole;
  }
  for (const auto& [flag, slot] :
       {std::pair{"fx", &r->fx}, std::pair{"fy", &r->fy}, std::pair{"cx", &r->cx},
        std::pair{"cy", &r->cy}, std::pair{"camera-height-m", &r->camera_height_m},
        std::pair{"measured-distance-m", &r->measured_distance_m}}) {
    if (!cl.Has(flag)) continue;
    absl::StatusOr<double> v = cl.GetDouble(flag, 0);
    if (!v.ok()) return v.status();
    *slot = *v;
  }
  for (const auto& [flag, slot] :
       {std::pair{"longitudinal-offset-m", &r->longitudinal_offset_m},
        std::pair{"lateral-offset-m", &r->lateral_offset_m}, std::pair{"roll-deg", &r->roll_deg},
        std::pair{"tolerance-percent", &r->tolerance_percent}}) {
    absl::StatusOr<double> v = cl.GetDouble(flag, *slot);
    if (!v.ok()) return v.status();
    *slot = *v;
  }
  if (cl.Has("rear")) r->looking_backward = true;
  if (cl.Has("distortion")) {
    absl::StatusOr<std::vector<double>> d =
        cli::ParseNumberList(cl.Get("distortion"), "--distortion");
    if (!d.ok()) return d.status();
    r->distortion = *d;
  }
  if (cl.Has("lane") && cl.Has("markers"))
    return absl::InvalidArgumentError("--lane and --markers: give one of them");
  if (cl.Has("lane")) {
    r->lanes_px.clear();
    for (const std::string& text : cl.GetAll("lane")) {
      absl::StatusOr<std::vector<Eigen::Vector2d>> p = ParsePoints(text, "--lane");
      if (!p.ok()) return p.status();
      r->lanes_px.push_back(*p);
    }
  }
  if (cl.Has("markers")) {
    absl::StatusOr<std::vector<Eigen::Vector2d>> p = ParsePoints(cl.Get("markers"), "--markers");
    if (!p.ok()) return p.status();
    absl::StatusOr<std::vector<std::vector<Eigen::Vector2d>>> lanes =
        LanesOfMarkers(*p, "--markers");
    if (!lanes.ok()) return lanes.status();
    r->lanes_px = *lanes;
  }
  if (cl.Has("roll-line")) {
    absl::StatusOr<std::vector<Eigen::Vector2d>> p =
        ParsePoints(cl.Get("roll-line"), "--roll-line");
    if (!p.ok()) return p.status();
    if (p->size() != 2) {
      return absl::InvalidArgumentError(
          absl::StrCat("--roll-line: 2 points needed, got ", p->size()));
    }
    r->roll_line_px = std::array<Eigen::Vector2d, 2>{(*p)[0], (*p)[1]};
  }
  if (cl.Has("marked-point")) {
    absl::StatusOr<std::vector<Eigen::Vector2d>> p =
        ParsePoints(cl.Get("marked-point"), "--marked-point");
    if (!p.ok()) return p.status();
    if (p->size() != 1) return absl::InvalidArgumentError("--marked-point: one point U,V needed");
    r->marked_point_px = (*p)[0];
  }
  return absl::OkStatus();
}

// A polyline through `points` (distorted pixels), skipping gaps where a point is missing.
void DrawPolyline(RgbImage* img, const std::vector<std::optional<Eigen::Vector2d>>& points,
                  int thickness, const RgbColour& c) {
  for (size_t i = 1; i < points.size(); ++i) {
    if (points[i - 1] && points[i]) DrawSegment(img, *points[i - 1], *points[i], thickness, c);
  }
}

// The image with the overlay's lines (station/aftersale/overlay.h: the ground grid, the
// horizon, the lane lines through the vanishing point), the roll line and the marked point.
RgbImage DrawOverlay(const Image8& image, const CameraModel& camera, const LaneCalibrationInput& in,
                     const LaneCalibrationResult& r) {
  RgbImage img = GreyToRgb(image.view());
  const RgbColour grid{0, 200, 255}, lane{0, 230, 0}, vp{255, 40, 40}, horizon{255, 220, 0},
      roll{255, 140, 0}, mark{255, 0, 255};
  const LaneOverlay overlay = LaneOverlayOf(camera, in, r);
  for (const ImagePolyline& line : overlay.ground_grid) DrawPolyline(&img, line, 1, grid);
  DrawPolyline(&img, overlay.horizon, 1, horizon);
  for (size_t i = 0; i < in.lanes_px.size(); ++i) {
    DrawPolyline(&img, overlay.lane_lines[i], 2, lane);
    for (const Eigen::Vector2d& uv : in.lanes_px[i]) DrawCross(&img, uv, 8, lane);
  }
  if (in.roll_line_px) {
    DrawSegment(&img, (*in.roll_line_px)[0], (*in.roll_line_px)[1], 2, roll);
    for (const Eigen::Vector2d& uv : *in.roll_line_px) DrawCross(&img, uv, 8, roll);
  }
  if (in.marked_point) DrawCross(&img, in.marked_point->uv_px, 12, mark);
  if (overlay.vanishing_point_uv) DrawCross(&img, *overlay.vanishing_point_uv, 14, vp);
  return img;
}

// The reference toolbox's three files (docs/aftersale.md, "Export"), with the real values.
absl::StatusOr<std::vector<std::string>> Export(const std::string& dir, const std::string& name,
                                                const LaneCalibrationInput& in,
                                                const LaneCalibrationResult& r) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec)
    return absl::InvalidArgumentError(
        absl::StrCat("--export: cannot create ", dir, ": ", ec.message()));
  std::vector<std::string> written;
  for (const auto& [file, j] : AftersaleExportFiles(name, in, r)) {
    const std::string path = (fs::path(dir) / file).string();
    if (absl::Status s = WriteJsonFile(path, j); !s.ok()) return s;
    written.push_back(path);
  }
  return written;
}

}  // namespace

int RunAftersale(const Args& args) {
  cli::CommandLine cl(
      "linecal aftersale [--input FILE] [--image FILE --lane U,V,U,V --lane U,V,U,V "
      "--camera-height-m H --fx F --fy F] "
      "[options]",
      "Calibrates a camera from points on two lane lines (or four markers parallel to the car) in "
      "one of its "
      "images: vanishing point, roll from an optional roll line, pitch and yaw, the ground "
      "homography, a bird's-eye "
      "view, and the ranging error at a marked point of measured distance (docs/aftersale.md). "
      "Flags override the "
      "input file. Exit 0 done (distance check passed or not asked), 1 the distance check failed, "
      "2 bad input.",
      {{"input", "FILE", "the input as JSON (docs/aftersale.md)"},
       {"image", "FILE", "the camera's image (PNG or JPEG)"},
       {"name", "NAME", "the camera's name in the outputs (default front_camera)"},
       {"lane", "U,V,U,V[,...]", "points on one lane line, distorted pixels; give it for each line",
        false, true},
       {"markers", "U,V x4", "four markers: left near, left far, right near, right far"},
       {"roll-line", "U,V,U,V", "the two ends of the roll line"},
       {"roll-deg", "R", "the roll assumed without a roll line, degrees (default 0)"},
       {"camera-height-m", "H", "the camera's height above the ground, metres"},
       {"longitudinal-offset-m", "X",
        "the camera's x in the car frame (forward), metres (default 0)"},
       {"lateral-offset-m", "Y", "the camera's y in the car frame (left), metres (default 0)"},
       {"rear", "", "the camera looks backward"},
       {"fx", "F", "focal length, pixels"},
       {"fy", "F", "focal length, pixels"},
       {"cx", "C", "principal point, pixels (default the image centre)"},
       {"cy", "C", "principal point, pixels (default the image centre)"},
       {"model", "pinhole|fisheye", "lens model (default pinhole)"},
       {"distortion", "K1,K2,P1,P2[,K3]", "distortion (fisheye: K1,K2,K3,K4; default none)"},
       {"marked-point", "U,V", "a marked point on the ground"},
       {"measured-distance-m", "D",
        "its measured distance ahead of the camera's footprint, metres"},
       {"tolerance-percent", "P", "the distance check's tolerance, percent (default 1)"},
       {"json", "", "print the result as JSON"},
       {"out", "DIR", "write <name>-overlay.png and <name>-birdseye.png here"},
       {"export", "DIR", "write the reference toolbox's three JSON files here"}});
  if (auto code = cli::ParseOrExit(cl, kCommand, args)) return *code;

  AftersaleRequest request;
  if (cl.Has("input")) {
    if (absl::Status s = ReadInputFile(cl.Get("input"), &request); !s.ok())
      return cli::BadInput(kCommand, std::string(s.message()));
  }
  if (absl::Status s = ReadFlags(cl, &request); !s.ok())
    return cli::BadInput(kCommand, std::string(s.message()));
  if (request.image.empty())
    return cli::BadInput(kCommand, "image: missing (--image or the input file's image)");
  absl::StatusOr<Image8> image = ReadImage8(request.image);
  if (!image.ok())
    return cli::BadInput(kCommand, absl::StrCat("unreadable image: ", image.status().message()));
  absl::StatusOr<LaneCalibrationInput> in =
      AftersaleSolverInput(request, image->width, image->height);
  if (!in.ok()) return cli::BadInput(kCommand, std::string(in.status().message()));
  absl::StatusOr<LaneCalibrationResult> r = CalibrateFromLanes(*in);
  if (!r.ok()) return cli::BadInput(kCommand, std::string(r.status().message()));
  const CameraModel camera = *CameraModel::Create(in->intrinsics);

  nlohmann::json j = AftersaleResultJson(request.name, *in, *r);
  j["image"] = request.image;
  if (cl.Has("out")) {
    const fs::path dir = cl.Get("out");
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec)
      return cli::BadInput(kCommand,
                           absl::StrCat("--out: cannot create ", dir.string(), ": ", ec.message()));
    const std::string overlay = (dir / (request.name + "-overlay.png")).string();
    const std::string birdseye = (dir / (request.name + "-birdseye.png")).string();
    for (const auto& [path, picture] :
         {std::pair{overlay, DrawOverlay(*image, camera, *in, *r)},
          std::pair{birdseye, BirdsEyePicture(*image, camera, *in, *r)}}) {
      if (absl::Status s = WritePngRgb(path, picture); !s.ok()) {
        std::fprintf(stderr, "linecal aftersale: %s\n", std::string(s.message()).c_str());
        return cli::kExitNegative;
      }
    }
    j["overlay_png"] = overlay;
    j["birdseye_png"] = birdseye;
  }
  if (cl.Has("export")) {
    absl::StatusOr<std::vector<std::string>> written =
        Export(cl.Get("export"), request.name, *in, *r);
    if (!written.ok()) return cli::BadInput(kCommand, std::string(written.status().message()));
    j["export"] = *written;
  }
  if (cl.Has("json")) {
    std::printf("%s\n", j.dump(2).c_str());
  } else {
    std::printf(
        "%s: vanishing point (%.2f, %.2f) px, yaw %.3f, pitch %.3f, roll %.3f deg (roll %s)\n",
        request.name.c_str(), r->vanishing_point_px.x(), r->vanishing_point_px.y(),
        r->angles.yaw / kDeg, r->angles.pitch / kDeg, r->angles.roll / kDeg,
        r->roll_from_line ? "from the roll line" : "assumed");
    if (r->distance_check) {
      const LaneDistanceCheck& c = *r->distance_check;
      std::printf(
          "distance check: %.3f m computed, %.3f m measured, %+.2f%% (tolerance %.2f%%): %s\n",
          c.computed_distance_m, c.measured_distance_m, c.error_percent, in->tolerance_percent,
          c.pass ? "pass" : "FAIL");
    }
  }
  return r->distance_check && !r->distance_check->pass ? cli::kExitNegative : cli::kExitOk;
}

}  // namespace linecal::tools

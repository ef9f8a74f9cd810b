// linecal detect: finds a calibration board in an image, or the round-hole board in LiDAR
// point clouds, and prints its features (docs/interfaces.md, "linecal detect"; fixed, the
// acceptance tests call it).
#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/detect.h"
#include "detectors/detection.h"
#include "detectors/round_hole/round_hole_search.h"
#include "station/camera/camera_model.h"
#include "station/io/image_io.h"
#include "station/model/camera_intrinsics_file.h"
#include "station/model/pose_json.h"
#include "station/sensors/lidar/pcd.h"
#include "station/solvers/undistorted_board.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/board_options.h"
#include "tools/linecal/commands.h"
#include "tools/linecal/detection_overlay.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "detect";

// True when every sample is a multiple of 257: the file held 8-bit samples, which
// ReadImage16 widened (v * 257). Those are detected as they are, without stretching.
bool Holds8BitSamples(const Image16& image) {
  for (std::uint16_t v : image.pixels) {
    if (v % 257 != 0) return false;
  }
  return true;
}

// The boards the cloud search kept, with their evidence and verdict (docs/interfaces.md).
nlohmann::json FitsJson(const std::vector<RoundHoleBoardFit>& fits) {
  nlohmann::json out = nlohmann::json::array();
  for (const RoundHoleBoardFit& f : fits) {
    out.push_back({{"centre", {f.centre_lidar.x(), f.centre_lidar.y(), f.centre_lidar.z()}},
                   {"range_m", f.centre_lidar.norm()},
                   {"edges", f.edges},
                   {"edge_rms_m", f.edge_rms_m},
                   {"edge_rms_mrad", 1e3 * f.edge_rms_rad},
                   {"rms_ratio", f.rms_ratio},
                   {"hole_fill", f.hole_fill},
                   {"rings_through_holes", f.rings_through_holes},
                   {"verdict", RoundHoleFitVerdictName(f.verdict)}});
  }
  return out;
}

// The same as text, one line per board, and what to do when several tie.
void PrintFits(const RoundHoleSearchResult& result) {
  if (result.fits.size() < 2) return;
  for (const RoundHoleBoardFit& f : result.fits) {
    std::printf(
        "board at %7.3f %7.3f %7.3f (%.2f m): %4d edges, edge rms %.1f mm (%.2f mrad, "
        "x%.2f), hole fill %.2f, %d rings through holes: %s\n",
        f.centre_lidar.x(), f.centre_lidar.y(), f.centre_lidar.z(), f.centre_lidar.norm(), f.edges,
        1e3 * f.edge_rms_m, 1e3 * f.edge_rms_rad, f.rms_ratio, f.hole_fill, f.rings_through_holes,
        RoundHoleFitVerdictName(f.verdict));
  }
  if (!result.found) {
    std::printf(
        "several boards fit alike: cover or move all but the one to use, or scan from "
        "where it is nearer than the others\n");
  }
}

// --cloud: reads every PCD (rings from the elevations when a file has none), searches them
// accumulated for the round-hole board and prints the hole centres.
int DetectInClouds(const cli::CommandLine& cl, const Board& board) {
  std::vector<std::vector<RoundHoleCloudPoint>> frames;
  bool rings_from_elevation = false;
  for (const std::string& path : cl.GetAll("cloud")) {
    const absl::StatusOr<PcdCloud> cloud = ReadPcd(path);
    if (!cloud.ok()) {
      return cli::BadInput(kCommand,
                           absl::StrCat("--cloud ", path, ": ", cloud.status().message()));
    }
    std::vector<RoundHoleCloudPoint>& frame = frames.emplace_back();
    frame.reserve(cloud->points.size());
    for (const LidarPoint& p : cloud->points) frame.push_back({p.x, p.y, p.z, p.ring});
    rings_from_elevation = rings_from_elevation || !cloud->has_ring;
  }
  // Rings must number the same beams in every frame, so all frames get them from elevation
  // when one file has none.
  if (rings_from_elevation) AssignRingsByElevation(frames);
  const std::vector<std::span<const RoundHoleCloudPoint>> views(frames.begin(), frames.end());

  const auto start = std::chrono::steady_clock::now();
  const RoundHoleSearchResult result = SearchRoundHoleBoardInCloud(board, views);
  const double elapsed_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();

  const RoundHoleCloudDetection& d = result.detection;
  const double scale = board.params().scale;
  const std::string reason = RoundHoleSearchReasonName(result.reason);
  // What the best candidate's whole-board fit said, when the board was not found.
  const std::string fit_reason =
      result.found || result.candidates == 0 ? "" : RoundHoleCloudReasonName(d.reason);
  if (cl.Has("json")) {
    nlohmann::json features = nlohmann::json::array();
    for (const RoundHoleHole& h : d.holes) {
      const Eigen::Vector2d& p_board = board.features()[h.id].p_board;
      features.push_back({{"id", h.id},
                          {"p", {h.p_lidar.x(), h.p_lidar.y(), h.p_lidar.z()}},
                          {"x", p_board.x() / scale},
                          {"y", p_board.y() / scale},
                          {"rings", h.rings}});
    }
    nlohmann::json report = {
        {"board", board.name()},
        {"found", result.found},
        {"reason", reason},
        {"features", features},
        {"T_lidar_board", result.found ? MatrixToJson(d.T_lidar_board.Matrix()) : nlohmann::json()},
        {"elapsed_ms", elapsed_ms},
        {"clouds", frames.size()},
        {"rings_from_elevation", rings_from_elevation},
        {"candidates", result.candidates},
        {"boards", FitsJson(result.fits)},
        {"fit",
         {{"reason", fit_reason},
          {"plane_inliers", d.plane_inliers},
          {"plane_rms_m", d.plane_rms_m},
          {"normal_sigma_deg", d.normal_sigma_rad * 180.0 / std::numbers::pi},
          {"edges", d.edges},
          {"edge_rms_m", d.edge_rms_m},
          {"rings_through_holes", d.rings_through_holes}}}};
    std::printf("%s\n", report.dump().c_str());
  } else {
    std::printf(
        "%s: %s%s, %zu clouds%s, %d candidates, %.2f ms\n", board.name(),
        result.found ? "found" : "not found",
        result.found
            ? ""
            : absl::StrCat(" (", reason, fit_reason.empty() ? "" : ": ", fit_reason, ")").c_str(),
        frames.size(), rings_from_elevation ? " (rings from elevation)" : "", result.candidates,
        elapsed_ms);
    for (const RoundHoleHole& h : d.holes) {
      const Eigen::Vector2d& p_board = board.features()[h.id].p_board;
      std::printf("%4d  p %9.4f %9.4f %9.4f  x %8.4f  y %8.4f  rings %d\n", h.id, h.p_lidar.x(),
                  h.p_lidar.y(), h.p_lidar.z(), p_board.x() / scale, p_board.y() / scale, h.rings);
    }
    PrintFits(result);
  }
  return result.found ? cli::kExitOk : cli::kExitNegative;
}

// --intrinsics: the camera of the file, which must have the image's size.
absl::StatusOr<CameraModel> ReadCamera(const cli::CommandLine& cl, int width, int height) {
  const std::string path = cl.Get("intrinsics");
  const absl::StatusOr<CameraIntrinsics> intrinsics =
      ReadCameraIntrinsicsFile(path, cl.Has("camera") ? cl.Get("camera") : "");
  if (!intrinsics.ok()) return intrinsics.status();
  if (intrinsics->width != width || intrinsics->height != height) {
    return absl::InvalidArgumentError(absl::StrCat("--intrinsics ", path, ": the camera is ",
                                                   intrinsics->width, " x ", intrinsics->height,
                                                   " px, the image ", width, " x ", height, " px"));
  }
  return CameraModel::Create(*intrinsics);
}

// With --intrinsics, a board's features must lie on one plane through the camera model: a
// detection (found, or partial with the 4 features a homography needs) that fails the check
// becomes not found, verification_failed, without features, since none of them is certain.
void ApplyCheck(const UndistortedBoard& check, Detection* detection) {
  const bool checked =
      detection->found || (detection->reason == DetectReason::kPartial && check.points >= 4);
  if (!checked || check.verified) return;
  detection->found = false;
  detection->reason = DetectReason::kVerificationFailed;
  detection->features.clear();
}

// A finite number, or null for JSON (a check that could not fit gives +infinity).
nlohmann::json FiniteOrNull(double v) { return std::isfinite(v) ? nlohmann::json(v) : nullptr; }

bool HasPose(const UndistortedBoard& check) {
  return check.verified && check.pose.outcome == PnpOutcome::kOk;
}

nlohmann::json CheckToJson(const cli::CommandLine& cl, const CameraModel& camera,
                           const UndistortedBoard& check) {
  const bool pose = HasPose(check);
  return {{"file", cl.Get("intrinsics")},
          {"camera", cl.Has("camera") ? cl.Get("camera") : ""},
          {"model", CameraModelTypeName(camera.type())},
          {"residual_rms_px", FiniteOrNull(check.homography_rms_px)},
          {"residual_max_px", FiniteOrNull(check.homography_max_px)},
          {"pose_reason", check.verified ? PnpOutcomeName(check.pose.outcome) : ""},
          {"T_camera_board",
           pose ? MatrixToJson(check.pose.T_camera_object.Matrix()) : nlohmann::json()},
          {"pose_rms_px", pose ? nlohmann::json(check.pose.residual_rms_px) : nlohmann::json()}};
}

void PrintCheck(const cli::CommandLine& cl, const CameraModel& camera,
                const UndistortedBoard& check) {
  std::printf("intrinsics %s (%s): ", cl.Get("intrinsics").c_str(),
              CameraModelTypeName(camera.type()));
  if (check.points < 4) {
    std::printf("not checked: %d features, a homography needs 4\n", check.points);
    return;
  }
  if (!std::isfinite(check.homography_rms_px)) {
    std::printf("no board homography in undistorted coordinates\n");
    return;
  }
  std::printf("board homography residual %.3f px RMS, %.3f px max (undistorted coordinates)\n",
              check.homography_rms_px, check.homography_max_px);
  if (!check.verified) return;
  if (!HasPose(check)) {
    std::printf("pose: %s\n", PnpOutcomeName(check.pose.outcome));
    return;
  }
  const Rigid3d& T = check.pose.T_camera_object;
  const Eigen::AngleAxisd r(T.rotation());
  const Eigen::Vector3d r_deg = r.axis() * r.angle() * 180.0 / std::numbers::pi;
  const Eigen::Vector3d t_mm = 1e3 * T.translation();
  std::printf(
      "T_camera_board: t %.3f %.3f %.3f mm, rotation vector %.4f %.4f %.4f deg, "
      "residual %.3f px RMS\n",
      t_mm.x(), t_mm.y(), t_mm.z(), r_deg.x(), r_deg.y(), r_deg.z(), check.pose.residual_rms_px);
}

// The options of `linecal detect`: the board's (board_options.h), then the image or clouds and
// what to print or draw.
std::vector<cli::OptionSpec> DetectOptionSpecs() {
  std::vector<cli::OptionSpec> options = BoardOptionSpecs();
  options.push_back({"image", "FILE", "PNG or JPEG, 8- or 16-bit, grey or colour"});
  options.push_back({"cloud", "FILE",
                     "PCD point cloud (ascii, binary, binary_compressed), --board round_hole; "
                     "several are accumulated",
                     false, true});
  options.push_back({"json", "", "print the result as one JSON object"});
  options.push_back({"overlay", "OUT.png", "write the image with the features drawn"});
  options.push_back({"intrinsics", "FILE",
                     "the camera's model (linecal car model, OpenCV FileStorage YAML or JSON, "
                     "ROS camera_info or Kalibr camchain YAML): the board is verified through "
                     "it and its pose printed"});
  options.push_back({"camera", "NAME",
                     "the camera of --intrinsics when the file holds several (car model, "
                     "Kalibr camchain)"});
  return options;
}

// The 8-bit image the detector sees: the file's own samples, or the 16-bit range stretched.
Image8 DetectorImage(const Image16& image16) {
  Image8 image8;
  if (Holds8BitSamples(image16)) {
    image8 = Image8(image16.width, image16.height);
    for (std::size_t i = 0; i < image8.pixels.size(); ++i) {
      image8.pixels[i] = static_cast<std::uint8_t>(image16.pixels[i] / 257);
    }
  } else {
    image8 = RangeTo8Bit(image16.view());
  }
  return image8;
}

// An image detection as one JSON object on stdout, with the --intrinsics check when it ran.
void PrintDetectionJson(const cli::CommandLine& cl, const Board& board, const Detection& detection,
                        const std::optional<CameraModel>& camera,
                        const std::optional<UndistortedBoard>& check, double elapsed_ms) {
  // x, y at the default scale (docs/interfaces.md): the ids' positions on the PDF board.
  const double scale = board.params().scale;
  nlohmann::json features = nlohmann::json::array();
  for (const DetectedFeature& f : detection.features) {
    features.push_back({{"id", f.id},
                        {"u", f.uv_px.x()},
                        {"v", f.uv_px.y()},
                        {"x", f.p_board.x() / scale},
                        {"y", f.p_board.y() / scale},
                        {"marker", f.marker}});
  }
  // complete: every feature of the board is here (false for a partial view of a board
  // with ids, whose seen features are listed).
  const bool complete = detection.features.size() == board.features().size();
  nlohmann::json report = {{"board", board.name()}, {"found", detection.found},
                           {"complete", complete},  {"reason", DetectReasonName(detection.reason)},
                           {"features", features},  {"elapsed_ms", elapsed_ms}};
  if (check.has_value()) report["intrinsics"] = CheckToJson(cl, *camera, *check);
  std::printf("%s\n", report.dump().c_str());
}

// An image detection as text on stdout: a summary line, a line per feature and the
// --intrinsics check when it ran.
void PrintDetectionText(const cli::CommandLine& cl, const Board& board, const Detection& detection,
                        const std::optional<CameraModel>& camera,
                        const std::optional<UndistortedBoard>& check, double elapsed_ms) {
  // x, y at the default scale (docs/interfaces.md): the ids' positions on the PDF board.
  const double scale = board.params().scale;
  std::printf(
      "%s: %s%s, %zu features, %.2f ms\n", board.name(), detection.found ? "found" : "not found",
      detection.found ? "" : absl::StrCat(" (", DetectReasonName(detection.reason), ")").c_str(),
      detection.features.size(), elapsed_ms);
  for (const DetectedFeature& f : detection.features) {
    std::printf("%4d  u %9.3f  v %9.3f  x %8.4f  y %8.4f%s\n", f.id, f.uv_px.x(), f.uv_px.y(),
                f.p_board.x() / scale, f.p_board.y() / scale,
                f.marker >= 0 ? absl::StrFormat("  marker %d", f.marker).c_str() : "");
  }
  if (check.has_value()) PrintCheck(cl, *camera, *check);
}

}  // namespace

int RunDetect(const Args& args) {
  cli::CommandLine cl(
      "linecal detect --board NAME [--scale S] [--cols N --rows M] [--square METRES] "
      "[--gap METRES] [--spacing METRES --diameter METRES] [--asymmetric | --hexagonal] "
      "[--light-circles] [--marker METRES] [--legacy-pattern] [--dictionary NAME] "
      "--image FILE [--intrinsics FILE [--camera NAME]] [--json] "
      "[--overlay OUT.png]\n"
      "       linecal detect --board round_hole [--scale S] --cloud FILE [--cloud FILE ...] "
      "[--json]",
      "Finds the board in the image and prints every feature found: its id, sub-pixel image "
      "position (u, v; pixel centres at integers) and board position (x, y, metres, at the "
      "default scale). 16-bit images are stretched from their darkest to their brightest "
      "pixel. With --cloud, searches the LiDAR scans for the round-hole board (no expected "
      "pose needed) and prints its hole centres p in the LiDAR frame and T_lidar_board; "
      "clouds without a ring field get rings from their elevation angles. With --intrinsics, "
      "the features must fit one board plane through the camera model (homography residual "
      "at most 1 px RMS, else verification_failed) and the board's pose T_camera_board is "
      "printed; features stay in raw pixels. Exit 0 when the "
      "whole board was found, 1 when not (the reason is printed), 2 on bad usage or input.",
      DetectOptionSpecs());
  if (const std::optional<int> exit = cli::ParseOrExit(cl, kCommand, args)) return *exit;

  const absl::StatusOr<BoardParams> params = BoardParamsFromCommandLine(cl);
  if (!params.ok()) return cli::BadInput(kCommand, std::string(params.status().message()));
  const std::optional<Board> board = Board::Create(*params);
  if (!board.has_value()) return cli::BadInput(kCommand, "invalid board parameters");

  if (cl.Has("camera") && !cl.Has("intrinsics")) {
    return cli::BadInput(kCommand, "--camera: names a camera of --intrinsics FILE");
  }
  if (cl.Has("cloud")) {
    if (cl.Has("intrinsics")) {
      return cli::BadInput(kCommand, "--intrinsics: images only, not --cloud");
    }
    if (cl.Has("image")) return cli::BadInput(kCommand, "--image and --cloud: give one of them");
    if (cl.Has("overlay")) return cli::BadInput(kCommand, "--overlay: images only, not --cloud");
    if (board->type() != BoardType::kRoundHole) {
      return cli::BadInput(kCommand, absl::StrCat("--cloud: only --board round_hole is found in "
                                                  "point clouds, not --board ",
                                                  board->name()));
    }
    return DetectInClouds(cl, *board);
  }
  if (!cl.Has("image")) return cli::BadInput(kCommand, "--image FILE or --cloud FILE is required");

  const std::string path = cl.Get("image");
  absl::StatusOr<Image16> image16 = ReadImage16(path);
  if (!image16.ok()) return cli::BadInput(kCommand, std::string(image16.status().message()));
  std::optional<CameraModel> camera;
  if (cl.Has("intrinsics")) {
    absl::StatusOr<CameraModel> read = ReadCamera(cl, image16->width, image16->height);
    if (!read.ok()) return cli::BadInput(kCommand, std::string(read.status().message()));
    camera = *std::move(read);
  }
  const Image8 image8 = DetectorImage(*image16);

  const auto start = std::chrono::steady_clock::now();
  std::optional<Detection> detection = DetectBoard(image8.view(), *board);
  std::optional<UndistortedBoard> check;
  if (camera.has_value() && detection.has_value()) {
    absl::StatusOr<UndistortedBoard> checked = CheckBoardUndistorted(*camera, detection->features);
    if (!checked.ok()) return cli::BadInput(kCommand, std::string(checked.status().message()));
    ApplyCheck(*checked, &*detection);
    check = *std::move(checked);
  }
  const double elapsed_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  if (!detection.has_value()) {
    return cli::BadInput(kCommand, absl::StrCat("--board ", board->name(),
                                                ": no image detector for this board yet"));
  }

  if (cl.Has("overlay")) {
    const std::string out = cl.Get("overlay");
    const absl::Status written = WritePngRgb(out, DrawDetectionOverlay(image8.view(), *detection));
    if (!written.ok()) return cli::BadInput(kCommand, std::string(written.message()));
  }

  if (cl.Has("json")) {
    PrintDetectionJson(cl, *board, *detection, camera, check, elapsed_ms);
  } else {
    PrintDetectionText(cl, *board, *detection, camera, check, elapsed_ms);
  }
  return detection->found ? cli::kExitOk : cli::kExitNegative;
}

}  // namespace linecal::tools

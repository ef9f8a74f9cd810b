// linecal detect: finds a calibration board in an image, or the round-hole board in LiDAR
// point clouds, and prints its features (docs/interfaces.md, "linecal detect"; fixed, the
// acceptance tests call it).
#include <chrono>
#include <numbers>
#include <span>
#include <vector>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/detect.h"
#include "detectors/detection.h"
#include "detectors/round_hole/round_hole_search.h"
#include "station/io/image_io.h"
#include "station/io/pcd.h"
#include "station/model/pose_json.h"
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

// --cloud: reads every PCD (rings from the elevations when a file has none), searches them
// accumulated for the round-hole board and prints the hole centres.
int DetectInClouds(const cli::CommandLine& cl, const Board& board) {
  std::vector<std::vector<RoundHoleCloudPoint>> frames;
  bool rings_from_elevation = false;
  for (const std::string& path : cl.GetAll("cloud")) {
    const absl::StatusOr<PcdCloud> cloud = ReadPcd(path);
    if (!cloud.ok()) {
      return cli::BadInput(kCommand, absl::StrCat("--cloud ", path, ": ", cloud.status().message()));
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
        {"fit", {{"reason", fit_reason},
                 {"plane_inliers", d.plane_inliers},
                 {"plane_rms_m", d.plane_rms_m},
                 {"normal_sigma_deg", d.normal_sigma_rad * 180.0 / std::numbers::pi},
                 {"edges", d.edges},
                 {"edge_rms_m", d.edge_rms_m},
                 {"rings_through_holes", d.rings_through_holes}}}};
    std::printf("%s\n", report.dump().c_str());
  } else {
    std::printf("%s: %s%s, %zu clouds%s, %d candidates, %.2f ms\n", board.name(),
                result.found ? "found" : "not found",
                result.found ? ""
                             : absl::StrCat(" (", reason, fit_reason.empty() ? "" : ": ",
                                            fit_reason, ")")
                                   .c_str(),
                frames.size(), rings_from_elevation ? " (rings from elevation)" : "",
                result.candidates, elapsed_ms);
    for (const RoundHoleHole& h : d.holes) {
      const Eigen::Vector2d& p_board = board.features()[h.id].p_board;
      std::printf("%4d  p %9.4f %9.4f %9.4f  x %8.4f  y %8.4f  rings %d\n", h.id, h.p_lidar.x(),
                  h.p_lidar.y(), h.p_lidar.z(), p_board.x() / scale, p_board.y() / scale, h.rings);
    }
  }
  return result.found ? cli::kExitOk : cli::kExitNegative;
}

}  // namespace

int RunDetect(const Args& args) {
  std::vector<cli::OptionSpec> options = BoardOptionSpecs();
  options.push_back({"image", "FILE", "PNG or JPEG, 8- or 16-bit, grey or colour"});
  options.push_back({"cloud", "FILE",
                     "PCD point cloud (ascii, binary, binary_compressed), --board round_hole; "
                     "several are accumulated",
                     false, true});
  options.push_back({"json", "", "print the result as one JSON object"});
  options.push_back({"overlay", "OUT.png", "write the image with the features drawn"});
  cli::CommandLine cl(
      "linecal detect --board NAME [--scale S] [--cols N --rows M] [--square METRES] "
      "[--gap METRES] [--spacing METRES --diameter METRES] [--asymmetric] [--light-circles] "
      "--image FILE [--json] [--overlay OUT.png]\n"
      "       linecal detect --board round_hole [--scale S] --cloud FILE [--cloud FILE ...] "
      "[--json]",
      "Finds the board in the image and prints every feature found: its id, sub-pixel image "
      "position (u, v; pixel centres at integers) and board position (x, y, metres, at the "
      "default scale). 16-bit images are stretched from their darkest to their brightest "
      "pixel. With --cloud, searches the LiDAR scans for the round-hole board (no expected "
      "pose needed) and prints its hole centres p in the LiDAR frame and T_lidar_board; "
      "clouds without a ring field get rings from their elevation angles. Exit 0 when the "
      "whole board was found, 1 when not (the reason is printed), 2 on bad usage or input.",
      std::move(options));
  if (const std::optional<int> exit = cli::ParseOrExit(cl, kCommand, args)) return *exit;

  const absl::StatusOr<BoardParams> params = BoardParamsFromCommandLine(cl);
  if (!params.ok()) return cli::BadInput(kCommand, std::string(params.status().message()));
  const std::optional<Board> board = Board::Create(*params);
  if (!board.has_value()) return cli::BadInput(kCommand, "invalid board parameters");

  if (cl.Has("cloud")) {
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
  // The 8-bit image the detector sees: the file's own samples, or the 16-bit range stretched.
  Image8 image8;
  if (Holds8BitSamples(*image16)) {
    image8 = Image8(image16->width, image16->height);
    for (std::size_t i = 0; i < image8.pixels.size(); ++i) {
      image8.pixels[i] = static_cast<std::uint8_t>(image16->pixels[i] / 257);
    }
  } else {
    image8 = RangeTo8Bit(image16->view());
  }

  const auto start = std::chrono::steady_clock::now();
  const std::optional<Detection> detection = DetectBoard(image8.view(), *board);
  const double elapsed_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  if (!detection.has_value()) {
    return cli::BadInput(kCommand, absl::StrCat("--board ", board->name(),
                                                ": no image detector for this board yet"));
  }

  if (cl.Has("overlay")) {
    const std::string out = cl.Get("overlay");
    const absl::Status written =
        WritePngRgb(out, DrawDetectionOverlay(image8.view(), *detection));
    if (!written.ok()) return cli::BadInput(kCommand, std::string(written.message()));
  }

  // x, y at the default scale (docs/interfaces.md): the ids' positions on the PDF board.
  const double scale = board->params().scale;
  if (cl.Has("json")) {
    nlohmann::json features = nlohmann::json::array();
    for (const DetectedFeature& f : detection->features) {
      features.push_back({{"id", f.id},
                          {"u", f.uv_px.x()},
                          {"v", f.uv_px.y()},
                          {"x", f.p_board.x() / scale},
                          {"y", f.p_board.y() / scale},
                          {"marker", f.marker}});
    }
    // complete: every feature of the board is here (false for a partial view of a board
    // with ids, whose seen features are listed).
    const bool complete = detection->features.size() == board->features().size();
    const nlohmann::json report = {{"board", board->name()},
                                   {"found", detection->found},
                                   {"complete", complete},
                                   {"reason", DetectReasonName(detection->reason)},
                                   {"features", features},
                                   {"elapsed_ms", elapsed_ms}};
    std::printf("%s\n", report.dump().c_str());
  } else {
    std::printf("%s: %s%s, %zu features, %.2f ms\n", board->name(),
                detection->found ? "found" : "not found",
                detection->found ? "" : absl::StrCat(" (", DetectReasonName(detection->reason), ")").c_str(),
                detection->features.size(), elapsed_ms);
    for (const DetectedFeature& f : detection->features) {
      std::printf("%4d  u %9.3f  v %9.3f  x %8.4f  y %8.4f%s\n", f.id, f.uv_px.x(), f.uv_px.y(),
                  f.p_board.x() / scale, f.p_board.y() / scale,
                  f.marker >= 0 ? absl::StrFormat("  marker %d", f.marker).c_str() : "");
    }
  }
  return detection->found ? cli::kExitOk : cli::kExitNegative;
}

}  // namespace linecal::tools

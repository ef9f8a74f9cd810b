#include "daemon/web/aftersale_api.h"

#include <atomic>
#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"
#include "station/aftersale/document.h"
#include "station/aftersale/overlay.h"
#include "station/io/image_io.h"
#include "station/io/input_budget.h"
#include "station/io/json_reader.h"

namespace linecal {
namespace {

// Photos being decoded now, in the whole process (kMaxPhotoDecodes).
std::atomic<int> photo_decodes{0};

// A pixel for drawing: 0.01 px is far below a screen pixel at any zoom the page offers, and
// keeps the answer a third of the full doubles' size.
nlohmann::json DrawnPixel(const Eigen::Vector2d& uv) {
  return {std::round(uv.x() * 100) / 100, std::round(uv.y() * 100) / 100};
}

nlohmann::json PolylineJson(const ImagePolyline& line) {
  nlohmann::json points = nlohmann::json::array();
  for (const std::optional<Eigen::Vector2d>& p : line) {
    points.push_back(p ? DrawnPixel(*p) : nlohmann::json(nullptr));
  }
  return points;
}

nlohmann::json PolylinesJson(const std::vector<ImagePolyline>& lines) {
  nlohmann::json out = nlohmann::json::array();
  for (const ImagePolyline& line : lines) out.push_back(PolylineJson(line));
  return out;
}

// image_size: [w, h], whole numbers of pixels in [1, kMaxImageSide].
absl::StatusOr<std::array<int, 2>> ImageSize(const JsonField& root) {
  absl::StatusOr<std::vector<double>> size = root.Numbers("image_size", 2);
  if (!size.ok()) return size.status();
  std::array<int, 2> out{};
  for (int i = 0; i < 2; ++i) {
    const double v = (*size)[i];
    if (v != std::floor(v) || v < 1 || v > kMaxImageSide) {
      return root.Error("image_size", absl::StrCat("must be two whole numbers of pixels in [1, ",
                                                   kMaxImageSide, "], got ", v));
    }
    out[i] = static_cast<int>(v);
  }
  return out;
}

// The kept photo `id` is of `size`, the request's image_size: NotFound when it is not kept,
// InvalidArgument naming image_size when it differs.
absl::Status CheckPhotoSize(AftersalePhotos& photos, const std::string& id,
                            const std::array<int, 2>& size, const JsonField& root) {
  absl::StatusOr<std::pair<int, int>> kept = photos.Size(id);
  if (!kept.ok()) return kept.status();
  if (kept->first == size[0] && kept->second == size[1]) return absl::OkStatus();
  return root.Error("image_size", absl::StrCat("[", size[0], ", ", size[1], "] differs from photo ",
                                               id, "'s ", kept->first, " x ", kept->second));
}

// A solve's answer (without birdseye) and what it was computed from.
struct SolvedRequest {
  nlohmann::json answer;
  LaneCalibrationInput in;
  LaneCalibrationResult result;
};

// The solve of the request's `input` for an image of `size`: the command's input reader,
// solver, result JSON, overlay and export files. Errors: the command's messages.
absl::StatusOr<SolvedRequest> Solve(const JsonField& input, const std::array<int, 2>& size) {
  AftersaleRequest request;
  if (absl::Status s = ReadAftersaleInput(input, &request); !s.ok()) return s;
  if (!request.image.empty()) {
    return input.Error("image",
                       "not taken here: the photo is uploaded (POST "
                       "/api/aftersale/photo) and its size given as image_size");
  }
  absl::StatusOr<LaneCalibrationInput> in = AftersaleSolverInput(request, size[0], size[1]);
  if (!in.ok()) return in.status();
  absl::StatusOr<LaneCalibrationResult> r = CalibrateFromLanes(*in);
  if (!r.ok()) return r.status();
  // CalibrateFromLanes accepted the intrinsics, so the model exists.
  const CameraModel camera = *CameraModel::Create(in->intrinsics);
  LaneOverlayOptions overlay_options;
  overlay_options.segments = kPageOverlaySegments;
  const LaneOverlay overlay = LaneOverlayOf(camera, *in, *r, overlay_options);
  nlohmann::json files = nlohmann::json::array();
  for (const auto& [file, j] : AftersaleExportFiles(request.name, *in, *r)) {
    files.push_back({{"file", file}, {"text", JsonFileText(j)}});
  }
  nlohmann::json answer{
      {"result", AftersaleResultJson(request.name, *in, *r)},
      {"overlay",
       {{"ground_grid", PolylinesJson(overlay.ground_grid)},
        {"horizon", PolylineJson(overlay.horizon)},
        {"lane_lines", PolylinesJson(overlay.lane_lines)},
        {"vanishing_point", overlay.vanishing_point_uv ? DrawnPixel(*overlay.vanishing_point_uv)
                                                       : nlohmann::json(nullptr)}}},
      {"export", files}};
  return SolvedRequest{std::move(answer), *std::move(in), *std::move(r)};
}

}  // namespace

absl::StatusOr<nlohmann::json> AftersalePhotoJson(std::string_view bytes, AftersalePhotos& photos) {
  if (++photo_decodes > kMaxPhotoDecodes) {
    --photo_decodes;
    return absl::UnavailableError(absl::StrCat(
        "photo: ", kMaxPhotoDecodes, " photos are being read already; send it again shortly"));
  }
  InputBudget budget;
  budget.max_file_bytes = kMaxPhotoBytes;
  budget.max_image_pixels = kMaxPhotoPixels;
  absl::StatusOr<Image8> image = DecodeImage8(bytes, "photo", budget);
  --photo_decodes;
  if (!image.ok()) return image.status();
  const int width = image->width, height = image->height;
  absl::StatusOr<std::string> id = photos.Keep(*std::move(image));
  if (!id.ok()) return id.status();
  return nlohmann::json{{"width", width}, {"height", height}, {"photo_id", *id}};
}

nlohmann::json AftersaleCamerasJson(const std::vector<CarModel>& cars) {
  nlohmann::json cameras = nlohmann::json::array();
  for (const CarModel& car : cars) {
    for (const SensorModel& s : car.sensors) {
      if (s.kind != SensorKind::kCamera || !s.intrinsics) continue;
      const Rigid3d& T = s.T_car_sensor_nominal;
      // A camera looks backward when its optical axis (z_camera) points to -x_car.
      const bool backward = T.RotationMatrix().col(2).x() < 0;
      cameras.push_back(
          {{"car_model_id", car.id},
           {"camera", s.name},
           {"image_size", {s.intrinsics->width, s.intrinsics->height}},
           {"input", AftersaleCameraInput(s.name, *s.intrinsics, T.translation(), backward)}});
    }
  }
  return {{"cameras", cameras}, {"max_photo_bytes", kMaxPhotoBytes}};
}

absl::StatusOr<nlohmann::json> AftersaleSolveJson(std::string_view body, AftersalePhotos& photos) {
  absl::StatusOr<JsonDocument> doc = JsonDocument::FromText(std::string(body), "request");
  if (!doc.ok()) return doc.status();
  absl::StatusOr<JsonField> root = doc->Root();
  if (!root.ok()) return root.status();
  if (absl::Status s = root->AllowOnlyKeys({"image_size", "input", "photo_id"}); !s.ok()) return s;
  absl::StatusOr<std::array<int, 2>> size = ImageSize(*root);
  if (!size.ok()) return size.status();
  absl::StatusOr<std::string> photo_id = root->StringOr("photo_id", "");
  if (!photo_id.ok()) return photo_id.status();
  if (!photo_id->empty()) {
    if (absl::Status s = CheckPhotoSize(photos, *photo_id, *size, *root); !s.ok()) return s;
  }
  absl::StatusOr<JsonField> input = root->Object("input");
  if (!input.ok()) return input.status();
  absl::StatusOr<SolvedRequest> solved = Solve(*input, *size);
  if (!photo_id->empty()) {
    // The bird's-eye view follows the latest solve, and shows nothing after a refused one.
    absl::StatusOr<int> solve = photos.SetSolution(
        *photo_id,
        solved.ok() ? std::optional(AftersaleSolution{solved->in, solved->result}) : std::nullopt);
    if (!solve.ok()) return solve.status();
    if (solved.ok()) {
      solved->answer["birdseye"] =
          absl::StrCat("/api/aftersale/photos/", *photo_id, "/birdseye.png?solve=", *solve);
    }
  }
  if (!solved.ok()) return solved.status();
  return std::move(solved->answer);
}

}  // namespace linecal

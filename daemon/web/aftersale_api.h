#pragma once
// The after-sale page's API (docs/console.md, "After-sale"): what a workshop technician's
// browser asks linecald for while placing lane points on a photo of a car's camera. The
// computations are station/aftersale's and station/solvers/lane_calibration's, the same as
// `linecal aftersale` (docs/aftersale.md), so the page shows the command's numbers and exports
// its bytes. Nothing here reads or changes the station's state: the calls are open to every
// console role. Functions of their arguments, without HTTP (web_server.cc routes them); the
// only state is the uploaded photos and their latest solves in AftersalePhotos, kept for the
// bird's-eye view.

#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "daemon/web/aftersale_photos.h"
#include "station/model/car_model.h"

namespace linecal {

// The largest photo accepted, bytes. 32 MiB: a camera's PNG (1920x1080 RGB, at worst
// uncompressed, 6 MB) or a phone's JPEG (12-24 Mpx, 3-10 MB) fit with room; more is not a
// photo of a car's camera.
inline constexpr std::int64_t kMaxPhotoBytes = std::int64_t{32} << 20;
// The most pixels of a photo, from its header before decoding. 25 Mpx: a 24 Mpx camera's
// photo; decoding one takes about 7 bytes a pixel (image_io.h), 175 MB.
inline constexpr std::int64_t kMaxPhotoPixels = 25'000'000;
// Photos decoded at once in the daemon; one more is refused (Unavailable) rather than queued,
// so that uploads neither hold the server's threads nor add up in memory (2 x 175 MB).
inline constexpr int kMaxPhotoDecodes = 2;
// The largest JSON request of POST /api/aftersale, bytes: a request with a hundred points is
// about 5 KB.
inline constexpr std::int64_t kMaxAftersaleRequestBytes = std::int64_t{1} << 20;
// Straight segments a drawn line is cut into in the page's overlay (station/aftersale/
// overlay.h): smooth at a screen's resolution, a fifth of the command's PNG overlay's points.
inline constexpr int kPageOverlaySegments = 40;

// POST /api/aftersale/photo: the upload's bytes decoded as `linecal aftersale` reads an image
// (PNG or JPEG by its signature, station/io/image_io.h), under kMaxPhotoBytes and
// kMaxPhotoPixels, and kept in `photos`. Answer {"width", "height", "photo_id"}: the image
// size the solve needs (the page draws the photo itself) and the photo's id in `photos` for the
// bird's-eye view. InvalidArgument "photo: not a PNG or JPEG file", "photo: empty", "photo:
// N pixels exceed the budget ...", a corrupt file's message; Unavailable when kMaxPhotoDecodes
// decodes are running. Cost: one decode.
absl::StatusOr<nlohmann::json> AftersalePhotoJson(std::string_view bytes, AftersalePhotos& photos);

// GET /api/aftersale/cameras: {"cameras": [{car_model_id, camera, image_size: [w, h], input}]}
// for every camera with intrinsics of the station's car models, in their order; `input` is the
// input document's camera part at the nominal mounting (AftersaleCameraInput: intrinsics,
// camera_height_m, offsets, looking_backward, tolerance_percent), and max_photo_bytes
// (kMaxPhotoBytes), so that the page refuses a larger photo before sending it.
nlohmann::json AftersaleCamerasJson(const std::vector<CarModel>& cars);

// POST /api/aftersale: the body {"image_size": [w, h], "input": {...}} where input is the
// document of `linecal aftersale --input` without `image` (docs/aftersale.md, "Input").
// Answer {"result": AftersaleResultJson (what --json prints but the file names), "overlay":
// {ground_grid, horizon, lane_lines: polylines of [u, v] or null at a gap, rounded to 0.01 px;
// vanishing_point: [u, v] or null}, "export": [{"file", "text"}] (the three files of --export,
// their text byte for byte)}. InvalidArgument with the command's message for bad input or a
// refused calibration ("parallel lines: ...", "lanes[0][0] (...) is above the horizon: ...");
// JSON errors name "request". With "photo_id" (of AftersalePhotoJson) the solve is recorded
// as that photo's latest (a refused one clears it) and the answer has "birdseye": the path of
// its bird's-eye PNG (GET /api/aftersale/photos/ID/birdseye.png?solve=N); NotFound when the
// photo is not kept, InvalidArgument when image_size is not its size. Cost: the solve,
// O(points), and the overlay, O(lines).
absl::StatusOr<nlohmann::json> AftersaleSolveJson(std::string_view body, AftersalePhotos& photos);

}  // namespace linecal

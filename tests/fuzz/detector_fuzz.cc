// Fuzzes one camera board detector through DetectBoard (LINECAL_FUZZ_BOARD: the BoardType
// enumerator, one target per board). Input byte 0 picks what the detector is given:
//   even: a render of the board (made once, in the simulator) with the remaining bytes XORed
//         in from the pixel offset given by bytes 1-3, so mutations land on the board's
//         features, its edges and the background alike and reach refinement and verification;
//         bit 2 of byte 0 picks the board far away (its page over 17% of the width: the
//         marker boards' cells about 4 px, where their sides are fitted to the page model);
//   odd:  bytes 1-4 give width, height and stride padding (bit 1 of byte 0: 16-bit pixels),
//         the rest the pixels, repeated to fill the view: odd sizes, tiny images, strides,
//         flat and noisy images.
// Invariants: no crash; a found board has every feature a camera sees; features are ordered by id,
// of this board, finite and inside the image; the reason is kNone exactly when found.
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"
#include "detectors/core/pose.h"
#include "detectors/detect.h"
#include "station/camera/camera_model.h"
#include "station/model/station_layout.h"
#include "station/sim/camera_render.h"

namespace {

using linecal::Board;
using linecal::BoardType;

constexpr BoardType kType = static_cast<BoardType>(LINECAL_FUZZ_BOARD);
// A quarter of the test scenes' 1280 x 720 camera: detection stays fast enough for
// thousands of inputs a second, and every board still has features of several pixels.
constexpr int kWidth = 640;
constexpr int kHeight = 360;
constexpr double kFocalPx = 500.0;

const Board& TheBoard() {
  static const Board board = [] {
    linecal::BoardParams p;
    p.type = kType;
    return *Board::Create(p);
  }();
  return board;
}

// The board upright and a little turned, 1.5 m up, at the distance where its page spans
// `width_fraction` of the image width.
linecal::Image8 Render(double width_fraction) {
  linecal::CameraIntrinsics c;
  c.type = linecal::CameraModelType::kPinhole;
  c.width = kWidth;
  c.height = kHeight;
  c.fx = c.fy = kFocalPx;
  c.cx = (kWidth - 1) / 2.0;
  c.cy = (kHeight - 1) / 2.0;
  const linecal::CameraModel camera = *linecal::CameraModel::Create(c);
  const linecal::Rigid3d T_station_camera(
      linecal::RotationFromYawPitchRoll({0.0, 0.0, 0.0}) * linecal::CameraBaseRotation(),
      Eigen::Vector3d(0.0, 0.0, 1.5));
  const Eigen::Vector2d page = TheBoard().page_size_m();
  const double distance_m = kFocalPx * page.x() / (width_fraction * kWidth);
  // Upright, print facing the camera (-x), turned 10 degrees about its vertical axis.
  Eigen::Matrix3d base;
  base.col(0) = -Eigen::Vector3d::UnitY();
  base.col(1) = Eigen::Vector3d::UnitZ();
  base.col(2) = -Eigen::Vector3d::UnitX();
  linecal::StationBoard b;
  b.id = "board";
  b.params = TheBoard().params();
  b.board = TheBoard();
  b.T_station_board = linecal::Rigid3d(linecal::MountingRotation({0.17, 0.05, 0.08}, base),
                                       Eigen::Vector3d(distance_m, 0.0, 1.5));
  linecal::StationLayout layout;
  layout.name = "fuzz";
  layout.boards.push_back(b);
  linecal::CameraRenderOptions options;
  options.blur_sigma_px = 0.7;
  options.noise_sigma = 2.0;
  return linecal::RenderCameraFrame(camera, T_station_camera, layout, options, 1)->image8;
}

void Check(const linecal::Detection& d, int width, int height) {
  const Board& board = TheBoard();
  if (d.found != (d.reason == linecal::DetectReason::kNone)) __builtin_trap();
  // A found board has every feature a camera sees (the round-hole board's hole centres are
  // the LiDAR's).
  const auto seen = std::count_if(
      board.features().begin(), board.features().end(),
      [](const linecal::BoardFeature& f) { return f.kind != linecal::FeatureKind::kHoleCentre; });
  if (d.found && static_cast<std::ptrdiff_t>(d.features.size()) != seen) __builtin_trap();
  int last_id = -1;
  for (const linecal::DetectedFeature& f : d.features) {
    if (f.id <= last_id || f.id >= static_cast<int>(board.features().size())) __builtin_trap();
    last_id = f.id;
    if (!std::isfinite(f.uv_px.x()) || !std::isfinite(f.uv_px.y())) __builtin_trap();
    if (f.uv_px.x() < -0.5 || f.uv_px.y() < -0.5 || f.uv_px.x() > width - 0.5 ||
        f.uv_px.y() > height - 0.5) {
      __builtin_trap();
    }
  }
}

void FuzzRender(const std::uint8_t* data, std::size_t size) {
  static const linecal::Image8 near = Render(0.7);
  static const linecal::Image8 far = Render(0.17);
  linecal::Image8 image = (data[0] & 4) != 0 ? far : near;
  if (size >= 4) {
    const std::size_t n = image.pixels.size();
    const std::size_t offset = (data[1] | data[2] << 8 | data[3] << 16) % n;
    for (std::size_t i = 4; i < size; ++i) image.pixels[(offset + i - 4) % n] ^= data[i];
  }
  const std::optional<linecal::Detection> d = linecal::DetectBoard(image.view(), TheBoard());
  if (!d) __builtin_trap();  // every board type has an image detector
  Check(*d, image.width, image.height);
}

template <typename T>
void FuzzRaw(const std::uint8_t* data, std::size_t size) {
  // Up to 255 x 255 pixels with up to 15 pixels of padding a row: small enough to run fast,
  // large enough for the smallest boards.
  const int width = data[1];
  const int height = data[2];
  const int pad = data[3] % 16;
  const std::size_t stride = static_cast<std::size_t>(width + pad);
  std::vector<T> pixels(std::max<std::size_t>(1, stride * height));
  const std::uint8_t* body = data + 4;
  const std::size_t body_size = size - 4;
  for (std::size_t i = 0; i < pixels.size(); ++i) {
    std::uint8_t bytes[sizeof(T)] = {};
    for (std::size_t k = 0; k < sizeof(T) && body_size > 0; ++k) {
      bytes[k] = body[(i * sizeof(T) + k) % body_size];
    }
    std::memcpy(&pixels[i], bytes, sizeof(T));
  }
  linecal::ImageView<T> view{pixels.data(), width, height,
                             static_cast<std::ptrdiff_t>(stride * sizeof(T))};
  const std::optional<linecal::Detection> d = linecal::DetectBoard(view, TheBoard());
  if (!d) __builtin_trap();
  if (view.Validate() != linecal::ImageViewError::kOk &&
      d->reason != linecal::DetectReason::kBadImage) {
    __builtin_trap();
  }
  Check(*d, width, height);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  if (data[0] % 2 == 0) {
    FuzzRender(data, size);
  } else if (size >= 4) {
    if (data[0] & 2) {
      FuzzRaw<std::uint16_t>(data, size);
    } else {
      FuzzRaw<std::uint8_t>(data, size);
    }
  }
  return 0;
}

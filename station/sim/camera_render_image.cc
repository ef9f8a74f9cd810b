#include <algorithm>
#include <array>
#include <atomic>
#include <cstdint>
#include <optional>
#include <thread>
#include <utility>
#include <vector>

#include "station/sim/camera_render_internal.h"

namespace linecal::camera_render_internal {
namespace {

// ------------------------------------------------------------------------------------------
// Rendering the linear image.

// Rows of pixels handed out at a time: work is spread evenly whatever the scene, and each
// band recomputes one corner row (1/16 extra).
constexpr int kBandRows = 16;

class LinearRenderer {
 public:
  LinearRenderer(const CameraModel& camera, const Scene& scene, const CameraRenderOptions& options)
      : camera_(camera),
        scene_(scene),
        options_(options),
        grid_(RayGrid::Build(camera)),
        candidates_(grid_, scene),
        width_(camera.intrinsics().width),
        height_(camera.intrinsics().height) {}

  // Mean reflectance per pixel, row-major.
  std::vector<float> Render() const {
    std::vector<float> image(static_cast<std::size_t>(width_) * height_);
    // Bands go to whichever thread is free; a band's pixels are computed the same way
    // whichever thread takes it.
    const int bands = (height_ + kBandRows - 1) / kBandRows;
    std::atomic<int> next{0};
    const auto work = [&] {
      PixelIntegrator integrator(scene_, options_);
      std::vector<CornerSample> upper(width_ + 1), lower(width_ + 1);
      for (int band = next++; band < bands; band = next++) {
        const int y0 = band * kBandRows, y1 = std::min(height_, y0 + kBandRows);
        CornerRow(y0, &upper);
        for (int y = y0; y < y1; ++y) {
          CornerRow(y + 1, &lower);
          float* row = image.data() + static_cast<std::size_t>(y) * width_;
          for (int x = 0; x < width_; ++x) {
            row[x] = static_cast<float>(Pixel(x, y, &upper, &lower, &integrator));
          }
          std::swap(upper, lower);
        }
      }
    };
    const int threads = std::min(options_.threads, bands);
    std::vector<std::thread> pool;
    for (int i = 1; i < threads; ++i) pool.emplace_back(work);
    work();
    for (std::thread& t : pool) t.join();
    return image;
  }

 private:
  void Trace(int x, int y, CornerSample* c) const {
    if (!c->valid) return;
    const auto [candidates, n] = candidates_.At(x, y);
    c->hit = scene_.Trace(c->ray, candidates, n);
  }

  // The rays and hits of pixel-corner row y (v = y - 0.5).
  void CornerRow(int y, std::vector<CornerSample>* row) const {
    for (int x = 0; x <= width_; ++x) {
      CornerSample& c = (*row)[x];
      grid_.CornerRay(x, y, &c.ray, &c.error_px, &c.valid);
      Trace(x, y, &c);
    }
  }

  // The reflectance of the whole pixel if it is flat: its corners see one look, the surface
  // is uniform over the footprint (grown by the corners' ray errors), and nothing else
  // shows in between: every other surface lies behind, or the centre sees the same look.
  std::optional<double> Flat(const std::array<CornerSample*, 4>& c, const std::uint32_t* candidates,
                             int n) const {
    const std::uint64_t label = c[0]->hit.look.label;
    for (int k = 1; k < 4; ++k) {
      if (c[k]->hit.look.label != label) return std::nullopt;
    }
    const int s = c[0]->hit.surface;
    if (s >= 0) {
      const double error_px =
          std::max({c[0]->error_px, c[1]->error_px, c[2]->error_px, c[3]->error_px});
      if (!scene_.UniformOver(
              scene_.surfaces()[s],
              {c[0]->hit.p_surface, c[1]->hit.p_surface, c[2]->hit.p_surface, c[3]->hit.p_surface},
              error_px)) {
        return std::nullopt;
      }
    }
    if (!InFrontOverPixel(scene_, c, candidates, n)) {
      const Eigen::Vector3d centre = c[0]->ray + c[1]->ray + c[2]->ray + c[3]->ray;
      if (scene_.Trace(centre, candidates, n).look.label != label) return std::nullopt;
    }
    return c[0]->hit.look.reflectance;
  }

  double Pixel(int x, int y, std::vector<CornerSample>* upper, std::vector<CornerSample>* lower,
               PixelIntegrator* integrator) const {
    const std::array<CornerSample*, 4> c = {&(*upper)[x], &(*upper)[x + 1], &(*lower)[x],
                                            &(*lower)[x + 1]};
    const auto [candidates, n] = candidates_.At(x, y);
    if (c[0]->valid && c[1]->valid && c[2]->valid && c[3]->valid) {
      if (const std::optional<double> flat = Flat(c, candidates, n)) return *flat;
      // An edge pixel: exact corner rays (kept for the neighbours that share them).
      const std::array<std::array<int, 2>, 4> xy = {
          {{x, y}, {x + 1, y}, {x, y + 1}, {x + 1, y + 1}}};
      bool refined = false;
      for (int k = 0; k < 4; ++k) {
        if (c[k]->error_px == 0.0) continue;
        c[k]->valid = grid_.ExactCornerRay(xy[k][0], xy[k][1], &c[k]->ray);
        c[k]->error_px = 0.0;
        Trace(xy[k][0], xy[k][1], c[k]);
        refined = true;
      }
      if (c[0]->valid && c[1]->valid && c[2]->valid && c[3]->valid) {
        if (refined) {
          if (const std::optional<double> flat = Flat(c, candidates, n)) return *flat;
        }
        return integrator->Integrate(c, candidates, n);
      }
    }
    // On the rim of the lens's valid region: the centre ray alone, black outside.
    Eigen::Vector3d ray;
    if (!camera_.Unproject(Eigen::Vector2d(x, y), &ray)) return 0.0;
    return scene_.Trace(ray, candidates, n).look.reflectance;
  }

  const CameraModel& camera_;
  const Scene& scene_;
  const CameraRenderOptions& options_;
  const RayGrid grid_;
  const TileCandidates candidates_;
  const int width_;
  const int height_;
};

}  // namespace

std::vector<float> RenderLinearImage(const CameraModel& camera, const Scene& scene,
                                     const CameraRenderOptions& options) {
  return LinearRenderer(camera, scene, options).Render();
}

}  // namespace linecal::camera_render_internal

#include "detectors/common/paint_check.h"

#include <array>
#include <cmath>

#include "detectors/common/homography.h"

namespace linecal {
namespace {

// Probes per side of the board's page for the paint check: a 1100 mm board gets a probe
// every 34 mm, several per printed area of any of the marker boards.
constexpr int kPaintProbesPerSide = 32;
// A paint probe is used only when the board is uniform this many pixels around it (blur of
// up to 1.5 px, plus the homography's error, must not reach an edge).
constexpr double kPaintProbeClearancePx = 3.0;
// Fewer probes of a paint than this say nothing about it.
constexpr int kMinPaintProbes = 8;

}  // namespace

bool PaintAgrees(const Board& board, const Eigen::Matrix3d& H_image_board, const Image8& dark,
                 double px_per_m, double min_agreement) {
  const Eigen::Vector2d page = board.page_size_m();
  const double clearance_m = kPaintProbeClearancePx / px_per_m;
  std::array<int, 2> total = {0, 0};  // white, black
  std::array<int, 2> agree = {0, 0};
  for (int iy = 0; iy < kPaintProbesPerSide; ++iy) {
    for (int ix = 0; ix < kPaintProbesPerSide; ++ix) {
      const Eigen::Vector2d p(page.x() * ((ix + 0.5) / kPaintProbesPerSide - 0.5),
                              page.y() * ((iy + 0.5) / kPaintProbesPerSide - 0.5));
      const Paint paint = board.PaintAt(p);
      if (paint != Paint::kWhite && paint != Paint::kBlack) continue;
      bool uniform = true;
      for (int k = 0; k < 4 && uniform; ++k) {
        const Eigen::Vector2d q(p.x() + ((k & 1) ? clearance_m : -clearance_m),
                                p.y() + ((k & 2) ? clearance_m : -clearance_m));
        uniform = board.PaintAt(q) == paint;
      }
      if (!uniform) continue;
      const Eigen::Vector2d uv = ApplyHomography(H_image_board, p);
      if (!(uv.x() >= 0.0 && uv.y() >= 0.0 && uv.x() <= dark.width - 1.0 &&
            uv.y() <= dark.height - 1.0)) {
        continue;
      }
      const bool is_dark = dark.at(static_cast<int>(std::lround(uv.x())),
                                   static_cast<int>(std::lround(uv.y()))) != 0;
      const int k = paint == Paint::kBlack ? 1 : 0;
      ++total[k];
      if (is_dark == (k == 1)) ++agree[k];
    }
  }
  for (int k = 0; k < 2; ++k) {
    if (total[k] >= kMinPaintProbes && agree[k] < min_agreement * total[k]) return false;
  }
  return total[0] + total[1] >= kMinPaintProbes;
}

}  // namespace linecal

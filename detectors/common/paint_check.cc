#include "detectors/common/paint_check.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <utility>
#include <vector>

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

bool PaintContrastPrefers(const Board& board, const Board& other, const Eigen::Matrix3d& H_image_board,
                          const ImageView8& image, double px_per_m, double min_share) {
  // Denser and closer to the edges than PaintAgrees: the areas where sibling boards differ
  // can be small (the round-hole board's black rings), and each vote compares two points
  // under the same blur, so 2 px of clearance are enough.
  constexpr int kProbes = 64;
  constexpr double kClearancePx = 2.0;
  const Eigen::Vector2d page = board.page_size_m();
  const double clearance_m = kClearancePx / px_per_m;
  // A probe's paint on a board when it is the same kClearancePx around it, else kOffBoard.
  const auto clear_paint = [&](const Board& b, const Eigen::Vector2d& p) {
    const Paint paint = b.PaintAt(p);
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector2d q(p.x() + ((k & 1) ? clearance_m : -clearance_m),
                              p.y() + ((k & 2) ? clearance_m : -clearance_m));
      if (b.PaintAt(q) != paint) return Paint::kOffBoard;
    }
    return paint;
  };
  // Per grid probe: the grey where both boards print white (-1 elsewhere), and the probes
  // where they differ with whether `board` prints black there.
  std::vector<double> white_grey(kProbes * kProbes, -1.0);
  std::vector<std::pair<int, bool>> differing;  // grid index, board prints black
  std::vector<double> differing_grey;
  for (int iy = 0; iy < kProbes; ++iy) {
    for (int ix = 0; ix < kProbes; ++ix) {
      const Eigen::Vector2d p(page.x() * ((ix + 0.5) / kProbes - 0.5), page.y() * ((iy + 0.5) / kProbes - 0.5));
      const Paint a = clear_paint(board, p);
      const Paint b = clear_paint(other, p);
      const bool both_white = a == Paint::kWhite && b == Paint::kWhite;
      const bool differ = (a == Paint::kBlack && b == Paint::kWhite) || (a == Paint::kWhite && b == Paint::kBlack);
      if (!both_white && !differ) continue;
      const Eigen::Vector2d uv = ApplyHomography(H_image_board, p);
      if (!(uv.x() >= 0.0 && uv.y() >= 0.0 && uv.x() <= image.width - 1.0 && uv.y() <= image.height - 1.0)) continue;
      const double grey = image.At(static_cast<int>(std::lround(uv.x())), static_cast<int>(std::lround(uv.y())));
      if (both_white) {
        white_grey[iy * kProbes + ix] = grey;
      } else {
        differing.emplace_back(iy * kProbes + ix, a == Paint::kBlack);
        differing_grey.push_back(grey);
      }
    }
  }
  // The nearest both-white probe, searched ring by ring out to 15% of the page.
  const int reach = static_cast<int>(std::ceil(0.15 * kProbes));
  int votes = 0;
  int for_board = 0;
  for (std::size_t i = 0; i < differing.size(); ++i) {
    const int ix = differing[i].first % kProbes;
    const int iy = differing[i].first / kProbes;
    double reference = -1.0;
    int best_d2 = reach * reach + 1;
    for (int r = 1; r <= reach && reference < 0.0; ++r) {
      for (int dy = -r; dy <= r; ++dy) {
        for (int dx = -r; dx <= r; ++dx) {
          if (std::max(std::abs(dx), std::abs(dy)) != r) continue;  // this ring only
          const int x = ix + dx, y = iy + dy;
          if (x < 0 || y < 0 || x >= kProbes || y >= kProbes) continue;
          const double g = white_grey[y * kProbes + x];
          if (g >= 0.0 && dx * dx + dy * dy < best_d2) {
            best_d2 = dx * dx + dy * dy;
            reference = g;
          }
        }
      }
    }
    if (reference < 0.0) continue;
    // Printed black reflects a tenth of white or less; under any gamma of 0.6-1.6 it stays
    // below 60% of the white beside it, while white beside white is near 100%.
    const bool dark = differing_grey[i] < 0.6 * reference;
    ++votes;
    if (dark == differing[i].second) ++for_board;
  }
  return votes >= kMinPaintProbes && for_board >= min_share * votes;
}

}  // namespace linecal

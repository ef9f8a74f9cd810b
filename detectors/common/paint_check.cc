#include "detectors/common/paint_check.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <utility>
#include <vector>

#include "detectors/common/homography.h"

namespace linecal {
namespace {

// Probes per side of the board's page for the paint check: a 1100 mm board gets a probe
// every 34 mm, several per printed area of any of the marker boards.
constexpr int kPaintProbesPerSide = 32;
// A paint probe is used only when the board is uniform this many pixels around it. Blur of
// up to 1.5 px still mixes in a quarter of the other paint 1.5 px from an edge, which keeps
// black below 0.35 of white (kBlackToWhiteMax is 0.6); more clearance would leave no black
// probe in the 6 px squares of a small chessboard seen 50 degrees off axis.
constexpr double kPaintProbeClearancePx = 1.5;
// Fewer probes of a paint than this say nothing about it.
constexpr int kMinPaintProbes = 8;
// A probe is compared with probes at most this share of the page away: near enough to share
// the light (a 4:1 gradient across the page changes it by at most 4^0.15 = 1.23 over that
// distance), far enough to reach the next area of other paint on every board of docs/boards.md.
constexpr double kPaintNeighbourReach = 0.15;
// Printed black reflects a tenth of white or less; under any gamma of 0.6-1.6 it stays below
// 60% of the white beside it, while white beside white is near 100%.
constexpr double kBlackToWhiteMax = 0.6;
// PaintAgrees compares each probe with this many nearest probes of the opposite paint. One is
// fooled by a board identified on a larger checker (a white probe on a black square paired
// with a black probe on a white one); four make a probe agree only when its whole
// neighbourhood has the printed contrast.
constexpr int kPaintComparisons = 4;

// VisiblePaintAgrees: disagreeing probes this many grid steps apart (Chebyshev) are one hidden
// area; a gap of one probe between them is an occluder's white next to the page's.
constexpr int kHiddenGapProbes = 2;

// Up to `count` probes of a side x side grid nearest to probe `from` (Euclidean distance in
// probe steps, at most `reach`) for which `wanted(index)` holds, nearest first; ties in the
// grid's order. O(reach^2 + count log count).
template <typename Wanted>
std::vector<int> NearestProbes(int side, int from, int reach, int count, const Wanted& wanted) {
  const int ix = from % side, iy = from / side;
  std::vector<std::pair<int, int>> found;  // distance², index
  for (int dy = -reach; dy <= reach; ++dy) {
    for (int dx = -reach; dx <= reach; ++dx) {
      const int x = ix + dx, y = iy + dy;
      if ((dx == 0 && dy == 0) || x < 0 || y < 0 || x >= side || y >= side) continue;
      if (dx * dx + dy * dy > reach * reach || !wanted(y * side + x)) continue;
      found.emplace_back(dx * dx + dy * dy, y * side + x);
    }
  }
  const std::size_t n = std::min<std::size_t>(count, found.size());
  std::partial_sort(found.begin(), found.begin() + n, found.end());
  std::vector<int> out(n);
  for (std::size_t i = 0; i < n; ++i) out[i] = found[i].second;
  return out;
}

BoardToImage ThroughHomography(const Eigen::Matrix3d& H_image_board) {
  return [H_image_board](const Eigen::Vector2d& p) -> std::optional<Eigen::Vector2d> {
    return ApplyHomography(H_image_board, p);
  };
}

// The board point of PaintAgrees's grid probe (ix, iy): the centres of a grid over the page.
Eigen::Vector2d ProbeOnPage(const Eigen::Vector2d& page, int ix, int iy) {
  return Eigen::Vector2d(page.x() * ((ix + 0.5) / kPaintProbesPerSide - 0.5),
                         page.y() * ((iy + 0.5) / kPaintProbesPerSide - 0.5));
}

// PaintAgrees's vote of one grid probe.
enum class ProbeVote : std::uint8_t { kNone, kAgree, kDisagree };

struct PaintVotes {
  std::vector<Paint> paint;  // per grid probe; kOffBoard where it is not used
  std::vector<ProbeVote> vote;
};

// Every probe of PaintAgrees's grid compared with its nearest probes of the opposite paint.
PaintVotes VotePaint(const Board& board, const BoardToImage& to_image, const ImageView8& image,
                     double px_per_m) {
  const Eigen::Vector2d page = board.page_size_m();
  const double clearance_m = kPaintProbeClearancePx / px_per_m;
  constexpr int kCount = kPaintProbesPerSide * kPaintProbesPerSide;
  PaintVotes votes{std::vector<Paint>(kCount, Paint::kOffBoard),
                   std::vector<ProbeVote>(kCount, ProbeVote::kNone)};
  std::vector<double> grey(kCount, 0.0);
  for (int iy = 0; iy < kPaintProbesPerSide; ++iy) {
    for (int ix = 0; ix < kPaintProbesPerSide; ++ix) {
      const Eigen::Vector2d p = ProbeOnPage(page, ix, iy);
      const Paint here = board.PaintAt(p);
      if (here != Paint::kWhite && here != Paint::kBlack) continue;
      bool uniform = true;
      for (int k = 0; k < 4 && uniform; ++k) {
        const Eigen::Vector2d q(p.x() + ((k & 1) ? clearance_m : -clearance_m),
                                p.y() + ((k & 2) ? clearance_m : -clearance_m));
        uniform = board.PaintAt(q) == here;
      }
      if (!uniform) continue;
      const std::optional<Eigen::Vector2d> mapped = to_image(p);
      if (!mapped.has_value()) continue;
      const Eigen::Vector2d uv = *mapped;
      if (!(uv.x() >= 0.0 && uv.y() >= 0.0 && uv.x() <= image.width - 1.0 &&
            uv.y() <= image.height - 1.0)) {
        continue;
      }
      const int i = iy * kPaintProbesPerSide + ix;
      votes.paint[i] = here;
      grey[i] =
          image.At(static_cast<int>(std::lround(uv.x())), static_cast<int>(std::lround(uv.y())));
    }
  }
  const int reach = static_cast<int>(std::ceil(kPaintNeighbourReach * kPaintProbesPerSide));
  for (int i = 0; i < kCount; ++i) {
    if (votes.paint[i] == Paint::kOffBoard) continue;
    const Paint opposite = votes.paint[i] == Paint::kBlack ? Paint::kWhite : Paint::kBlack;
    const std::vector<int> near = NearestProbes(kPaintProbesPerSide, i, reach, kPaintComparisons,
                                                [&](int k) { return votes.paint[k] == opposite; });
    if (near.empty()) continue;
    const bool black_here = votes.paint[i] == Paint::kBlack;
    // Against every neighbour: one black-printed neighbour that is as bright as a white probe
    // (or one white-printed neighbour as dark as a black probe) is paint the board does not
    // have there.
    const bool agrees = std::all_of(near.begin(), near.end(), [&](int j) {
      const double black = black_here ? grey[i] : grey[j];
      const double white = black_here ? grey[j] : grey[i];
      return black < kBlackToWhiteMax * white;
    });
    votes.vote[i] = agrees ? ProbeVote::kAgree : ProbeVote::kDisagree;
  }
  return votes;
}

// PaintAgrees's test over the votes.
bool VotesAgree(const PaintVotes& votes, double min_agreement) {
  std::array<int, 2> total = {0, 0};  // white probes, black probes with neighbours to compare
  std::array<int, 2> agree = {0, 0};
  for (std::size_t i = 0; i < votes.vote.size(); ++i) {
    if (votes.vote[i] == ProbeVote::kNone) continue;
    const int kind = votes.paint[i] == Paint::kBlack ? 1 : 0;
    ++total[kind];
    agree[kind] += votes.vote[i] == ProbeVote::kAgree;
  }
  for (int k = 0; k < 2; ++k) {
    if (total[k] >= kMinPaintProbes && agree[k] < min_agreement * total[k]) return false;
  }
  return total[0] + total[1] >= kMinPaintProbes;
}

}  // namespace

bool PaintAgrees(const Board& board, const Eigen::Matrix3d& H_image_board, const ImageView8& image,
                 double px_per_m, double min_agreement) {
  return PaintAgrees(board, ThroughHomography(H_image_board), image, px_per_m, min_agreement);
}

bool PaintAgrees(const Board& board, const BoardToImage& to_image, const ImageView8& image,
                 double px_per_m, double min_agreement) {
  return VotesAgree(VotePaint(board, to_image, image, px_per_m), min_agreement);
}

bool VisiblePaintAgrees(const Board& board, const BoardToImage& to_image, const ImageView8& image,
                        double px_per_m, double min_agreement, const BoardRegion& seen) {
  PaintVotes votes = VotePaint(board, to_image, image, px_per_m);
  if (VotesAgree(votes, min_agreement)) return true;
  const Eigen::Vector2d page = board.page_size_m();
  constexpr int n = kPaintProbesPerSide;
  // Groups of disagreeing probes, joined across gaps (an occluder's own white agrees with the
  // page's here and there).
  std::vector<bool> grouped(votes.vote.size(), false);
  for (int start = 0; start < n * n; ++start) {
    if (votes.vote[start] != ProbeVote::kDisagree || grouped[start]) continue;
    std::vector<int> members = {start};
    grouped[start] = true;
    bool rim = false;
    bool holds_seen = false;
    for (std::size_t m = 0; m < members.size(); ++m) {
      const int ix = members[m] % n, iy = members[m] / n;
      rim = rim || ix == 0 || iy == 0 || ix == n - 1 || iy == n - 1;
      holds_seen = holds_seen || seen(ProbeOnPage(page, ix, iy));
      for (int dy = -kHiddenGapProbes; dy <= kHiddenGapProbes; ++dy) {
        for (int dx = -kHiddenGapProbes; dx <= kHiddenGapProbes; ++dx) {
          const int x = ix + dx, y = iy + dy;
          if (x < 0 || y < 0 || x >= n || y >= n) continue;
          const int k = y * n + x;
          if (votes.vote[k] != ProbeVote::kDisagree || grouped[k]) continue;
          grouped[k] = true;
          members.push_back(k);
        }
      }
    }
    // Reaching in from the rim and clear of everything the detector read: hidden, no vote.
    if (rim && !holds_seen) {
      for (int k : members) votes.vote[k] = ProbeVote::kNone;
    }
  }
  return VotesAgree(votes, min_agreement);
}

bool PaintContrastPrefers(const Board& board, const Board& other,
                          const Eigen::Matrix3d& H_image_board, const ImageView8& image,
                          double px_per_m, double min_share) {
  return PaintContrastPrefers(board, other, ThroughHomography(H_image_board), image, px_per_m,
                              min_share);
}

bool PaintContrastPrefers(const Board& board, const Board& other, const BoardToImage& to_image,
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
      const Eigen::Vector2d p(page.x() * ((ix + 0.5) / kProbes - 0.5),
                              page.y() * ((iy + 0.5) / kProbes - 0.5));
      const Paint a = clear_paint(board, p);
      const Paint b = clear_paint(other, p);
      const bool both_white = a == Paint::kWhite && b == Paint::kWhite;
      const bool differ =
          (a == Paint::kBlack && b == Paint::kWhite) || (a == Paint::kWhite && b == Paint::kBlack);
      if (!both_white && !differ) continue;
      const std::optional<Eigen::Vector2d> mapped = to_image(p);
      if (!mapped.has_value()) continue;
      const Eigen::Vector2d uv = *mapped;
      if (!(uv.x() >= 0.0 && uv.y() >= 0.0 && uv.x() <= image.width - 1.0 &&
            uv.y() <= image.height - 1.0))
        continue;
      const double grey =
          image.At(static_cast<int>(std::lround(uv.x())), static_cast<int>(std::lround(uv.y())));
      if (both_white) {
        white_grey[iy * kProbes + ix] = grey;
      } else {
        differing.emplace_back(iy * kProbes + ix, a == Paint::kBlack);
        differing_grey.push_back(grey);
      }
    }
  }
  // Each differing probe against the nearest probe both print white.
  const int reach = static_cast<int>(std::ceil(kPaintNeighbourReach * kProbes));
  int votes = 0;
  int for_board = 0;
  for (std::size_t i = 0; i < differing.size(); ++i) {
    const std::vector<int> near = NearestProbes(kProbes, differing[i].first, reach, 1,
                                                [&](int k) { return white_grey[k] >= 0.0; });
    if (near.empty()) continue;
    const bool dark = differing_grey[i] < kBlackToWhiteMax * white_grey[near[0]];
    ++votes;
    if (dark == differing[i].second) ++for_board;
  }
  return votes >= kMinPaintProbes && for_board >= min_share * votes;
}

}  // namespace linecal

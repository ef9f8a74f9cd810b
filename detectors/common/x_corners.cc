#include "detectors/common/x_corners.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <deque>
#include <map>
#include <numbers>
#include <utility>

#include "detectors/common/homography.h"

namespace linecal {
namespace {

// Samples on the test ring: 32 gives 11.25 degree steps, fine enough to see sectors of
// 35 degrees (a square foreshortened by 50 degrees and rolled) as at least 3 samples.
constexpr int kRingSamples = 32;

// Links of the corner graph: the neighbour lies within 25 degrees of the edge direction
// and one of its own edge lines is within 25 degrees of the link. Perspective bends a
// board's lines between neighbouring vertices by far less; a wrong corner off the line
// by a quarter square is already 14 degrees off.
const double kCosLinkTolerance = std::cos(25.0 * 3.14159265358979 / 180.0);
// The dark axes of edge neighbours are perpendicular (bisectors of the same two lines);
// |cos| below 0.5 (60 degrees) allows for strong perspective.
constexpr double kMaxDarkAxisCos = 0.5;

struct RingResult {
  XCorner corner;
  bool ok = false;
  bool enough_contrast = false;  // passed the first test, the ring's contrast
};

// The unit direction of the doubled-angle mean of two line angles (radians), i.e. the
// average of two undirected directions.
Eigen::Vector2d MeanLine(double angle1, double angle2) {
  const double c = std::cos(2.0 * angle1) + std::cos(2.0 * angle2);
  const double s = std::sin(2.0 * angle1) + std::sin(2.0 * angle2);
  const double a = 0.5 * std::atan2(s, c);
  return Eigen::Vector2d(std::cos(a), std::sin(a));
}

RingResult TestRing(const ImageF& blurred, const Eigen::Vector2d& centre,
                    const XCornerOptions& options,
                    const std::array<Eigen::Vector2d, kRingSamples>& ring) {
  RingResult result;
  std::array<float, kRingSamples> v;
  float lo = 1e30f;
  float hi = -1e30f;
  for (int k = 0; k < kRingSamples; ++k) {
    const Eigen::Vector2d p = centre + options.ring_radius_px * ring[k];
    v[k] = SampleBilinear(blurred, p.x(), p.y());
    lo = std::min(lo, v[k]);
    hi = std::max(hi, v[k]);
  }
  const float contrast = hi - lo;
  if (contrast < options.min_contrast) return result;
  result.enough_contrast = true;
  const float mid = 0.5f * (hi + lo);
  std::array<double, 4> transitions;
  std::array<bool, 4> dark_after;  // the sector after transition i is dark
  int count = 0;
  for (int k = 0; k < kRingSamples; ++k) {
    const float a = v[k];
    const float b = v[(k + 1) % kRingSamples];
    if ((a > mid) != (b > mid)) {
      if (count == 4) return result;
      const double t = (mid - a) / (b - a);
      // Sample k sits at angle (k + 0.5) steps (see the ring below).
      transitions[count] = (k + 0.5 + t) * 2.0 * std::numbers::pi / kRingSamples;
      dark_after[count] = b <= mid;
      ++count;
    }
  }
  if (count != 4) return result;
  // Every sector spans at least two samples (22.5 degrees), and opposite samples agree
  // for at least 3/4 of the ring (a point-symmetric pattern; the misses are the samples
  // next to the four transitions).
  constexpr double kMinSectorRad = 2.0 * 2.0 * std::numbers::pi / kRingSamples;
  for (int i = 0; i < 4; ++i) {
    double span = transitions[(i + 1) % 4] - transitions[i];
    if (span < 0.0) span += 2.0 * std::numbers::pi;
    if (span < kMinSectorRad) return result;
  }
  int agree = 0;
  for (int k = 0; k < kRingSamples / 2; ++k) {
    agree += (v[k] > mid) == (v[k + kRingSamples / 2] > mid) ? 2 : 0;
  }
  constexpr int kMinAgreement = kRingSamples * 3 / 4;
  if (agree < kMinAgreement) return result;
  // The blurred vertex is the mean of its sectors: mid-grey where they are right angles, and
  // brighter where the dark sectors are acute (a board seen obliquely). Two dark corners
  // with a light gap between them, which also give four transitions, leave the vertex light
  // whatever the angles. 0.2 of the contrast allows for blur asymmetry.
  double dark_span = 0.0;
  for (int i = 0; i < 4; ++i) {
    if (!dark_after[i]) continue;
    double span = transitions[(i + 1) % 4] - transitions[i];
    if (span < 0.0) span += 2.0 * std::numbers::pi;
    dark_span += span;
  }
  const double expected_centre = hi - contrast * dark_span / (2.0 * std::numbers::pi);
  constexpr double kCentreTolerance = 0.2;
  const double centre_excess = SampleBilinear(blurred, centre.x(), centre.y()) - expected_centre;
  if (centre_excess < -kCentreTolerance * contrast ||
      (centre_excess > kCentreTolerance * contrast && !options.allow_light_centre)) {
    return result;
  }

  XCorner& c = result.corner;
  c.contrast = contrast;
  const double pi = std::numbers::pi;
  c.line_a = MeanLine(transitions[0], transitions[2] - pi);
  c.line_b = MeanLine(transitions[1], transitions[3] - pi);
  if (c.line_a.x() * c.line_b.y() - c.line_a.y() * c.line_b.x() < 0.0) c.line_b = -c.line_b;
  // The dark sectors start at the transitions with dark_after; bisect the first of them
  // and its opposite.
  const int i = dark_after[0] ? 0 : 1;
  double end = transitions[i + 1];
  if (end < transitions[i]) end += 2.0 * pi;
  const double mid_first = 0.5 * (transitions[i] + end);
  double start2 = transitions[i + 2];
  double end2 = transitions[(i + 3) % 4];
  if (end2 < start2) end2 += 2.0 * pi;
  c.dark_axis = MeanLine(mid_first, 0.5 * (start2 + end2) - pi);
  result.ok = true;
  return result;
}

// The saddle response R = Ixy^2 - Ixx Iyy, from central differences, computed row by row into
// a ring of kRingRows rows, enough for the 5 x 5 non-maximum suppression (an image-sized buffer
// would cost more in fresh pages than the arithmetic), with each row's maximum over 5 columns
// in a second ring.
class ResponseRows {
 public:
  static constexpr int kRingRows = 5;

  explicit ResponseRows(const ImageF& blurred)
      : blurred_(blurred),
        w_(blurred.width),
        h_(blurred.height),
        response_ring_(static_cast<std::size_t>(kRingRows) * w_, 0.0f),
        row_max_ring_(static_cast<std::size_t>(kRingRows) * w_, 0.0f) {}

  // Row y's response and 5-column maxima, once Compute(y) has run and until Compute(y + 5).
  const float* Response(int y) const {
    return response_ring_.data() + static_cast<std::size_t>(y % kRingRows) * w_;
  }
  const float* RowMax(int y) const {
    return row_max_ring_.data() + static_cast<std::size_t>(y % kRingRows) * w_;
  }

  // Computes row y (zero on the image's first and last rows and columns).
  void Compute(int y) {
    float* __restrict out = response_ring_.data() + static_cast<std::size_t>(y % kRingRows) * w_;
    float* __restrict out_max = row_max_ring_.data() + static_cast<std::size_t>(y % kRingRows) * w_;
    const int w = w_;
    if (y < 1 || y > h_ - 2) {
      std::fill(out, out + w, 0.0f);
      std::fill(out_max, out_max + w, 0.0f);
      return;
    }
    const float* up = blurred_.Row(y - 1);
    const float* row = blurred_.Row(y);
    const float* down = blurred_.Row(y + 1);
    out[0] = 0.0f;
    out[w - 1] = 0.0f;
    for (int x = 1; x < w - 1; ++x) {
      const float ixx = row[x - 1] - 2.0f * row[x] + row[x + 1];
      const float iyy = up[x] - 2.0f * row[x] + down[x];
      const float ixy = 0.25f * (down[x + 1] - down[x - 1] - up[x + 1] + up[x - 1]);
      out[x] = ixy * ixy - ixx * iyy;
    }
    // Columns 0, 1, w - 2, w - 1 are never a maximum's centre (margin >= 2).
    for (int x = 2; x < w - 2; ++x) {
      out_max[x] = std::max(
          std::max(std::max(out[x - 2], out[x - 1]), std::max(out[x], out[x + 1])), out[x + 2]);
    }
  }

 private:
  const ImageF& blurred_;
  int w_ = 0;
  int h_ = 0;
  std::vector<float> response_ring_;
  std::vector<float> row_max_ring_;
};

// True when the eight bytes at p are all zero.
bool NoneOfEight(const std::uint8_t* p) {
  std::uint64_t word;
  std::memcpy(&word, p, sizeof(word));
  return word == 0;
}

struct Peak {
  float r;
  int x;
  int y;
};

// Needs the blurred image (at least 5 x 5) and the options; gives the response's local maxima
// in a 5 x 5 neighbourhood (vertices of the smallest squares are 8 px apart) above the floor,
// far enough from the border for the ring, strongest first, at most max_candidates. Ties go
// to the first in raster order. The vectorised pass keeps the pixels above the floor that no
// neighbour exceeds (at most a few hundred); only those are checked for ties one by one.
std::vector<Peak> FindPeaks(const ImageF& blurred, const XCornerOptions& options) {
  const int w = blurred.width;
  const int h = blurred.height;
  // For an ideal X-corner of contrast C blurred to sigma, Ixy at the vertex is
  // C / (pi sigma^2); the floor takes half of that for min_contrast at sigma 2.5 px (detector
  // blur plus a camera blur of 1.5 px, the worst of docs/acceptance.md), so any printed
  // corner passes and flat noise does not.
  constexpr double kWorstSigmaPx = 2.5;
  const double ixy_floor =
      0.5 * options.min_contrast / (std::numbers::pi * kWorstSigmaPx * kWorstSigmaPx);
  const float floor = static_cast<float>(ixy_floor * ixy_floor);
  ResponseRows rows(blurred);
  std::vector<Peak> peaks;
  std::vector<std::uint8_t> candidate(w, 0);
  const int margin = std::max(2, static_cast<int>(std::ceil(options.ring_radius_px)) + 1);
  for (int y = margin - 2; y < std::min(h, margin + 2); ++y) rows.Compute(y);
  for (int y = margin; y < h - margin; ++y) {
    rows.Compute(y + 2);
    const float* row = rows.Response(y);
    const float* m0 = rows.RowMax(y - 2);
    const float* m1 = rows.RowMax(y - 1);
    const float* m2 = rows.RowMax(y);
    const float* m3 = rows.RowMax(y + 1);
    const float* m4 = rows.RowMax(y + 2);
    std::uint8_t* __restrict is_candidate = candidate.data();
    // `&`, not `&&`: without the branch the loop vectorises (scalar, this loop and the scan
    // below took most of FindPeaks' time).
    for (int x = margin; x < w - margin; ++x) {
      const float m = std::max(std::max(std::max(m0[x], m1[x]), std::max(m3[x], m4[x])), m2[x]);
      is_candidate[x] = static_cast<std::uint8_t>((row[x] >= floor) & (row[x] >= m));
    }
    for (int x = margin; x < w - margin; ++x) {
      // Eight flags at a time: candidates are a few hundred in a frame.
      if (x + 8 <= w - margin && NoneOfEight(is_candidate + x)) {
        x += 7;
        continue;
      }
      if (!is_candidate[x]) continue;
      const float r = row[x];
      bool is_max = true;
      for (int dy = -2; dy <= 0 && is_max; ++dy) {
        const float* other = rows.Response(y + dy);
        for (int dx = -2; dx <= (dy < 0 ? 2 : -1); ++dx) {
          if (other[x + dx] == r) {
            is_max = false;
            break;
          }
        }
      }
      if (is_max) peaks.push_back({r, x, y});
    }
  }
  std::sort(peaks.begin(), peaks.end(), [](const Peak& a, const Peak& b) { return a.r > b.r; });
  if (static_cast<int>(peaks.size()) > options.max_candidates) {
    peaks.resize(options.max_candidates);
  }
  return peaks;
}

// Needs the peaks; gives the X-corners among them: each passes the ring test at the peak or
// at its refined saddle, and is placed at the saddle. In the peaks' order.
std::vector<XCorner> TestPeaks(const ImageF& blurred, const XCornerOptions& options,
                               const std::vector<Peak>& peaks) {
  std::array<Eigen::Vector2d, kRingSamples> ring;
  for (int k = 0; k < kRingSamples; ++k) {
    const double a = (k + 0.5) * 2.0 * std::numbers::pi / kRingSamples;
    ring[k] = Eigen::Vector2d(std::cos(a), std::sin(a));
  }
  std::vector<XCorner> corners;
  for (const Peak& peak : peaks) {
    const Eigen::Vector2d start(peak.x, peak.y);
    RingResult ring_result = TestRing(blurred, start, options, ring);
    if (!ring_result.ok && !ring_result.enough_contrast) continue;
    const std::optional<Eigen::Vector2d> refined = RefineSaddle(blurred, start, options.saddle);
    if (!refined) continue;
    if (!ring_result.ok) {
      // The ring is point-symmetric about the vertex only. The integer peak is up to 0.7 px
      // off it, and from there a small ring sees the sectors of small or obliquely seen
      // squares unevenly: a 3 px ring on squares foreshortened to 7 px, or a 4 px ring whose
      // acute dark sectors of 25 degrees (1.7 px of arc) the offset hides. Tested again at
      // the saddle.
      ring_result = TestRing(blurred, *refined, options, ring);
      if (!ring_result.ok) continue;
    }
    ring_result.corner.uv_px = *refined;
    corners.push_back(ring_result.corner);
  }
  return corners;
}

// Needs X-corners; gives them by decreasing contrast, each one closer than kMergeDistancePx
// to a stronger one left out: two maxima converging to one vertex. 2 px is far below the
// smallest vertex spacing (8 px).
std::vector<XCorner> MergeDuplicates(std::vector<XCorner> corners) {
  std::sort(corners.begin(), corners.end(),
            [](const XCorner& a, const XCorner& b) { return a.contrast > b.contrast; });
  constexpr double kMergeDistancePx = 2.0;
  std::vector<XCorner> merged;
  for (const XCorner& c : corners) {
    bool duplicate = false;
    for (const XCorner& m : merged) {
      if ((m.uv_px - c.uv_px).squaredNorm() < kMergeDistancePx * kMergeDistancePx) {
        duplicate = true;
        break;
      }
    }
    if (!duplicate) merged.push_back(c);
  }
  return merged;
}
}  // namespace

std::vector<XCorner> FindXCorners(const ImageF& blurred, const XCornerOptions& options) {
  if (blurred.width < 5 || blurred.height < 5) return {};
  return MergeDuplicates(TestPeaks(blurred, options, FindPeaks(blurred, options)));
}

Eigen::Vector2d XCornerDirection(const XCorner& c, int k) {
  switch (k & 3) {
    case 0:
      return c.line_a;
    case 1:
      return c.line_b;
    case 2:
      return -c.line_a;
    default:
      return -c.line_b;
  }
}

namespace {

// True when the segment from corner a to corner b runs along a printed edge: at a quarter,
// half and three quarters of the way, the points 0.15 of its length to either side
// differ by at least kMinEdgeContrastFraction of the weaker corner's contrast, dark on the
// same side each time (a square edge separates one dark and one light square). A saddle
// of texture inside a square (the dots of an ECoCheck board, print, clutter) lies within
// one square: its side samples agree.
bool AlongPrintedEdge(const ImageF& blurred, const XCorner& a, const XCorner& b) {
  // A third: a saddle inside a square sees the same paint on both sides (steps of a few grey
  // levels), while along a real edge the step stays near the corners' contrast, dimmed at
  // most to half by vignetting at a fisheye's rim.
  constexpr double kMinEdgeContrastFraction = 0.35;
  // The side samples stay within 0.15 of the segment's length of it: inside a board's outer
  // squares even where the print cuts them to 0.4 of a square, and outside the blur of the
  // edge for squares of 12 px and more (1.8 px off it under a blur sigma of 1.5 px).
  const Eigen::Vector2d d = b.uv_px - a.uv_px;
  const Eigen::Vector2d side(-0.15 * d.y(), 0.15 * d.x());
  const double min_step = kMinEdgeContrastFraction * std::min(a.contrast, b.contrast);
  int sense = 0;
  for (double t : {0.25, 0.5, 0.75}) {
    const Eigen::Vector2d p = a.uv_px + t * d;
    const Eigen::Vector2d l = p + side, r = p - side;
    for (const Eigen::Vector2d& q : {l, r}) {
      if (q.x() < 0.0 || q.y() < 0.0 || q.x() > blurred.width - 1 || q.y() > blurred.height - 1) {
        return false;
      }
    }
    const double step =
        SampleBilinear(blurred, l.x(), l.y()) - SampleBilinear(blurred, r.x(), r.y());
    const int s = step >= min_step ? 1 : step <= -min_step ? -1 : 0;
    if (s == 0 || (sense != 0 && s != sense)) return false;
    sense = s;
  }
  return true;
}

}  // namespace

std::vector<std::array<int, 4>> LinkXCorners(const std::vector<XCorner>& corners,
                                             const ImageF* blurred) {
  const int n = static_cast<int>(corners.size());
  std::vector<std::array<int, 4>> best(n, {-1, -1, -1, -1});
  // Two corners nearer than this are not neighbouring vertices of a board (the smallest
  // foreshortened square is about 8 px).
  constexpr double kMinLinkPx = 4.0;
  for (int i = 0; i < n; ++i) {
    std::array<double, 4> best_dist = {1e300, 1e300, 1e300, 1e300};
    for (int j = 0; j < n; ++j) {
      if (j == i) continue;
      const Eigen::Vector2d d = corners[j].uv_px - corners[i].uv_px;
      const double dist = d.norm();
      if (dist < kMinLinkPx) continue;
      const Eigen::Vector2d dir = d / dist;
      if (std::abs(corners[i].dark_axis.dot(corners[j].dark_axis)) > kMaxDarkAxisCos) continue;
      if (std::max(std::abs(corners[j].line_a.dot(dir)), std::abs(corners[j].line_b.dot(dir))) <
          kCosLinkTolerance) {
        continue;
      }
      for (int k = 0; k < 4; ++k) {
        if (XCornerDirection(corners[i], k).dot(dir) >= kCosLinkTolerance && dist < best_dist[k] &&
            (blurred == nullptr || AlongPrintedEdge(*blurred, corners[i], corners[j]))) {
          best_dist[k] = dist;
          best[i][k] = j;
        }
      }
    }
  }
  // Along one board line, the next vertex is at most kMaxLinkStretch times as far as the
  // previous one: perspective changes neighbouring squares by far less (2x would need the
  // line's vanishing point within two squares). A corner of clutter beyond a board's edge,
  // which can be the nearest along the outward direction of an edge vertex and link back
  // to it, is usually much farther; such a link would join the board's grid to clutter
  // and make it larger than it is.
  constexpr double kMaxLinkStretch = 2.0;
  const auto within_stretch = [&](int i, int k, double dist) {
    const int opposite = best[i][(k + 2) & 3];
    return opposite < 0 ||
           dist <= kMaxLinkStretch * (corners[opposite].uv_px - corners[i].uv_px).norm();
  };
  // Keep mutual links only: j is i's nearest along k and i is j's nearest back, and neither
  // end stretches the line.
  std::vector<std::array<int, 4>> links(n, {-1, -1, -1, -1});
  for (int i = 0; i < n; ++i) {
    for (int k = 0; k < 4; ++k) {
      const int j = best[i][k];
      if (j < 0) continue;
      const double dist = (corners[i].uv_px - corners[j].uv_px).norm();
      if (!within_stretch(i, k, dist)) continue;
      const Eigen::Vector2d back = (corners[i].uv_px - corners[j].uv_px) / dist;
      for (int m = 0; m < 4; ++m) {
        if (best[j][m] == i && XCornerDirection(corners[j], m).dot(back) >= kCosLinkTolerance &&
            within_stretch(j, m, dist)) {
          links[i][k] = j;
        }
      }
    }
  }
  return links;
}

std::string_view XCornerOptions::Validate() const {
  if (!(ring_radius_px >= 2.0 && ring_radius_px <= 32.0)) return "corners.ring_radius_px";
  if (!(min_contrast > 0.0 && min_contrast <= 255.0)) return "corners.min_contrast";
  if (max_candidates < 1 || max_candidates > 1000000) return "corners.max_candidates";
  if (saddle.half_window < 1 || saddle.half_window > 15) return "corners.saddle.half_window";
  return {};
}

std::vector<XCornerComponent> GridComponents(const std::vector<XCorner>& corners,
                                             const std::vector<std::array<int, 4>>& links) {
  const int n = static_cast<int>(corners.size());
  constexpr std::array<int, 4> kDi = {1, 0, -1, 0};
  constexpr std::array<int, 4> kDj = {0, 1, 0, -1};
  std::vector<int> rotation(n, -1);
  std::vector<std::pair<int, int>> coords(n);
  std::vector<XCornerComponent> components;
  for (int seed = 0; seed < n; ++seed) {
    if (rotation[seed] >= 0) continue;
    bool linked = false;
    for (int j : links[seed]) linked = linked || j >= 0;
    if (!linked) continue;
    rotation[seed] = 0;
    coords[seed] = {0, 0};
    std::deque<int> queue = {seed};
    std::map<std::pair<int, int>, int> at;  // grid point -> the strongest corner there
    while (!queue.empty()) {
      const int c = queue.front();
      queue.pop_front();
      if (const auto [it, fresh] = at.emplace(coords[c], c); !fresh) {
        it->second = std::min(it->second, c);
        continue;  // the weaker of two corners on one point spreads nothing
      }
      for (int g = 0; g < 4; ++g) {
        const int j = links[c][(rotation[c] + g) % 4];
        if (j < 0 || rotation[j] >= 0) continue;
        const Eigen::Vector2d v = XCornerDirection(corners[c], rotation[c] + g);
        int m_best = 0;
        for (int m = 1; m < 4; ++m) {
          if (XCornerDirection(corners[j], m).dot(v) >
              XCornerDirection(corners[j], m_best).dot(v)) {
            m_best = m;
          }
        }
        rotation[j] = (m_best - g + 4) % 4;
        coords[j] = {coords[c].first + kDi[g], coords[c].second + kDj[g]};
        queue.push_back(j);
      }
    }
    XCornerComponent comp;
    for (const auto& [point, index] : at) {
      comp.corners.push_back({index, point.first, point.second});
    }
    components.push_back(std::move(comp));
  }
  return components;
}

std::vector<std::vector<int>> GridWindows(const XCornerComponent& component, int w, int h,
                                          int min_corners) {
  int i0 = 1 << 30, i1 = -(1 << 30), j0 = 1 << 30, j1 = -(1 << 30);
  for (const XCornerGridCorner& gc : component.corners) {
    i0 = std::min(i0, gc.gi);
    i1 = std::max(i1, gc.gi);
    j0 = std::min(j0, gc.gj);
    j1 = std::max(j1, gc.gj);
  }
  const int bw = i1 - i0 + 1, bh = j1 - j0 + 1;
  std::vector<int> at(static_cast<std::size_t>(std::max(bw, 0)) * std::max(bh, 0), -1);
  for (const XCornerGridCorner& gc : component.corners) {
    at[(gc.gj - j0) * bw + gc.gi - i0] = gc.index;
  }
  std::vector<std::vector<int>> windows;
  for (int wj = 0; wj + h <= bh; ++wj) {
    for (int wi = 0; wi + w <= bw; ++wi) {
      std::vector<int> indices;
      int present = 0;
      for (int j = wj; j < wj + h; ++j) {
        for (int i = wi; i < wi + w; ++i) {
          indices.push_back(at[j * bw + i]);
          present += at[j * bw + i] >= 0 ? 1 : 0;
        }
      }
      if (present >= min_corners) windows.push_back(std::move(indices));
    }
  }
  return windows;
}

namespace {
// The first corner of the block of three that is centred nearest to x, inside 0..n-1.
int BlockOrigin(double x, int n) {
  return std::clamp(static_cast<int>(std::lround(x)) - 1, 0, std::max(0, n - 3));
}
}  // namespace

std::optional<Eigen::Vector2d> GridBlockMap::Map(double x, double y) {
  const std::optional<Eigen::Matrix3d>& H = Block(BlockOrigin(x, w_), BlockOrigin(y, h_));
  if (!H) return std::nullopt;
  const Eigen::Vector2d p = ApplyHomography(*H, Eigen::Vector2d(x, y));
  if (!p.allFinite()) return std::nullopt;
  return p;
}

const std::optional<Eigen::Matrix3d>& GridBlockMap::Block(int c0, int r0) {
  const auto key = std::make_pair(c0, r0);
  if (auto it = blocks_.find(key); it != blocks_.end()) return it->second;
  std::vector<Eigen::Vector2d> src, dst;
  for (int r = r0; r < std::min(h_, r0 + 3); ++r) {
    for (int c = c0; c < std::min(w_, c0 + 3); ++c) {
      src.emplace_back(c, r);
      dst.push_back(uv_[r * w_ + c]);
    }
  }
  std::optional<Eigen::Matrix3d> H;
  if (const std::optional<HomographyFit> fit = FitHomography(src, dst, {.refine = false})) {
    H = fit->H;
  }
  return blocks_.emplace(key, H).first->second;
}

}  // namespace linecal

#include "detectors/common/contours.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <numeric>
#include <optional>

namespace linecal {
namespace {

struct Run {
  int x0 = 0;  // inclusive
  int x1 = 0;  // exclusive
  int y = 0;
  int parent = 0;  // union-find over runs
};

int FindRoot(std::vector<Run>& runs, int i) {
  while (runs[i].parent != i) {
    runs[i].parent = runs[runs[i].parent].parent;  // path halving
    i = runs[i].parent;
  }
  return i;
}

void Unite(std::vector<Run>& runs, int a, int b) {
  a = FindRoot(runs, a);
  b = FindRoot(runs, b);
  if (a == b) return;
  // The smaller index stays the root, so a component's root is its first run in raster
  // order.
  if (a < b) {
    runs[b].parent = a;
  } else {
    runs[a].parent = b;
  }
}

// The set (non-zero) pixels of a row as bits: bit x % 64 of words[x / 64], and a zero word
// past the row's end, so that every run of set bits ends before the words do. Eight pixels
// at a time without a branch; the runs are then found a word at a time (NextBit): a binary
// image's runs are tens of pixels long, and a loop that stops at each group of pixels to test
// it spends its time on mispredicted branches.
void RowBits(const std::uint8_t* row, int width, std::vector<std::uint64_t>* words) {
  constexpr std::uint64_t kLow7 = 0x7f7f7f7f7f7f7f7fULL;
  constexpr std::uint64_t kHigh = 0x8080808080808080ULL;
  // Gathers the high bit of byte i (bit 8 i + 7) into bit 56 + i: no two products overlap.
  constexpr std::uint64_t kGather = 0x0102040810204080ULL;
  words->assign(static_cast<std::size_t>(width) / 64 + 1, 0);
  std::uint64_t* out = words->data();
  int x = 0;
  if constexpr (std::endian::native == std::endian::little) {
    for (; x + 8 <= width; x += 8) {
      std::uint64_t v;
      std::memcpy(&v, row + x, 8);
      // The high bit of each byte: set when the byte is non-zero (no carry crosses a byte:
      // 0x7f + 0x7f < 0x100).
      const std::uint64_t non_zero = (((v & kLow7) + kLow7) | v) & kHigh;
      out[x / 64] |= (((non_zero >> 7) * kGather) >> 56) << (x % 64);
    }
  }
  for (; x < width; ++x) out[x / 64] |= static_cast<std::uint64_t>(row[x] != 0) << (x % 64);
}

// The first bit at or after x that is set when `set`, unset when not; words.size() * 64 when
// there is none.
int NextBit(const std::vector<std::uint64_t>& words, int x, bool set) {
  const int n = static_cast<int>(words.size());
  int k = x / 64;
  if (k >= n) return n * 64;
  const std::uint64_t flip = set ? 0 : ~std::uint64_t{0};
  std::uint64_t w = (words[k] ^ flip) & (~std::uint64_t{0} << (x % 64));
  while (w == 0) {
    if (++k == n) return n * 64;
    w = words[k] ^ flip;
  }
  return k * 64 + std::countr_zero(w);
}

// Moore neighbourhood, clockwise in the image (y down), starting east.
constexpr std::array<int, 8> kDx = {1, 1, 0, -1, -1, -1, 0, 1};
constexpr std::array<int, 8> kDy = {0, 1, 1, 1, 0, -1, -1, -1};

double PointLineDistance(const Eigen::Vector2d& p, const Eigen::Vector2d& a,
                         const Eigen::Vector2d& b) {
  const Eigen::Vector2d d = b - a;
  const double len = d.norm();
  if (len == 0.0) return (p - a).norm();
  return std::abs(d.x() * (p.y() - a.y()) - d.y() * (p.x() - a.x())) / len;
}

// Douglas-Peucker on contour[first..last] (indices modulo n), appending kept interior
// indices (not first or last) in order.
void Simplify(const std::vector<Eigen::Vector2i>& contour, int first, int last, double epsilon,
              std::vector<int>* kept) {
  const int n = static_cast<int>(contour.size());
  // An explicit stack keeps deep recursion on long contours off the call stack.
  std::vector<std::pair<int, int>> stack = {{first, last}};
  std::vector<int> found;
  while (!stack.empty()) {
    const auto [a, b] = stack.back();
    stack.pop_back();
    const int span = (b - a + n) % n;
    if (span < 2) continue;
    const Eigen::Vector2d pa = contour[a].cast<double>();
    const Eigen::Vector2d pb = contour[b].cast<double>();
    double best = -1.0;
    int best_k = -1;
    for (int s = 1; s < span; ++s) {
      const int k = (a + s) % n;
      const double d = PointLineDistance(contour[k].cast<double>(), pa, pb);
      if (d > best) {
        best = d;
        best_k = k;
      }
    }
    if (best > epsilon) {
      found.push_back(best_k);
      stack.push_back({a, best_k});
      stack.push_back({best_k, b});
    }
  }
  // Order by position along the path from `first`.
  std::sort(found.begin(), found.end(),
            [&](int i, int j) { return (i - first + n) % n < (j - first + n) % n; });
  kept->insert(kept->end(), found.begin(), found.end());
}

double Cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

}  // namespace

ComponentLabels LabelComponents(const ImageView8& binary, bool label_image) {
  ComponentLabels out;
  out.width = binary.width;
  out.height = binary.height;
  std::vector<Run> runs;
  std::vector<int> row_start(static_cast<std::size_t>(binary.height) + 1, 0);
  int prev_begin = 0;
  int prev_end = 0;
  std::vector<std::uint64_t> bits;
  for (int y = 0; y < binary.height; ++y) {
    const std::uint8_t* row = binary.Row(y);
    const int begin = static_cast<int>(runs.size());
    RowBits(row, binary.width, &bits);
    // The zero word past the row's end ends the last run at binary.width at the latest.
    for (int x = NextBit(bits, 0, true); x < binary.width; x = NextBit(bits, x, true)) {
      const int x0 = x;
      x = NextBit(bits, x0, false);
      const int index = static_cast<int>(runs.size());
      runs.push_back(Run{x0, x, y, index});
    }
    const int end = static_cast<int>(runs.size());
    // Runs of consecutive rows touch (4-connectivity) when their x ranges overlap; both
    // lists are sorted by x, so one merge-like sweep finds every overlap.
    int p = prev_begin;
    for (int r = begin; r < end; ++r) {
      while (p < prev_end && runs[p].x1 <= runs[r].x0) ++p;
      for (int q = p; q < prev_end && runs[q].x0 < runs[r].x1; ++q) Unite(runs, q, r);
    }
    row_start[y] = begin;
    prev_begin = begin;
    prev_end = end;
  }
  row_start[binary.height] = static_cast<int>(runs.size());

  // The labels are written once each, in raster order, the gaps between the runs as 0 (a
  // zeroed image with the runs filled in would write the runs' pixels twice: the labels of
  // a large image are several megabytes, and writing them is most of the cost).
  const std::size_t pixels = static_cast<std::size_t>(binary.width) * binary.height;
  if (label_image) out.labels.reserve(pixels);
  std::vector<int> component_of_root(runs.size(), -1);
  std::vector<int> component_of_run(label_image ? 0 : runs.size());
  for (int i = 0; i < static_cast<int>(runs.size()); ++i) {
    const int root = FindRoot(runs, i);
    int c = component_of_root[root];
    const Run& run = runs[i];
    if (c < 0) {
      c = static_cast<int>(out.components.size());
      component_of_root[root] = c;
      Component comp;
      comp.min_x = run.x0;
      comp.max_x = run.x1 - 1;
      comp.min_y = comp.max_y = run.y;
      comp.first_x = run.x0;
      comp.first_y = run.y;
      out.components.push_back(comp);
    }
    Component& comp = out.components[c];
    comp.area_px += run.x1 - run.x0;
    comp.min_x = std::min(comp.min_x, run.x0);
    comp.max_x = std::max(comp.max_x, run.x1 - 1);
    comp.max_y = std::max(comp.max_y, run.y);
    if (!label_image) {
      component_of_run[i] = c;
      continue;
    }
    const std::size_t start = static_cast<std::size_t>(run.y) * binary.width + run.x0;
    out.labels.insert(out.labels.end(), start - out.labels.size(), 0);
    out.labels.insert(out.labels.end(), run.x1 - run.x0, c + 1);
  }
  if (label_image) {
    out.labels.insert(out.labels.end(), pixels - out.labels.size(), 0);
    return out;
  }
  // The runs grouped by component (a counting sort, which keeps each one's raster order).
  const int n = static_cast<int>(out.components.size());
  out.run_begin.assign(n + 1, 0);
  for (const int c : component_of_run) ++out.run_begin[c + 1];
  for (int c = 0; c < n; ++c) out.run_begin[c + 1] += out.run_begin[c];
  std::vector<int> next(out.run_begin.begin(), out.run_begin.end() - 1);
  out.runs.resize(runs.size());
  for (int i = 0; i < static_cast<int>(runs.size()); ++i) {
    out.runs[next[component_of_run[i]]++] = PixelRun{runs[i].x0, runs[i].x1, runs[i].y};
  }
  return out;
}

namespace {

// Moore-neighbour tracing of the component `comp`, whose pixels inside(x, y) tells (false
// off the image), as TraceOuterContour.
template <typename Inside>
std::vector<Eigen::Vector2i> TraceContour(const Component& comp, Inside&& inside) {
  std::vector<Eigen::Vector2i> contour;
  const Eigen::Vector2i start(comp.first_x, comp.first_y);
  contour.push_back(start);
  // The first pixel in raster order has no component pixel to its west or in the row above:
  // start as if we had arrived with the west neighbour as the last background pixel seen.
  int backtrack = 4;
  Eigen::Vector2i p = start;
  int first_move = -1;
  // A boundary pixel is visited at most 4 times (once per side it exposes), so this bounds
  // the walk even for an inconsistent labelling.
  const long max_steps = 4L * comp.area_px + 8;
  for (long step = 0; step < max_steps; ++step) {
    int move = -1;
    for (int k = 1; k <= 8; ++k) {
      const int d = (backtrack + k) % 8;
      if (inside(p.x() + kDx[d], p.y() + kDy[d])) {
        move = d;
        break;
      }
    }
    if (move < 0) break;  // an isolated pixel
    // Jacob's stopping criterion: back at the start, leaving it the way we first did.
    if (p == start) {
      if (first_move < 0) {
        first_move = move;
      } else if (move == first_move) {
        contour.pop_back();  // the start was appended again on arrival
        break;
      }
    }
    p += Eigen::Vector2i(kDx[move], kDy[move]);
    contour.push_back(p);
    // The last background pixel examined, seen from the new pixel: north of it for an axis
    // move east, and so on; the table below is that rule for every direction.
    backtrack = (move + 6 - (move & 1)) % 8;
  }
  return contour;
}

}  // namespace

std::vector<Eigen::Vector2i> TraceOuterContour(const ComponentLabels& labels, int index) {
  const Component& comp = labels.components[index];
  if (labels.labels.empty()) {
    // The component's pixels in its bounding box with a border of one pixel, which holds
    // every neighbour the trace looks at: no bounds to check.
    const int x0 = comp.min_x - 1, y0 = comp.min_y - 1;
    const int w = comp.max_x - comp.min_x + 3;
    std::vector<std::uint8_t> mask(static_cast<std::size_t>(w) * (comp.max_y - comp.min_y + 3), 0);
    for (int r = labels.run_begin[index]; r < labels.run_begin[index + 1]; ++r) {
      const PixelRun& run = labels.runs[r];
      std::fill_n(&mask[static_cast<std::size_t>(run.y - y0) * w + (run.x0 - x0)], run.x1 - run.x0,
                  std::uint8_t{1});
    }
    return TraceContour(comp, [&](int x, int y) {
      return mask[static_cast<std::size_t>(y - y0) * w + (x - x0)] != 0;
    });
  }
  const std::int32_t label = index + 1;
  return TraceContour(comp, [&](int x, int y) {
    return x >= 0 && y >= 0 && x < labels.width && y < labels.height &&
           labels.LabelAt(x, y) == label;
  });
}

std::vector<int> ApproximateClosedPolygon(const std::vector<Eigen::Vector2i>& contour,
                                          double epsilon_px) {
  const int n = static_cast<int>(contour.size());
  std::vector<int> out;
  if (n < 3) {
    out.resize(n);
    std::iota(out.begin(), out.end(), 0);
    return out;
  }
  // Anchors: the point farthest from the first, and the point farthest from that one: two
  // points that are vertices of any good approximation.
  auto farthest_from = [&](int i) {
    int best = i;
    long best_d2 = -1;
    for (int k = 0; k < n; ++k) {
      const long d2 = (contour[k] - contour[i]).cast<long>().squaredNorm();
      if (d2 > best_d2) {
        best_d2 = d2;
        best = k;
      }
    }
    return best;
  };
  const int a = farthest_from(0);
  const int b = farthest_from(a);
  if (a == b) return {a};
  std::vector<int> kept = {a};
  Simplify(contour, a, b, epsilon_px, &kept);
  kept.push_back(b);
  Simplify(contour, b, a, epsilon_px, &kept);
  std::sort(kept.begin(), kept.end());
  return kept;
}

namespace {

// Merges the closest pair of neighbouring vertices of the closed polygon into their midpoint
// while they are closer than min_distance_px (in place; order kept). O(n^2).
void MergeCloseVertices(double min_distance_px, std::vector<Eigen::Vector2d>* polygon) {
  while (polygon->size() > 3) {
    const std::size_t n = polygon->size();
    std::size_t closest = 0;
    for (std::size_t k = 1; k < n; ++k) {
      if (((*polygon)[(k + 1) % n] - (*polygon)[k]).norm() <
          ((*polygon)[(closest + 1) % n] - (*polygon)[closest]).norm()) {
        closest = k;
      }
    }
    const std::size_t next = (closest + 1) % n;
    if (!(((*polygon)[next] - (*polygon)[closest]).norm() < min_distance_px)) return;
    (*polygon)[closest] = 0.5 * ((*polygon)[closest] + (*polygon)[next]);
    polygon->erase(polygon->begin() + static_cast<std::ptrdiff_t>(next));
  }
}

// Twice the signed area of the closed polygon (shoelace; positive when clockwise in y-down
// image coordinates).
double TwiceSignedArea(const std::vector<Eigen::Vector2d>& polygon) {
  double sum = 0.0;
  for (std::size_t k = 0; k < polygon.size(); ++k) {
    sum += Cross(polygon[k], polygon[(k + 1) % polygon.size()]);
  }
  return sum;
}

// The largest distance of the contour points strictly between indices a and b (along the
// contour, modulo its size) from the chord a-b.
double ChordDeviation(const std::vector<Eigen::Vector2i>& contour, int a, int b) {
  const int n = static_cast<int>(contour.size());
  const Eigen::Vector2d pa = contour[a].cast<double>(), pb = contour[b].cast<double>();
  double worst = 0.0;
  for (int k = (a + 1) % n; k != b; k = (k + 1) % n) {
    worst = std::max(worst, PointLineDistance(contour[k].cast<double>(), pa, pb));
  }
  return worst;
}

// Removes from `vertices` (contour indices, increasing) the vertex whose neighbours' chord
// deviates least from the contour, while that deviation is within epsilon_px and more than
// four vertices remain: Douglas-Peucker keeps every point where it split, even one that a
// later split left on a straight side. O(vertices^2 x perimeter).
void DropStraightVertices(const std::vector<Eigen::Vector2i>& contour, double epsilon_px,
                          std::vector<int>* vertices) {
  while (vertices->size() > 4) {
    const std::size_t n = vertices->size();
    std::size_t best = n;
    double best_deviation = epsilon_px;
    for (std::size_t k = 0; k < n; ++k) {
      const double deviation =
          ChordDeviation(contour, (*vertices)[(k + n - 1) % n], (*vertices)[(k + 1) % n]);
      if (deviation <= best_deviation) {
        best_deviation = deviation;
        best = k;
      }
    }
    if (best == n) return;
    vertices->erase(vertices->begin() + static_cast<std::ptrdiff_t>(best));
  }
}

// Chamfers are at most this share of the shortest true side (a square's corner cut by a
// quarter of its side leaves a chamfer of 0.71 of what remains of the side); the edges of a
// blob of noise come in any length.
constexpr double kMaxCutEdgeFraction = 0.75;

// The quad whose sides lie on the four longest edges of `polygon` (in order, over four
// vertices), when every other edge is shorter than kMaxCutEdgeFraction of the shortest of
// them and the polygon covers at least kMinQuadAreaFraction of the quad; else the polygon
// unchanged. O(n log n).
void ReduceToLongestSides(std::vector<Eigen::Vector2d>* polygon) {
  const std::vector<Eigen::Vector2d>& v = *polygon;
  const int n = static_cast<int>(v.size());
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  const auto length = [&](int k) { return (v[(k + 1) % n] - v[k]).norm(); };
  std::sort(order.begin(), order.end(), [&](int a, int b) { return length(a) > length(b); });
  if (length(order[4]) >= kMaxCutEdgeFraction * length(order[3])) return;
  std::vector<int> sides(order.begin(), order.begin() + 4);
  std::sort(sides.begin(), sides.end());
  std::vector<Eigen::Vector2d> quad;
  for (int t = 0; t < 4; ++t) {
    const int a = sides[(t + 3) % 4], b = sides[t];
    const Eigen::Vector2d da = v[(a + 1) % n] - v[a], db = v[(b + 1) % n] - v[b];
    const double det = Cross(da, db);
    // Near-parallel sides (under about 3 degrees) meet nowhere useful.
    if (std::abs(det) < 0.05 * da.norm() * db.norm()) return;
    quad.push_back(v[a] + da * (Cross(v[b] - v[a], db) / det));
  }
  if (std::abs(TwiceSignedArea(v)) < kMinQuadAreaFraction * std::abs(TwiceSignedArea(quad))) {
    return;
  }
  *polygon = std::move(quad);
}

// The share of the contour between two corners of an inscribed quad, about its middle, whose
// points give that side's line (FittedSidesQuad): on a blurred square of 12 px whose corners
// are rounded with a radius of 3-4 px, the straight middle of a side; on a disc, an arc of 45
// degrees, whose line lies so far inside that the disc fills 0.83 of the quad.
constexpr double kSideFitSpan = 0.5;

// The quad whose sides are the total-least-squares lines through the middle kSideFitSpan of
// the contour between neighbouring `corners` (contour indices, in contour order, clockwise);
// nullopt when a side has fewer than 3 points there or two neighbouring sides are within
// about 3 degrees of parallel. O(contour).
std::optional<std::vector<Eigen::Vector2d>> FittedSidesQuad(
    const std::vector<Eigen::Vector2i>& contour, const std::array<int, 4>& corners) {
  const int n = static_cast<int>(contour.size());
  std::array<Eigen::Vector2d, 4> centroid, dir;
  for (int k = 0; k < 4; ++k) {
    const int span = (corners[(k + 1) % 4] - corners[k] + n) % n;
    const int first = static_cast<int>(std::ceil(0.5 * (1.0 - kSideFitSpan) * span));
    const int last = static_cast<int>(std::floor(0.5 * (1.0 + kSideFitSpan) * span));
    if (last - first < 2) return std::nullopt;
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (int s = first; s <= last; ++s) mean += contour[(corners[k] + s) % n].cast<double>();
    mean /= last - first + 1;
    Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
    for (int s = first; s <= last; ++s) {
      const Eigen::Vector2d d = contour[(corners[k] + s) % n].cast<double>() - mean;
      scatter += d * d.transpose();
    }
    // The principal axis of a 2 x 2 scatter in closed form: its angle is half that of
    // (sxx - syy, 2 sxy).
    const double angle = 0.5 * std::atan2(2.0 * scatter(0, 1), scatter(0, 0) - scatter(1, 1));
    centroid[k] = mean;
    dir[k] = Eigen::Vector2d(std::cos(angle), std::sin(angle));
  }
  std::vector<Eigen::Vector2d> quad;
  for (int k = 0; k < 4; ++k) {
    // Corner k ends side k - 1 and starts side k.
    const int a = (k + 3) % 4;
    const double det = Cross(dir[a], dir[k]);
    if (std::abs(det) < 0.05) return std::nullopt;
    quad.push_back(centroid[a] + dir[a] * (Cross(centroid[k] - centroid[a], dir[k]) / det));
  }
  return quad;
}

// Passes of InscribedQuad: each takes the quad's other diagonal, and the largest quad is
// reached in two or three.
constexpr int kInscribedQuadPasses = 4;

// The quad inscribed in a contour that ReduceToLongestSides could not reduce, found by
// growing it: from two anchors (the point farthest from the contour's first, and the point
// farthest from that one), the contour point farthest from their chord on either side; then
// the same about the quad's other diagonal, while the quad grows. Kept when it and the
// contour each hold kMinQuadAreaFraction of the other's area; otherwise the polygon is left
// unchanged. Blur rounds the ends of a small square's short sides (10-12 px under blur 1.5
// and a gamma) into arcs, on which Douglas-Peucker's vertices fall anywhere: a side's middle
// or a long chamfer, which no four of its edges give. A disc keeps 64% in such a quad, a
// regular hexagon 67%, an octagon 71%. The quad's corners lie on the rounded corners, inside
// the square's: the caller refines them. O(contour).
void InscribedQuad(const std::vector<Eigen::Vector2i>& contour,
                   std::vector<Eigen::Vector2d>* polygon) {
  const int n = static_cast<int>(contour.size());
  const auto point = [&](int k) { return contour[k].cast<double>(); };
  int a = 0;
  for (int k = 0; k < n; ++k) {
    if ((contour[k] - contour[0]).squaredNorm() > (contour[a] - contour[0]).squaredNorm()) a = k;
  }
  int b = a;
  for (int k = 0; k < n; ++k) {
    if ((contour[k] - contour[a]).squaredNorm() > (contour[b] - contour[a]).squaredNorm()) b = k;
  }
  if (a == b) return;
  // The point farthest from chord p-q among those after `from` up to `to` along the contour
  // (-1 when there is none off the chord).
  const auto farthest_between = [&](int from, int to) {
    int best = -1;
    double best_d = 0.0;
    for (int k = (from + 1) % n; k != to; k = (k + 1) % n) {
      const double d = PointLineDistance(point(k), point(from), point(to));
      if (d > best_d) {
        best_d = d;
        best = k;
      }
    }
    return best;
  };
  std::array<int, 4> corners = {a, -1, b, -1};  // contour indices, in contour order
  double area = 0.0;
  for (int pass = 0; pass < kInscribedQuadPasses; ++pass) {
    // Pass 0 and every even pass: new corners 1 and 3 about the diagonal 0-2; odd passes:
    // new corners 0 and 2 about 1-3.
    const int first = pass % 2 == 0 ? 0 : 1;
    std::array<int, 4> next = corners;
    next[first + 1] = farthest_between(corners[first], corners[first + 2]);
    next[(first + 3) % 4] = farthest_between(corners[first + 2], corners[first]);
    if (next[first + 1] < 0 || next[(first + 3) % 4] < 0) break;
    const double next_area =
        std::abs(TwiceSignedArea({point(next[0]), point(next[1]), point(next[2]), point(next[3])}));
    if (!(next_area > area)) break;
    area = next_area;
    corners = next;
  }
  // The contour's own area: a blob of noise, not convex, has a contour of less area than
  // the quad through four of its points, and a Douglas-Peucker polygon of less still.
  double contour_area = 0.0;
  for (int k = 0; k < n; ++k) contour_area += Cross(point(k), point((k + 1) % n));
  contour_area = std::abs(contour_area);
  if (corners[1] < 0 || contour_area < kMinQuadAreaFraction * area) return;
  if (area >= kMinQuadAreaFraction * contour_area) {
    *polygon = {point(corners[0]), point(corners[1]), point(corners[2]), point(corners[3])};
    return;
  }
  // Corners rounded with a radius of a quarter of the side (blur 1.5 and a gamma on a square
  // of 12 px) leave the inscribed quad, its corners on the arcs, at 0.77 of the contour. The
  // lines of the sides' straight middles meet beyond the arcs, and the contour fills that
  // quad (0.95 for such a square) as it does not a disc's (0.83).
  const std::optional<std::vector<Eigen::Vector2d>> fitted = FittedSidesQuad(contour, corners);
  if (!fitted) return;
  const double fitted_area = std::abs(TwiceSignedArea(*fitted));
  if (fitted_area < contour_area || contour_area < kMinQuadAreaFraction * fitted_area) return;
  *polygon = *fitted;
}

}  // namespace

std::vector<Quad> FindQuads(const ComponentLabels& labels, const QuadOptions& options) {
  std::vector<Quad> quads;
  const int max_side =
      static_cast<int>(options.max_side_fraction * std::max(labels.width, labels.height));
  for (int i = 0; i < static_cast<int>(labels.components.size()); ++i) {
    const Component& c = labels.components[i];
    const int w = c.max_x - c.min_x + 1;
    const int h = c.max_y - c.min_y + 1;
    if (std::max(w, h) < options.min_side_px || std::max(w, h) > max_side) continue;
    // A square rotated 45 degrees fills half its bounding box, and a marker's dark border
    // ring alone is over a third of its area: less than a tenth of the box inked is a thin
    // line drawing or clutter, not a marker.
    if (c.area_px < 0.1 * w * h) continue;
    const std::vector<Eigen::Vector2i> contour = TraceOuterContour(labels, i);
    if (contour.size() < 8) continue;
    double length = 0.0;
    for (std::size_t k = 0; k < contour.size(); ++k) {
      length += (contour[(k + 1) % contour.size()] - contour[k]).cast<double>().norm();
    }
    const double epsilon_px = options.polygon_epsilon_fraction * length;
    std::vector<int> vertices = ApproximateClosedPolygon(contour, epsilon_px);
    if (options.max_polygon_vertices > 4) DropStraightVertices(contour, epsilon_px, &vertices);
    std::vector<Eigen::Vector2d> polygon;
    for (int v : vertices) polygon.push_back(contour[v].cast<double>());
    MergeCloseVertices(options.merge_vertices_fraction * length, &polygon);
    const int n = static_cast<int>(polygon.size());
    if (n > 4 && n <= options.max_polygon_vertices) {
      ReduceToLongestSides(&polygon);
      if (polygon.size() > 4) InscribedQuad(contour, &polygon);
    }
    if (polygon.size() != 4) continue;
    Quad quad;
    quad.component = i;
    for (int k = 0; k < 4; ++k) quad.corners_px[k] = polygon[k];
    // Convex, and clockwise in the image (the trace direction): every turn has a positive
    // cross product in y-down coordinates.
    bool ok = true;
    double min_len = 1e300;
    double max_len = 0.0;
    for (int k = 0; k < 4 && ok; ++k) {
      const Eigen::Vector2d e0 = quad.corners_px[(k + 1) % 4] - quad.corners_px[k];
      const Eigen::Vector2d e1 = quad.corners_px[(k + 2) % 4] - quad.corners_px[(k + 1) % 4];
      if (Cross(e0, e1) <= 0.0) ok = false;
      min_len = std::min(min_len, e0.norm());
      max_len = std::max(max_len, e0.norm());
      const Eigen::Vector2d& p = quad.corners_px[k];
      if (p.x() < options.min_border_distance_px || p.y() < options.min_border_distance_px ||
          p.x() > labels.width - 1 - options.min_border_distance_px ||
          p.y() > labels.height - 1 - options.min_border_distance_px) {
        ok = false;
      }
    }
    if (!ok || min_len < options.min_side_ratio * max_len) continue;
    quads.push_back(quad);
  }
  return quads;
}

}  // namespace linecal

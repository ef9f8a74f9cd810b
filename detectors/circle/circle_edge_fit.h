#pragma once
// The sub-pixel stage shared by the circle detectors (circle_detector.h, circle_grid_detector.h):
// a printed circle's image ellipse measured from its edge.
//
// Method: two passes, each the strongest edge of the expected polarity along rays from the
// seed's centre (the parabolic peak of the grey profile's derivative, within a window around
// the seed's edge), then a direct ellipse fit (ellipse.h) with outlier rejection. The first
// pass, seeded by the caller's ellipse, searches 0.35 of the radius either side with half the
// rays; the second, seeded by the first, every 0.5 px over +-3 px with all of them.
//
// The result is the ellipse of the circle's edge: under perspective its centre is NOT the
// image of the circle's centre (ellipse.h, ImageOfCircle); the caller corrects that.
//
// Frames and units: image pixels, pixel-centre convention (docs/conventions.md).

#include <Eigen/Core>
#include <optional>
#include <vector>

#include "detectors/common/ellipse.h"
#include "detectors/core/image_view.h"

namespace linecal {

class CircleEdgeFitter {
 public:
  // `rays` edge points per circle, [16, 256] (the caller's options validate it): 64 average
  // the noise of single edge positions (0.1-0.2 px at noise sigma 4) down to a few hundredths
  // of a pixel in the centre. Precomputes the ray directions; O(rays).
  explicit CircleEdgeFitter(int rays);

  // The ellipse of the circle whose image `seed` approximates (its edge within about 0.35 of
  // the radius, at least 1.5 px, of the seed's), `light` when the circle is lighter than its
  // surroundings; edges weaker than a quarter of min_contrast per pixel are noise. nullopt
  // when fewer than half the rays find the edge (a circle half hidden, cut by the image
  // border, or merged with a neighbour), or when the result strays from the seed (centre
  // more than half a radius away, or radius off by more than a third plus 1 px: another
  // edge was measured). *median_residual_px, when not null, receives the median distance of
  // the last pass's edge points from its first ellipse fit (before outliers are removed), a
  // test of the shape: the edge noise (a tenth to a few tenths of a pixel) for a circle,
  // several percent of the size for a square. Reads only the pixels around the seed. Cost:
  // about 10 microseconds per circle at 64 rays.
  std::optional<Ellipse> Measure(const ImageView8& image, const Ellipse& seed, bool light,
                                 int min_contrast, double* median_residual_px = nullptr) const;

 private:
  std::vector<Eigen::Vector2d> coarse_;  // every other ray, for the first pass
  std::vector<Eigen::Vector2d> fine_;
};

}  // namespace linecal

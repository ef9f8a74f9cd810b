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

// How a measured edge departs from the ellipse fitted to it, a test of the printed shape. The
// image of a circle is an ellipse under any homography, and blur and noise keep it one up to
// the edge noise (a tenth to a few tenths of a pixel, spread over every harmonic of the angle
// around the ellipse). A square's image is an affine square up to perspective, which the
// ellipse's frame (the fit's affine map undone) turns back into a square: its edge departs
// from the ellipse by the fourfold harmonic above all (cos 4 phi: corners out, the sides'
// middles in), 0.14 of the radius for sharp corners, 0.86 of the departure's variance
// (64 rays around a square, computed).
struct EdgeShape {
  double median_residual_px = 0.0;  // the median distance of the edge points from the ellipse
  // The fourfold harmonic of the points' radial departure (least squares in the ellipse's
  // frame, scaled to pixels by the mean radius): amplitude, and its share of the departure's
  // variance about its mean.
  double fourfold_px = 0.0;
  double fourfold_share = 0.0;
};

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
  // edge was measured). *shape, when not null, receives how the last pass's edge points depart
  // from its first ellipse fit (before outliers are removed), a test of the shape (EdgeShape).
  // Reads only the pixels around the seed. Cost: about 10 microseconds per circle at 64 rays.
  std::optional<Ellipse> Measure(const ImageView8& image, const Ellipse& seed, bool light,
                                 int min_contrast, EdgeShape* shape = nullptr) const;

 private:
  std::vector<Eigen::Vector2d> coarse_;  // every other ray, for the first pass
  std::vector<Eigen::Vector2d> fine_;
};

// The centre of a circle's image ellipse from its grey levels rather than its edge: the
// centroid of each pixel's share of print, (page - grey) / (page - print) clamped to [0, 1],
// over the ellipse scaled by `outer` about its centre, the page a plane fitted to a ring
// just inside `outer` (past the blurred edge), the print the grey of the circle's core.
// `ellipse` is the edge fit (Measure), which gives the shape and the window.
//
// Why: the image of a printed circle is centrally symmetric about its ellipse's centre, and
// so is its blurred, gamma-curved, sampled image for any point-symmetric blur; the share
// centroid of a symmetric window is then that centre, exactly, without locating an edge.
// Its noise is the page's and the edge pixels' grey noise averaged over the whole window,
// where an edge fit's is the noise of 64 derivative peaks: on the renders of
// circle_grid_detector_test its centres are 0.002 px RMS clean and 0.026 px noisy against
// the edge fit's 0.045 and 0.09. Like the edge fit's ellipse centre, it is not the image of
// the circle's centre under perspective (the caller corrects that).
//
// nullopt, and the caller keeps the edge fit's centre, when the window does not fit: its
// scale (1 + 2.5 px and then a ring of max(2 px, a quarter radius), in semi-minor pixels)
// reaches within 2.5 px of `max_scale` (the caller's room: the scale of the ellipse at
// which it would touch the nearest other print, a neighbouring circle), it leaves
// the image, print and page are less than a grey level apart, or the centroid strays from
// the edge fit's centre by more than a quarter of the semi-minor axis. Reads the window's
// pixels twice (the levels, then the centroid): about 10 microseconds for a circle 18 px
// across. The window is centred on the edge fit's centre; centring a second window on the
// centroid changed the renders' RMS by under a thousandth of a pixel.
std::optional<Eigen::Vector2d> GreyCentroid(const ImageView8& image, const Ellipse& ellipse,
                                            bool light, double max_scale);

// The centre of a circle's image ellipse from a model of its window's grey levels (the
// window of GreyCentroid), fitted by least squares (Levenberg-Marquardt from the edge fit and
// GreyCentroid's levels): grey = page (1 - k F), the page a plane a + b du + c dv (the
// illumination, which dims the print with the page), k the print's contrast, F the share of
// print, the Gaussian integral of the pixel's distance from the ellipse over the blur sigma;
// the ellipse's centre and conic, sigma, the plane and k are fitted (10 parameters).
//
// Why: under Gaussian noise the least-squares fit weighs each pixel by what its grey tells
// of the centre, the blurred edge's slope, where the share centroid weighs the page ring's
// noise by its distance from the centre; and its print follows the light, where the
// centroid's print is one grey. On the renders of circle_grid_detector_test (noise 4, blur
// 1.0, a 3:1 gradient, gamma 1.4) its centres are 0.017 px RMS off against the centroid's
// 0.026 px; under JPEG 80 0.007 against 0.014. The model is point-symmetric about the
// centre, as the image is, so a wrong profile (gamma, the pixels' area) does not move the
// centre either, except through the pixel grid's sampling of the edge: on clean renders
// (blur 0.5) 0.005 px RMS against the centroid's 0.002 px, so the fit is left to images
// with noise.
//
// GreyCentroid's centre of the same window (its levels measured once) where the page ring's
// grey levels scatter about their plane by under a grey level RMS (there the centroid's error
// is the smaller), or where the fit does not converge, finds no contrast of the expected
// polarity, a blur over half the semi-minor axis, or a centre more than a quarter of the
// semi-minor axis from the edge fit's. nullopt (the caller keeps the edge fit's centre) where
// GreyCentroid gives none. Cost: 3-5 passes over the window: about 55 microseconds for a
// circle 18 px across, 5 times GreyCentroid.
std::optional<Eigen::Vector2d> ModelCentre(const ImageView8& image, const Ellipse& ellipse,
                                           bool light, double max_scale);

}  // namespace linecal

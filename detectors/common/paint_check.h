#pragma once
// The whole-board paint checks of the board detectors: does the image show the board's
// printed black and white where a fitted homography puts them? A board identified on the
// wrong pattern (another board, clutter) fails them even when its features fit the
// homography. Both compare grey levels of nearby points of opposite (or differing) paint,
// which see the same light: an illumination gradient or a gamma cancels, where a
// binarisation by local contrast reads large white areas under a 4:1 gradient as dark.

#include <Eigen/Core>
#include <functional>
#include <optional>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"

namespace linecal {

// True when the image agrees with the board's printed paint. Of a 32 x 32 grid of probes over
// the page, those clear of printed edges by 1.5 px and inside the image are compared each with
// its 4 nearest probes of the opposite paint within 15% of the page; a probe agrees when every
// black one of its pairs is darker than 0.6 of the white one. At least min_agreement of the
// black probes and of the white probes must agree (each paint counted only with 8 probes or
// more; false with fewer than 8 in all). H_image_board maps board metres to image pixels;
// px_per_m is the board's scale in the image (for the edge clearance). Cost: 1024 paint
// look-ups and a neighbour search of about 80 probes per probe, about 100 microseconds.
bool PaintAgrees(const Board& board, const Eigen::Matrix3d& H_image_board, const ImageView8& image,
                 double px_per_m, double min_agreement);

// Where a board point (metres) lies in the image, or nullopt where the caller's model of the
// board does not reach (a board bent by a lens and known only near its markers). Such probes
// are left out as those off the image are.
using BoardToImage = std::function<std::optional<Eigen::Vector2d>(const Eigen::Vector2d&)>;

// PaintAgrees through any mapping of the board into the image: the same probes and test.
bool PaintAgrees(const Board& board, const BoardToImage& to_image, const ImageView8& image,
                 double px_per_m, double min_agreement);

// A set of board points (metres, board frame).
using BoardRegion = std::function<bool(const Eigen::Vector2d&)>;

// PaintAgrees for a board that something in front of it may partly hide (another board, a
// post): a hidden area shows the occluder's paint, not the board's. When the whole page fails,
// the disagreeing probes are grouped (probes up to 2 grid steps apart are one group), and a
// group that reaches the page's rim and holds no point of `seen` (the areas the detector read
// its features from: what was read is not hidden) is left out of the vote; the rest must then
// pass as in PaintAgrees. A board identified on the wrong pattern disagrees where the print
// differs, inside the page and around what was read, and still fails. Cost: PaintAgrees's, plus
// a grouping of the 1024 probes and one `seen` call per disagreeing probe when the page fails.
bool VisiblePaintAgrees(const Board& board, const BoardToImage& to_image, const ImageView8& image,
                        double px_per_m, double min_agreement, const BoardRegion& seen);

// Two boards that print the same features (the ArUco and round-hole boards share their four
// markers, docs/boards.md) differ only in some of their paint, and a binarisation can be fooled
// there (a 4:1 illumination gradient darkens plain white paper below its local threshold).
// This votes on the grey image itself, pair by pair: on a 64 x 64 grid of probes, at each
// probe that one board prints black and the other white (2 px clear of edges on both), is
// the image darker than at the nearest probe both print white (within 15% of the page)?
// Each pair compares two nearby points under the same light, so gradients and gamma cancel.
// True when at least `min_share` of at least 8 votes go to `board`; false when `other` wins
// or when there are fewer votes (the boards cannot be told apart at this size). Cost: about
// 40k paint look-ups, under a millisecond.
bool PaintContrastPrefers(const Board& board, const Board& other,
                          const Eigen::Matrix3d& H_image_board, const ImageView8& image,
                          double px_per_m, double min_share);
// PaintContrastPrefers through any mapping of the board into the image.
bool PaintContrastPrefers(const Board& board, const Board& other, const BoardToImage& to_image,
                          const ImageView8& image, double px_per_m, double min_share);

}  // namespace linecal

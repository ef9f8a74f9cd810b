#pragma once
// What every board detector returns (docs/interfaces.md, `linecal detect`), and the reasons it can
// give when it finds no board. Detectors are pure functions over non-owning image views: no
// I/O, no threads, no global state; a detector either finds the whole board (found = true),
// or reports found = false with a reason and, only when they are certain, the features of a
// partly seen board (occlusion, a vertical board cut by the image border).

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "detectors/boards/board.h"
#include "detectors/core/image_view.h"

namespace linecal {

enum class DetectReason : std::uint8_t {
  kNone = 0,            // found
  kBadImage,            // the view is invalid (ImageView::Validate), or too small to hold a board
  kLowContrast,         // nothing in the image has the contrast of a printed board
  kNoCandidates,        // no feature candidates of this board's kind
  kTooFewFeatures,      // candidates, but too few to identify the board
  kAmbiguous,           // more than one way to identify the board (e.g. two boards in view)
  kVerificationFailed,  // a candidate board failed the geometric check of the whole board
  kWrongBoard,          // the pattern found belongs to another board (e.g. other marker ids)
  kPartial,             // only part of the board is visible; the certain features are reported
};

// "", "bad_image", "low_contrast", "no_candidates", "too_few_features", "ambiguous",
// "verification_failed", "wrong_board", "partial".
const char* DetectReasonName(DetectReason reason);

struct DetectedFeature {
  int id = 0;                                         // BoardFeature::id
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();    // sub-pixel, pixel-centre convention
  Eigen::Vector2d p_board = Eigen::Vector2d::Zero();  // BoardFeature::p_board, metres
  int marker = -1;                                    // BoardFeature::marker
};

struct Detection {
  bool found = false;
  DetectReason reason = DetectReason::kNoCandidates;
  std::vector<DetectedFeature> features;  // ordered by id
};

// Below this side no board of docs/boards.md (smallest squares and cells 12 px, circles a few
// pixels wide) fits in an image.
inline constexpr int kMinDetectImageSide = 16;

// The checks every image detector opens with: kWrongBoard when `board` is not of `type`;
// kBadImage for an invalid view, one under kMinDetectImageSide a side, or invalid options
// (`options_valid` false); kNone to go on. O(1).
DetectReason CheckDetectorInput(const ImageView8& image, const Board& board, BoardType type,
                                bool options_valid);

}  // namespace linecal

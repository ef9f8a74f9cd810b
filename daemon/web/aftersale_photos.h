#pragma once
// The after-sale page's photos kept in linecald (docs/console.md, "The after-sale page"): the
// photo a page uploaded, decoded as `linecal aftersale` reads it, and the page's latest
// solution on it, so that the daemon can draw the bird's-eye view of that photo through that
// solution (station/aftersale/overlay.h BirdsEyePicture, the command's <name>-birdseye.png).
// A photo is named by a random id the upload answers (128 bits: not guessable, so one page
// cannot ask for another's photo), not by the session, since the page works without a login
// when the daemon has no auth_token. Memory is bounded: at most kMaxKeptPhotoPixels of grey
// photos; the least recently used go first (the page then says to upload it again).
// Thread safety: every method may be called from any thread.

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "detectors/core/image_view.h"
#include "station/solvers/lane_calibration.h"

namespace linecal {

// Pixels of the photos kept at once (one byte a pixel): two photos of the largest size
// accepted (aftersale_api.h kMaxPhotoPixels), or 24 of a 1920 x 1080 camera.
inline constexpr std::int64_t kMaxKeptPhotoPixels = 50'000'000;

// A solve of the page: the solver's input (with the intrinsics) and its result.
struct AftersaleSolution {
  LaneCalibrationInput input;
  LaneCalibrationResult result;
};

class AftersalePhotos {
 public:
  // Keeps `photo` (dropping the least recently used ones beyond kMaxKeptPhotoPixels); its id,
  // 32 hex digits. Internal when the random generator fails.
  absl::StatusOr<std::string> Keep(Image8 photo);
  // Photo `id`'s size: NotFound "photo_id: '...' is not kept ..." when it is not (never
  // uploaded, or dropped for newer ones).
  absl::StatusOr<std::pair<int, int>> Size(const std::string& id);
  // Records the photo's latest solve (nullopt: the latest was refused); its number, counting
  // from 1. NotFound as Size.
  absl::StatusOr<int> SetSolution(const std::string& id, std::optional<AftersaleSolution> solution);
  // The bird's-eye view of the photo through its latest solution, as PNG bytes. NotFound as
  // Size; FailedPrecondition when the photo has no solution (none yet, or the latest solve was
  // refused). Cost: BirdsEyePicture (a 320 x 800 page, a lens projection a pixel) and its PNG.
  absl::StatusOr<std::string> BirdsEyePng(const std::string& id);

 private:
  struct Kept {
    std::string id;
    std::shared_ptr<const Image8> photo;
    std::shared_ptr<const AftersaleSolution> solution;
    int solves = 0;
  };
  // The kept photo `id`, made the most recently used; nullptr when not kept. Needs mutex_.
  Kept* Find(const std::string& id);

  std::mutex mutex_;
  std::list<Kept> kept_;  // most recently used first
  std::int64_t pixels_ = 0;
};

}  // namespace linecal

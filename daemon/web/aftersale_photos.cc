#include "daemon/web/aftersale_photos.h"

#include <openssl/rand.h>

#include <array>

#include "absl/strings/escaping.h"
#include "absl/strings/str_cat.h"
#include "daemon/store/store.h"
#include "station/aftersale/overlay.h"
#include "station/camera/camera_model.h"
#include "station/io/image_io.h"

namespace linecal {
namespace {

absl::Status NotKept(const std::string& id) {
  return absl::NotFoundError(absl::StrCat(
      "photo_id: ", QuoteInput(id),
      " is not kept (never uploaded, or dropped for newer photos): upload the photo again "
      "(POST /api/aftersale/photo)"));
}

std::int64_t PixelsOf(const Image8& photo) {
  return static_cast<std::int64_t>(photo.width) * photo.height;
}

}  // namespace

absl::StatusOr<std::string> AftersalePhotos::Keep(Image8 photo) {
  std::array<unsigned char, 16> bytes{};
  if (RAND_bytes(bytes.data(), static_cast<int>(bytes.size())) != 1) {
    return absl::InternalError("photo: the random generator failed");
  }
  std::string id = absl::BytesToHexString(
      absl::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
  const std::int64_t pixels = PixelsOf(photo);
  std::lock_guard<std::mutex> lock(mutex_);
  while (!kept_.empty() && pixels_ + pixels > kMaxKeptPhotoPixels) {
    pixels_ -= PixelsOf(*kept_.back().photo);
    kept_.pop_back();
  }
  kept_.push_front({id, std::make_shared<const Image8>(std::move(photo)), nullptr, 0});
  pixels_ += pixels;
  return id;
}

AftersalePhotos::Kept* AftersalePhotos::Find(const std::string& id) {
  for (auto it = kept_.begin(); it != kept_.end(); ++it) {
    if (it->id != id) continue;
    kept_.splice(kept_.begin(), kept_, it);
    return &kept_.front();
  }
  return nullptr;
}

absl::StatusOr<std::pair<int, int>> AftersalePhotos::Size(const std::string& id) {
  std::lock_guard<std::mutex> lock(mutex_);
  const Kept* k = Find(id);
  if (k == nullptr) return NotKept(id);
  return std::pair{k->photo->width, k->photo->height};
}

absl::StatusOr<int> AftersalePhotos::SetSolution(const std::string& id,
                                                 std::optional<AftersaleSolution> solution) {
  std::lock_guard<std::mutex> lock(mutex_);
  Kept* k = Find(id);
  if (k == nullptr) return NotKept(id);
  k->solution =
      solution ? std::make_shared<const AftersaleSolution>(*std::move(solution)) : nullptr;
  return ++k->solves;
}

absl::StatusOr<std::string> AftersalePhotos::BirdsEyePng(const std::string& id) {
  std::shared_ptr<const Image8> photo;
  std::shared_ptr<const AftersaleSolution> solution;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const Kept* k = Find(id);
    if (k == nullptr) return NotKept(id);
    if (k->solution == nullptr) {
      return absl::FailedPreconditionError(
          absl::StrCat("birdseye: photo ", QuoteInput(id),
                       k->solves == 0 ? " has no solution yet: solve its lane points first (POST "
                                        "/api/aftersale with its photo_id)"
                                      : " has no solution: its latest solve was refused"));
    }
    photo = k->photo;
    solution = k->solution;
  }
  // Drawn outside the lock: the shared pointers keep photo and solution alive if dropped.
  absl::StatusOr<CameraModel> camera = CameraModel::Create(solution->input.intrinsics);
  if (!camera.ok()) return camera.status();
  return EncodePngRgb(BirdsEyePicture(*photo, *camera, solution->input, solution->result),
                      "birdseye");
}

}  // namespace linecal

#include "detectors/core/image_view.h"

namespace linecal {

const char* ImageViewErrorName(ImageViewError e) {
  switch (e) {
    case ImageViewError::kOk:
      return "ok";
    case ImageViewError::kNullData:
      return "null_data";
    case ImageViewError::kEmpty:
      return "empty_image";
    case ImageViewError::kNegativeSize:
      return "negative_size";
    case ImageViewError::kTooLarge:
      return "image_too_large";
    case ImageViewError::kStrideTooSmall:
      return "stride_too_small";
    case ImageViewError::kStrideMisaligned:
      return "stride_misaligned";
  }
  return "unknown";
}

}  // namespace linecal

#pragma once
// One grey frame from a live camera driver (aravis_camera.h, v4l2_camera.h).

#include <cstdint>

#include "detectors/core/image_view.h"

namespace linecal {

struct CameraFrame {
  Image8 image;
  std::int64_t t_ns = 0;  // host time the frame was complete, ns since the Unix epoch
  int attempts = 0;       // frames received for this one, the dropped incomplete ones included
};

}  // namespace linecal

#pragma once
// The realistic cameras of docs/conventions.md and docs/acceptance.md that tests across the
// tree share: a 1920 x 1080 front camera with mild and with strong (wide-angle) distortion,
// and a 190-degree fisheye of 1280 x 960. One definition, so a test of the camera model and a
// test of a detector through a real lens use the same lens.

#include "station/camera/camera_model.h"

namespace linecal::reference_cameras {

// 1920 x 1080, f 2000 px, k1 -0.12.
inline CameraIntrinsics MildPinhole() {
  CameraIntrinsics c;
  c.type = CameraModelType::kPinhole;
  c.width = 1920;
  c.height = 1080;
  c.fx = 2000.0;
  c.fy = 2001.5;
  c.cx = 962.7;
  c.cy = 537.4;
  c.k1 = -0.12;
  c.k2 = 0.08;
  c.p1 = 2e-4;
  c.p2 = -1e-4;
  c.k3 = -0.02;
  return c;
}

// The same sensor behind a wide-angle lens: f 1000 px, k1 -0.30.
inline CameraIntrinsics StrongPinhole() {
  CameraIntrinsics c = MildPinhole();
  c.fx = 1000.0;
  c.fy = 1000.8;
  c.k1 = -0.30;
  c.k2 = 0.10;
  c.p1 = 1e-3;
  c.p2 = -5e-4;
  c.k3 = -0.01;
  return c;
}

// 1280 x 960; theta_d(95 deg) * 366.2 = 640 px: 190 degrees across the width.
inline CameraIntrinsics Fisheye190() {
  CameraIntrinsics c;
  c.type = CameraModelType::kFisheye;
  c.width = 1280;
  c.height = 960;
  c.fx = 366.2;
  c.fy = 366.6;
  c.cx = 641.2;
  c.cy = 477.2;
  c.k1 = 0.03;
  c.k2 = -0.005;
  c.k3 = 0.001;
  c.k4 = -0.0002;
  return c;
}

}  // namespace linecal::reference_cameras

#pragma once
// The per-camera picture of `linecal calibrate --report DIR`: the camera's first frame with
// what the calibration found and what it implies, to judge a result by eye.

#include "detectors/core/image_view.h"
#include "station/io/image_io.h"
#include "station/pipeline/capture_calibration.h"
#include "tools/linecal/detection_overlay.h"

namespace linecal::tools {

// Drawing colours (RGB), for the legend and for tests that look for them.
inline constexpr RgbColour kModelColour = {255, 0, 255};    // reprojected board features
inline constexpr RgbColour kHorizonColour = {0, 255, 255};  // the horizon and the vanishing point
inline constexpr RgbColour kGroundGridColour = {255, 255, 0};
// Radius of the ring drawn around each reprojected board feature and around the vanishing
// point, pixels.
inline constexpr int kModelRingPx = 6;
inline constexpr int kVanishingPointRingPx = 8;

// The grey `image` (the first frame of camera `sensor`) as RGB with, when the camera was
// solved: a ground grid (lines 1 m apart across the camera's horizontal view direction, 2 to
// 50 m ahead of it, mapped through the ground homography and then the lens), the horizon (the
// images of every horizontal direction; it passes through the vanishing point, ringed) and
// every feature of the camera's target boards reprojected from the solved pose (rings); then
// always the detected features (DrawFeatures, green for whole boards) and a legend with the
// verdict, yaw/pitch/roll and the seed formulas' results. Pose, homography and detections
// come from `result`; the layout and aligner from `capture`. Cost: one pass over the image
// plus O(features + grid samples).
RgbImage DrawCalibrationReport(const ImageView8& image, const Capture& capture,
                               const SensorModel& sensor, const SensorCalibration& result);

}  // namespace linecal::tools

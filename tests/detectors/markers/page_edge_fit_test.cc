// FitMarkerSidesToPage on renders with exact ground truth (station/sim/camera_render.h): a
// marker's corners, started off their truth, come back to it on small, blurred markers of
// the ArUco and round-hole boards, where edge-point centroids are a fifth of a pixel off;
// and a bad start or an image without the marker leaves the corners as they were.
#include "detectors/markers/page_edge_fit.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>

#include "tests/detectors/circle/circle_scene.h"

namespace linecal {
namespace {

Board MakeBoard(BoardType type) {
  BoardParams p;
  p.type = type;
  return *Board::Create(p);
}

struct MarkerTruth {
  std::array<Eigen::Vector2d, 4> board;
  std::array<Eigen::Vector2d, 4> image;
};

// Marker `marker`'s corners (feature ids 4 marker_index + c, docs/boards.md) on the page and in
// the render.
MarkerTruth Truth(const Board& board, const CameraFrame& frame, int marker_index) {
  MarkerTruth t;
  for (int c = 0; c < 4; ++c) {
    const int id = 4 * marker_index + c;
    t.board[c] = board.features()[id].p_board;
    bool seen = false;
    for (const RenderedFeature& f : frame.features) {
      if (f.feature_id != id) continue;
      t.image[c] = f.uv_px;
      seen = true;
    }
    EXPECT_TRUE(seen) << "corner " << id << " not in view";
  }
  return t;
}

// The farthest boards of the evaluation (4 px data cells), blur 1 px and no noise: only the
// estimator's own error is left.
CameraFrame FarRender(BoardType type, double yaw_deg, double pitch_deg, double roll_deg,
                      std::uint64_t seed) {
  const CameraModel camera = circle_scene::Camera();
  const double far_m = camera.intrinsics().fx * 0.040 / 4.0;  // docs/boards.md: 40 mm cells
  absl::StatusOr<CameraFrame> frame = circle_scene::RenderScene(
      circle_scene::OneBoard(
          type, circle_scene::EvaluationPose(far_m, yaw_deg, pitch_deg, roll_deg, seed)),
      circle_scene::Effects(0.0, 1.0), seed, camera);
  EXPECT_TRUE(frame.ok()) << frame.status();
  return *std::move(frame);
}

// Each corner moved off its truth by up to 0.35 px (a coarse edge fit's error at this size).
std::array<Eigen::Vector2d, 4> Disturbed(const std::array<Eigen::Vector2d, 4>& truth) {
  const std::array<Eigen::Vector2d, 4> offsets = {
      Eigen::Vector2d(0.3, -0.2), Eigen::Vector2d(-0.25, 0.1), Eigen::Vector2d(0.1, 0.3),
      Eigen::Vector2d(-0.2, -0.25)};
  std::array<Eigen::Vector2d, 4> out;
  for (int c = 0; c < 4; ++c) out[c] = truth[c] + offsets[c];
  return out;
}

double RmsPx(const std::array<Eigen::Vector2d, 4>& a, const std::array<Eigen::Vector2d, 4>& b) {
  double sum = 0.0;
  for (int c = 0; c < 4; ++c) sum += (a[c] - b[c]).squaredNorm();
  return std::sqrt(sum / 4.0);
}

TEST(PageEdgeFitTest, SmallBlurredMarkersComeBackToTheirTruth) {
  struct Case {
    BoardType type;
    double yaw, pitch, roll;
    std::uint64_t seed;
  };
  // Straight on, and foreshortened across either side (the case the centroids get most
  // wrong: their bias depends on the cell width across each side).
  for (const Case& k :
       {Case{BoardType::kAruco, 0, 0, 0, 3}, Case{BoardType::kAruco, -50, 0, -30, 5},
        Case{BoardType::kAruco, 0, -50, 30, 7}, Case{BoardType::kRoundHole, 0, 0, 0, 3},
        Case{BoardType::kRoundHole, 50, 0, 30, 11}}) {
    SCOPED_TRACE(::testing::Message() << BoardTypeName(k.type) << " yaw " << k.yaw << " pitch "
                                      << k.pitch << " roll " << k.roll);
    const Board board = MakeBoard(k.type);
    const CameraFrame frame = FarRender(k.type, k.yaw, k.pitch, k.roll, k.seed);
    double sum_sq = 0.0;
    for (int marker = 0; marker < 4; ++marker) {
      const MarkerTruth t = Truth(board, frame, marker);
      std::array<Eigen::Vector2d, 4> corners = Disturbed(t.image);
      ASSERT_TRUE(FitMarkerSidesToPage(frame.image8.view(), board, 6, t.board, 12.0, &corners))
          << "marker " << marker;
      const double rms = RmsPx(corners, t.image);
      sum_sq += rms * rms;
      // The start was 0.25 px RMS off.
      EXPECT_LT(rms, 0.13) << "marker " << marker;
    }
    const double board_rms = std::sqrt(sum_sq / 4.0);
    std::printf("%s yaw %.0f pitch %.0f: corner RMS %.4f px\n", BoardTypeName(k.type), k.yaw,
                k.pitch, board_rms);
    // Edge-point centroids are 0.2-0.3 px RMS off on these renders (docs/detectors.md); the
    // page fit's own error, before the board fit takes out the common dilation, is under
    // docs/acceptance.md's noisy bar.
    EXPECT_LT(board_rms, 0.1);
  }
}

TEST(PageEdgeFitTest, CornersOffByMoreThanHalfACellAreLeftAsTheyWere) {
  const Board board = MakeBoard(BoardType::kAruco);
  const CameraFrame frame = FarRender(BoardType::kAruco, 0, 0, 0, 3);
  const MarkerTruth t = Truth(board, frame, 0);
  // A whole cell (4 px) to the right: the profiles see the wrong page; whatever the fit finds
  // is farther than half a cell, or fails.
  std::array<Eigen::Vector2d, 4> corners = t.image;
  for (Eigen::Vector2d& c : corners) c.x() += 4.0;
  const std::array<Eigen::Vector2d, 4> before = corners;
  const bool moved = FitMarkerSidesToPage(frame.image8.view(), board, 6, t.board, 12.0, &corners);
  if (moved) {
    // Accepted only if it stayed within half a cell of the start.
    for (int c = 0; c < 4; ++c) EXPECT_LE((corners[c] - before[c]).norm(), 2.0 + 1e-9);
  } else {
    for (int c = 0; c < 4; ++c) EXPECT_EQ(corners[c], before[c]);
  }
}

TEST(PageEdgeFitTest, NoMarkerInTheImageFailsAndKeepsTheCorners) {
  const Board board = MakeBoard(BoardType::kAruco);
  const CameraFrame frame = FarRender(BoardType::kAruco, 0, 0, 0, 3);
  const MarkerTruth t = Truth(board, frame, 0);
  // A flat grey image: no contrast to fit.
  const Image8 flat(frame.image8.width, frame.image8.height, 128);
  std::array<Eigen::Vector2d, 4> corners = t.image;
  EXPECT_FALSE(FitMarkerSidesToPage(flat.view(), board, 6, t.board, 12.0, &corners));
  for (int c = 0; c < 4; ++c) EXPECT_EQ(corners[c], t.image[c]);
  // The marker at the image's edge: profiles leave the image.
  std::array<Eigen::Vector2d, 4> off = t.image;
  for (Eigen::Vector2d& c : off) c -= t.image[0] - Eigen::Vector2d(1.0, 1.0);
  const std::array<Eigen::Vector2d, 4> before = off;
  EXPECT_FALSE(FitMarkerSidesToPage(frame.image8.view(), board, 6, t.board, 12.0, &off));
  for (int c = 0; c < 4; ++c) EXPECT_EQ(off[c], before[c]);
}

}  // namespace
}  // namespace linecal

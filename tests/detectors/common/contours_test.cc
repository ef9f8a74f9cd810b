// Connected components, contour tracing and quad extraction on small hand-made binary
// images whose answers are known exactly.
#include "detectors/common/contours.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

namespace linecal {
namespace {

Image8 Blank(int w, int h) { return Image8(w, h, 0); }

void FillRect(Image8* img, int x0, int y0, int x1, int y1) {
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) img->at(x, y) = 1;
  }
}

// A filled convex polygon: pixels whose centre lies inside every edge's half-plane.
void FillConvex(Image8* img, const std::vector<Eigen::Vector2d>& poly) {
  for (int y = 0; y < img->height; ++y) {
    for (int x = 0; x < img->width; ++x) {
      bool inside = true;
      for (std::size_t k = 0; k < poly.size() && inside; ++k) {
        const Eigen::Vector2d a = poly[k];
        const Eigen::Vector2d b = poly[(k + 1) % poly.size()];
        const double cross = (b.x() - a.x()) * (y - a.y()) - (b.y() - a.y()) * (x - a.x());
        inside = cross >= 0.0;  // clockwise in y-down coordinates: the inside is on the right
      }
      if (inside) img->at(x, y) = 1;
    }
  }
}

TEST(ContoursTest, DiagonalNeighboursAreSeparateComponents) {
  Image8 img = Blank(20, 20);
  FillRect(&img, 2, 2, 5, 5);
  FillRect(&img, 6, 6, 9, 9);  // touches the first square only at a corner
  const ComponentLabels labels = LabelComponents(img.view());
  ASSERT_EQ(labels.components.size(), 2u);
  EXPECT_EQ(labels.components[0].area_px, 16);
  EXPECT_EQ(labels.components[0].min_x, 2);
  EXPECT_EQ(labels.components[0].max_y, 5);
  EXPECT_EQ(labels.components[1].first_x, 6);
  EXPECT_EQ(labels.components[1].first_y, 6);
  EXPECT_EQ(labels.LabelAt(3, 3), 1);
  EXPECT_EQ(labels.LabelAt(7, 7), 2);
  EXPECT_EQ(labels.LabelAt(0, 0), 0);
}

TEST(ContoursTest, UShapeMergesIntoOneComponent) {
  // Two columns joined only by their bottom row: the second column's runs start as a new
  // component and must be united with the first at the bottom.
  Image8 img = Blank(12, 12);
  FillRect(&img, 1, 1, 2, 8);
  FillRect(&img, 7, 1, 8, 8);
  FillRect(&img, 1, 9, 8, 9);
  const ComponentLabels labels = LabelComponents(img.view());
  ASSERT_EQ(labels.components.size(), 1u);
  EXPECT_EQ(labels.components[0].area_px, 2 * 8 * 2 + 8);
  EXPECT_EQ(labels.LabelAt(8, 1), labels.LabelAt(1, 1));
}

// Without the label image, the components are the same, their runs cover exactly the pixels
// the label image gives them, and every contour is traced the same: shapes touching at a
// corner, a U whose arms merge late, a ring, a component on the image's border, and rows
// wider than 64 pixels (the run search takes 64 pixels at a time).
TEST(ContoursTest, RunsGiveTheSameComponentsAndContoursAsTheLabelImage) {
  Image8 img = Blank(150, 40);
  FillRect(&img, 2, 2, 5, 5);
  FillRect(&img, 6, 6, 9, 9);
  FillRect(&img, 20, 1, 21, 20);
  FillRect(&img, 26, 1, 27, 20);
  FillRect(&img, 20, 21, 27, 21);
  FillRect(&img, 40, 5, 60, 25);
  for (int y = 10; y <= 20; ++y) {
    for (int x = 45; x <= 55; ++x) img.at(x, y) = 0;
  }
  FillRect(&img, 0, 30, 149, 39);  // the whole width, on the left, right and bottom borders
  FillRect(&img, 63, 2, 128, 3);   // across the 64-pixel boundaries
  img.at(100, 10) = 1;
  const ComponentLabels labels = LabelComponents(img.view());
  const ComponentLabels runs = LabelComponents(img.view(), /*label_image=*/false);
  EXPECT_TRUE(runs.labels.empty());
  ASSERT_EQ(runs.components.size(), 7u);
  ASSERT_EQ(labels.components.size(), runs.components.size());
  ASSERT_EQ(runs.run_begin.size(), runs.components.size() + 1);
  std::vector<std::int32_t> drawn(labels.labels.size(), 0);
  for (int c = 0; c < static_cast<int>(runs.components.size()); ++c) {
    const Component& a = labels.components[c];
    const Component& b = runs.components[c];
    EXPECT_EQ(a.area_px, b.area_px);
    EXPECT_EQ(a.min_x, b.min_x);
    EXPECT_EQ(a.max_x, b.max_x);
    EXPECT_EQ(a.min_y, b.min_y);
    EXPECT_EQ(a.max_y, b.max_y);
    EXPECT_EQ(a.first_x, b.first_x);
    EXPECT_EQ(a.first_y, b.first_y);
    for (int r = runs.run_begin[c]; r < runs.run_begin[c + 1]; ++r) {
      const PixelRun& run = runs.runs[r];
      for (int x = run.x0; x < run.x1; ++x) drawn[run.y * img.width + x] = c + 1;
    }
    EXPECT_EQ(TraceOuterContour(labels, c), TraceOuterContour(runs, c)) << "component " << c;
  }
  EXPECT_EQ(drawn, labels.labels);
}

TEST(ContoursTest, TracesASquareClockwiseFromItsFirstPixel) {
  Image8 img = Blank(10, 10);
  FillRect(&img, 3, 4, 5, 6);
  const ComponentLabels labels = LabelComponents(img.view());
  const std::vector<Eigen::Vector2i> contour = TraceOuterContour(labels, 0);
  const std::vector<Eigen::Vector2i> expected = {{3, 4}, {4, 4}, {5, 4}, {5, 5},
                                                 {5, 6}, {4, 6}, {3, 6}, {3, 5}};
  EXPECT_EQ(contour, expected);
}

TEST(ContoursTest, TracesSinglePixelAndThinLine) {
  Image8 img = Blank(10, 10);
  img.at(2, 2) = 1;
  FillRect(&img, 4, 7, 8, 7);
  const ComponentLabels labels = LabelComponents(img.view());
  ASSERT_EQ(labels.components.size(), 2u);
  EXPECT_EQ(TraceOuterContour(labels, 0), std::vector<Eigen::Vector2i>{Eigen::Vector2i(2, 2)});
  // A one-pixel-wide line is walked out and back: its end pixels once, the others twice.
  EXPECT_EQ(TraceOuterContour(labels, 1).size(), 8u);
}

TEST(ContoursTest, PolygonOfARectangleContourIsItsCorners) {
  Image8 img = Blank(40, 30);
  FillRect(&img, 5, 6, 30, 20);
  const ComponentLabels labels = LabelComponents(img.view());
  const std::vector<Eigen::Vector2i> contour = TraceOuterContour(labels, 0);
  const std::vector<int> vertices = ApproximateClosedPolygon(contour, 1.0);
  ASSERT_EQ(vertices.size(), 4u);
  std::vector<Eigen::Vector2i> corners;
  for (int v : vertices) corners.push_back(contour[v]);
  EXPECT_EQ(corners, (std::vector<Eigen::Vector2i>{{5, 6}, {30, 6}, {30, 20}, {5, 20}}));
}

TEST(ContoursTest, FindsARotatedSquareAndNotADiscOrATriangle) {
  Image8 img = Blank(200, 120);
  // A 40 px square turned by 25 degrees, centred at (50, 60), clockwise in the image.
  const double a = 25.0 * std::numbers::pi / 180.0;
  std::vector<Eigen::Vector2d> square;
  for (int k = 0; k < 4; ++k) {
    const double t = a + k * std::numbers::pi / 2.0 + std::numbers::pi / 4.0 * 5.0;
    square.push_back(Eigen::Vector2d(50, 60) +
                     20.0 * std::sqrt(2.0) * Eigen::Vector2d(std::cos(t), std::sin(t)));
  }
  FillConvex(&img, square);
  // A disc of radius 18 at (110, 60) and a triangle at the right.
  for (int y = 0; y < img.height; ++y) {
    for (int x = 0; x < img.width; ++x) {
      if (std::hypot(x - 110.0, y - 60.0) < 18.0) img.at(x, y) = 1;
    }
  }
  FillConvex(&img, {{150, 90}, {170, 30}, {190, 90}});
  const ComponentLabels labels = LabelComponents(img.view());
  ASSERT_EQ(labels.components.size(), 3u);
  const std::vector<Quad> quads = FindQuads(labels);
  ASSERT_EQ(quads.size(), 1u);
  // Contour corners are boundary pixel centres: within 1.5 px of the true corners (half a
  // pixel inside the edge, plus the pixel steps of a turned edge).
  constexpr double kContourCornerTolPx = 1.5;
  double turn = 0.0;
  for (int k = 0; k < 4; ++k) {
    double best = 1e9;
    for (const Eigen::Vector2d& c : square)
      best = std::min(best, (quads[0].corners_px[k] - c).norm());
    EXPECT_LT(best, kContourCornerTolPx) << "corner " << k;
    const Eigen::Vector2d e0 = quads[0].corners_px[(k + 1) % 4] - quads[0].corners_px[k];
    const Eigen::Vector2d e1 = quads[0].corners_px[(k + 2) % 4] - quads[0].corners_px[(k + 1) % 4];
    turn += e0.x() * e1.y() - e0.y() * e1.x();
  }
  EXPECT_GT(turn, 0.0);  // clockwise in the image
}

TEST(ContoursTest, ChamferedSquareIsAQuadOnlyWhenMoreVerticesAreAllowed) {
  Image8 img = Blank(160, 80);
  // A 40 px square at (10..50, 20..60) with every corner cut by 9 px along each side: eight
  // vertices that Douglas-Peucker keeps, too far apart to merge.
  FillConvex(&img,
             {{19, 20}, {41, 20}, {50, 29}, {50, 51}, {41, 60}, {19, 60}, {10, 51}, {10, 29}});
  // A regular hexagon of radius 20 at (110, 40): its largest quad holds two thirds of it.
  std::vector<Eigen::Vector2d> hexagon;
  for (int k = 0; k < 6; ++k) {
    const double t = k * std::numbers::pi / 3.0;
    hexagon.push_back(Eigen::Vector2d(110, 40) + 20.0 * Eigen::Vector2d(std::cos(t), std::sin(t)));
  }
  FillConvex(&img, hexagon);
  const ComponentLabels labels = LabelComponents(img.view());
  ASSERT_EQ(labels.components.size(), 2u);
  EXPECT_TRUE(FindQuads(labels).empty());
  QuadOptions options;
  options.max_polygon_vertices = 8;
  const std::vector<Quad> quads = FindQuads(labels, options);
  ASSERT_EQ(quads.size(), 1u);
  // The square's own corners, where its sides' lines meet: within a pixel (the contour runs
  // through the centres of the pixels inside its edges).
  const std::vector<Eigen::Vector2d> corners = {{10, 20}, {50, 20}, {50, 60}, {10, 60}};
  for (const Eigen::Vector2d& c : corners) {
    double best = 1e9;
    for (const Eigen::Vector2d& q : quads[0].corners_px) best = std::min(best, (q - c).norm());
    EXPECT_LT(best, 1.0);
  }
}

// A w x h rectangle at (x0, y0) whose corners are arcs of radius r, clockwise in the image.
std::vector<Eigen::Vector2d> RoundedRectangle(double x0, double y0, double w, double h, double r) {
  const std::vector<Eigen::Vector2d> centres = {
      {x0 + w - r, y0 + r}, {x0 + w - r, y0 + h - r}, {x0 + r, y0 + h - r}, {x0 + r, y0 + r}};
  std::vector<Eigen::Vector2d> out;
  for (int k = 0; k < 4; ++k) {
    for (int i = 0; i <= 6; ++i) {
      const double t = (-0.5 + 0.5 * k + i / 12.0) * std::numbers::pi;
      out.push_back(centres[k] + r * Eigen::Vector2d(std::cos(t), std::sin(t)));
    }
  }
  return out;
}

TEST(ContoursTest, SquareWhoseShortSidesAreArcsIsAQuad) {
  Image8 img = Blank(60, 60);
  // Blur under a gamma rounds a small square's corners until its short sides are mostly arc
  // (squares of the square grid 26 x 13 px seen at pitch 50 degrees): the polygon's vertices
  // fall on the arcs, and no four of its edges are the sides.
  FillConvex(&img, RoundedRectangle(10, 20, 26, 13, 4.0));
  const ComponentLabels labels = LabelComponents(img.view());
  ASSERT_EQ(labels.components.size(), 1u);
  EXPECT_TRUE(FindQuads(labels).empty());
  QuadOptions options;
  options.max_polygon_vertices = 8;
  const std::vector<Quad> quads = FindQuads(labels, options);
  ASSERT_EQ(quads.size(), 1u);
  // Each corner lies on its arc: within the arc's radius (4 px) and the contour's half pixel
  // of the rectangle's corner, where the square grid's line fits take it.
  const std::vector<Eigen::Vector2d> corners = {{10, 20}, {36, 20}, {36, 33}, {10, 33}};
  for (const Eigen::Vector2d& c : corners) {
    double best = 1e9;
    for (const Eigen::Vector2d& q : quads[0].corners_px) best = std::min(best, (q - c).norm());
    EXPECT_LT(best, 4.5);
  }
}

TEST(ContoursTest, QuadsTouchingTheBorderAreDropped) {
  Image8 img = Blank(60, 60);
  FillRect(&img, 0, 10, 30, 40);
  const ComponentLabels labels = LabelComponents(img.view());
  EXPECT_TRUE(FindQuads(labels).empty());
}

}  // namespace
}  // namespace linecal

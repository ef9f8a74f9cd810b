// Board rasters against the reference PDFs (rendered by poppler's pdftoppm at test time),
// area-correct anti-aliasing, and the true-scale SVG.
#include "station/io/board_raster.h"

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <numbers>
#include <set>
#include <string>

#include "station/io/image_io.h"
#include "tests/support/external_data.h"

namespace linecal {
namespace {

Board MakeBoard(BoardType type) {
  BoardParams p;
  p.type = type;
  std::optional<Board> b = Board::Create(p);
  EXPECT_TRUE(b.has_value());
  return *b;
}

class BoardRasterTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("linecal_board_raster_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

TEST_F(BoardRasterTest, DefaultBoardsMatchTheirPdfs) {
  struct Case {
    BoardType type;
    const char* pdf;
  };
  const Case cases[] = {{BoardType::kChessboard, "chessboard.pdf"},
                        {BoardType::kCircle, "circle_board.pdf"},
                        {BoardType::kVertical, "vertical_board.pdf"},
                        {BoardType::kAruco, "aruco_marker_board.pdf"},
                        {BoardType::kApriltag, "april_board.pdf"},
                        {BoardType::kRoundHole, "round_hole_board.pdf"}};
  // Both rasters at 10 px/cm (1 px per mm); pixels that differ after thresholding at
  // mid-grey may only be edge pixels that the two anti-aliasers round differently (poppler
  // snaps rectangle edges to the pixel grid).
  constexpr double kMinAgreement = 0.995;
  // april_board.pdf also prints what the board deliberately does not model
  // (docs/boards.md): a 1 pt frame around the grid, which poppler draws a full pixel wide,
  // and a caption with axis arrows in the lower-left margin. Those pixels are left out:
  // page millimetres (x right, y down from the top-left), frame lines +-2 px.
  const auto apriltag_page_extra = [](int x, int y) {
    const auto near = [](int v, double line_mm) { return std::abs(v + 0.5 - line_mm) < 2.0; };
    const bool frame = (near(x, 20.68) || near(x, 820.32)) || (near(y, 52.68) || near(y, 852.33));
    const bool caption = x >= 50 && x < 260 && y >= 780 && y < 825;
    return frame || caption;
  };
  for (const Case& c : cases) {
    const Board board = MakeBoard(c.type);
    const int w = static_cast<int>(std::lround(1e3 * board.page_size_m().x()));
    const int h = static_cast<int>(std::lround(1e3 * board.page_size_m().y()));
    // The reference PDFs of the boards (docs/external-data.md).
    LINECAL_EXTERNAL_IN_OR_SKIP(pdf, std::string("patterns/") + c.pdf,
                                testing_support::ExternalRoot::kSpec);
    const std::string prefix = (dir_ / board.name()).string();
    const std::string command = "pdftoppm -gray -png -singlefile -scale-to-x " + std::to_string(w) +
                                " -scale-to-y " + std::to_string(h) + " '" + pdf + "' '" + prefix +
                                "'";
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
    const absl::StatusOr<Image8> reference = ReadImage8(prefix + ".png");
    ASSERT_TRUE(reference.ok()) << reference.status();
    ASSERT_EQ(reference->width, w) << board.name();
    ASSERT_EQ(reference->height, h) << board.name();

    BoardRasterOptions options;
    options.pixels_per_metre = 1000.0;
    const absl::StatusOr<Image8> ours = RasterizeBoard(board, options);
    ASSERT_TRUE(ours.ok()) << ours.status();
    ASSERT_EQ(ours->width, w);
    ASSERT_EQ(ours->height, h);
    std::size_t agree = 0, compared = 0;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        if (c.type == BoardType::kApriltag && apriltag_page_extra(x, y)) continue;
        ++compared;
        agree += (ours->at(x, y) < 128) == (reference->at(x, y) < 128);
      }
    }
    const double agreement = static_cast<double>(agree) / compared;
    std::printf("%-11s %5d x %-5d px: %.5f of %zu compared pixels agree with %s\n", board.name(), w,
                h, agreement, compared, c.pdf);
    EXPECT_GE(agreement, kMinAgreement) << board.name();
  }
}

// The 1-bit-border AprilGrid is the ordinary tag36h11 layout: stock libapriltag must decode
// every tag of our rendering, with corners where the board says; the 2-bit (Kalibr) grid
// must give it nothing (docs/boards.md).
TEST_F(BoardRasterTest, StockAprilTagDecodesOnlyTheOneBitGrid) {
  using Family = std::unique_ptr<apriltag_family_t, void (*)(apriltag_family_t*)>;
  using Detector = std::unique_ptr<apriltag_detector_t, void (*)(apriltag_detector_t*)>;
  for (int border_bits : {1, 2}) {
    BoardParams p;
    p.type = BoardType::kApriltag;
    p.apriltag_border_bits = border_bits;
    const Board board = *Board::Create(p);
    BoardRasterOptions options;
    options.pixels_per_metre = 2000.0;  // 8.8 mm bits are 17.6 px
    const absl::StatusOr<Image8> image = RasterizeBoard(board, options);
    ASSERT_TRUE(image.ok());
    image_u8_t view{image->width, image->height, image->width,
                    const_cast<std::uint8_t*>(image->pixels.data())};
    const Family family(tag36h11_create(), tag36h11_destroy);
    const Detector detector(apriltag_detector_create(), apriltag_detector_destroy);
    apriltag_detector_add_family(detector.get(), family.get());
    zarray_t* detections = apriltag_detector_detect(detector.get(), &view);
    const int n = zarray_size(detections);
    std::set<int> ids;
    for (int i = 0; i < n; ++i) {
      apriltag_detection_t* d;
      zarray_get(detections, i, &d);
      ids.insert(d->id);
      ASSERT_LT(d->id, 36);
      for (int c = 0; c < 4; ++c) {
        // Our corners run top-left, top-right, bottom-right, bottom-left; libapriltag's p[]
        // bottom-left, bottom-right, top-right, top-left for an upright tag, in a pixel frame
        // whose origin is the top-left pixel's corner (ours: its centre), hence +0.5.
        const Eigen::Vector2d f = board.features()[4 * d->id + c].p_board;
        const double u = (f.x() + 0.5 * board.page_size_m().x()) * options.pixels_per_metre;
        const double v = (0.5 * board.page_size_m().y() - f.y()) * options.pixels_per_metre;
        // libapriltag's corner fit on a clean render: a few tenths of a pixel.
        constexpr double kCornerTolerancePx = 0.5;
        EXPECT_NEAR(d->p[3 - c][0], u, kCornerTolerancePx) << "tag " << d->id << " corner " << c;
        EXPECT_NEAR(d->p[3 - c][1], v, kCornerTolerancePx) << "tag " << d->id << " corner " << c;
      }
    }
    apriltag_detections_destroy(detections);
    EXPECT_EQ(n, border_bits == 1 ? 36 : 0) << "border bits " << border_bits;
    EXPECT_EQ(ids.size(), border_bits == 1 ? 36u : 0u);
  }
}

TEST_F(BoardRasterTest, AntiAliasingIsAreaCorrect) {
  // Circle board: black strips and square (2 x 100 x 500 + 500 x 500), minus 28 white
  // circles of diameter 50 and the 200 x 70 white bar, plus the two black circles.
  const double circle = std::numbers::pi * 25.0 * 25.0;
  const double black_mm2 =
      2 * 100.0 * 500.0 + 500.0 * 500.0 - 28 * circle - 200.0 * 70.0 + 2 * circle;
  const Board board = MakeBoard(BoardType::kCircle);
  for (int supersample : {4, 16}) {
    BoardRasterOptions options;
    options.pixels_per_metre = 1000.0;  // 1 px = 1 mm^2
    options.supersample = supersample;
    const absl::StatusOr<Image8> image = RasterizeBoard(board, options);
    ASSERT_TRUE(image.ok());
    double darkness = 0;
    for (std::uint8_t v : image->pixels) darkness += (255 - v) / 255.0;
    // Each of the ~5000 circle-edge pixels is off by less than 1/(2 n^2) of a pixel (sample
    // grid) plus 1/510 (8-bit rounding), with random signs: the sum stays within 0.05%.
    constexpr double kRelTolerance = 5e-4;
    EXPECT_NEAR(darkness, black_mm2, kRelTolerance * black_mm2) << "supersample " << supersample;
    std::printf("supersample %2d: black area %.1f px vs %.1f mm^2 exact\n", supersample, darkness,
                black_mm2);
  }
}

TEST_F(BoardRasterTest, EdgePixelsAreGrey) {
  // An edge on a pixel boundary stays sharp; an edge through a pixel's middle halves it.
  const Board board = MakeBoard(BoardType::kChessboard);
  BoardRasterOptions options;
  options.pixels_per_metre = 2000.0;  // 0.5 mm pixels; edges on whole mm fall on pixel edges
  const absl::StatusOr<Image8> sharp = RasterizeBoard(board, options);
  ASSERT_TRUE(sharp.ok());
  // Square (100,100)-(250,250) PDF mm: pixel columns 200..499, rows 200..499 at 2 px/mm.
  EXPECT_EQ(sharp->at(200, 300), 0);
  EXPECT_EQ(sharp->at(199, 300), 255);
  // 1.335 px/mm: x = 100 mm falls in the middle of pixel 133 (133.5 px): half black.
  options.pixels_per_metre = 1335.0;
  const absl::StatusOr<Image8> soft = RasterizeBoard(board, options);
  ASSERT_TRUE(soft.ok());
  EXPECT_EQ(soft->at(133, 200), 128);  // (8 x 255 + 8 x 0) / 16, rounded
  EXPECT_EQ(soft->at(132, 200), 255);
  EXPECT_EQ(soft->at(134, 200), 0);
}

TEST_F(BoardRasterTest, RefusesBadOptions) {
  const Board board = MakeBoard(BoardType::kChessboard);
  BoardRasterOptions options;
  options.pixels_per_metre = 300 / 0.0254;  // 300 dpi: 30709 px wide
  const absl::StatusOr<Image8> big = RasterizeBoard(board, options);
  EXPECT_EQ(big.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(big.status().message().find("at most 6301.54 px/m"), std::string::npos) << big.status();
  options.pixels_per_metre = 0;
  EXPECT_FALSE(RasterizeBoard(board, options).ok());
  options.pixels_per_metre = 100;
  options.supersample = 0;
  EXPECT_FALSE(RasterizeBoard(board, options).ok());
}

TEST_F(BoardRasterTest, SvgIsTrueScale) {
  const Board board = MakeBoard(BoardType::kChessboard);
  const std::string svg = BoardSvg(board);
  EXPECT_NE(svg.find("width=\"2600mm\" height=\"500mm\" viewBox=\"0 0 2600 500\""),
            std::string::npos);
  // The page, then the six squares; the first square at PDF (100, 100), 150 mm.
  EXPECT_NE(svg.find("<rect x=\"0\" y=\"0\" width=\"2600\" height=\"500\" fill=\"#ffffff\"/>"),
            std::string::npos);
  EXPECT_NE(svg.find("<rect x=\"100\" y=\"100\" width=\"150\" height=\"150\" fill=\"#000000\"/>"),
            std::string::npos)
      << svg;
  std::size_t rects = 0;
  for (std::size_t at = svg.find("<rect"); at != std::string::npos;
       at = svg.find("<rect", at + 1)) {
    ++rects;
  }
  EXPECT_EQ(rects, board.shapes().size());

  const Board holes = MakeBoard(BoardType::kRoundHole);
  const std::string hole_svg = BoardSvg(holes);
  EXPECT_NE(hole_svg.find("<circle cx=\"250\" cy=\"250\" r=\"120\" fill=\"#ffffff\" "
                          "stroke=\"#808080\""),
            std::string::npos);

  BoardParams scaled;
  scaled.type = BoardType::kAruco;
  scaled.scale = 0.5;
  const std::string half = BoardSvg(*Board::Create(scaled));
  EXPECT_NE(half.find("width=\"550mm\" height=\"550mm\" viewBox=\"0 0 550 550\""),
            std::string::npos);
  const std::string path = (dir_ / "a.svg").string();
  ASSERT_TRUE(WriteBoardSvg(board, path).ok());
  EXPECT_EQ(std::filesystem::file_size(path), svg.size());
  EXPECT_FALSE(WriteBoardSvg(board, (dir_ / "no/such/dir.svg").string()).ok());
}

}  // namespace
}  // namespace linecal

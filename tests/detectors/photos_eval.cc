// linecal's image detectors on real photographs (issue 19, part 6; docs/detectors.md): per set
// of the camera_real corpus (tests/detectors/photo_corpus.h), linecal's found / total and the
// reasons of its misses; a camera calibrated per set (per camera of a stereo set) from
// linecal's corners and, beside it, from OpenCV's findChessboardCornersSB corners of the same
// photos (findCirclesGrid for the circle sets, for reference); the reprojection RMS of each on
// all the photos each found and on the photos both found, the fair comparison. Then the
// false-positive sweep: every linecal board on every photo that does not show it, and every
// found board checked against OpenCV's corners (same points within 2 px, in an order that is
// a symmetry of the grid).
//   photos_eval [--photos DIR] [--set NAME] [--json] [--check] [--misses DIR] [--bootstrap N]
// --check exits 1 when a bar is missed: found >= 98% (mild) / 95% (wide, fisheye) of the
// whole-view photos of each set with a linecal board, no false detection, RMS(linecal) <=
// RMS(OpenCV) (mild) / 1.1x (wide, fisheye) on the common photos. A markdown table on stdout
// (JSON with --json), progress on stderr. Without the corpus: the skip message, exit 0.
// --bootstrap N adds, per set, the spread of RMS linecal / RMS OpenCV over N resamples of
// the photos both found (PrintBootstrap), to tell a detector's difference from the photos'.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "detectors/detect.h"
#include "station/io/image_io.h"
#include "tests/detectors/photo_corpus.h"
#include "tests/support/external_data.h"

namespace linecal {
namespace {

using photo_corpus::Lens;
using photo_corpus::PhotoSet;
using photo_corpus::ReferencePoints;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// A camera with distortion has 9 intrinsics; fewer than three views of a plane leave them
// unconstrained, and the RMS of such a fit means nothing.
constexpr int kMinViewsPerCamera = 3;

struct Options {
  std::string photos;  // corpus root; empty: ExternalPath("camera_real")
  std::string set;     // empty: every set
  bool json = false;
  bool check = false;
  std::string misses_dir;
  int bootstrap = 0;  // --bootstrap N: resamples of each set's common photos (0: none)
};

// One photo's outcome.
struct PhotoResult {
  std::string path;
  std::string camera;
  bool partial = false;
  cv::Size size;
  std::optional<Detection> linecal;  // nullopt: the set has no linecal board
  ReferencePoints reference;
};

// Correspondences of one view, for the calibration.
struct View {
  std::string photo;  // path
  std::string camera;
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
};

struct Calibration {
  int views = 0;  // views that entered a calibration (cameras with kMinViewsPerCamera or more)
  double rms_px = kNaN;
  std::map<std::string, double> view_rms_px;  // per photo
  // Photos OpenCV's fisheye calibration could not start from (CALIB_CHECK_COND), left out.
  std::set<std::string> dropped;
};

struct Disagreement {
  std::string photo;
  photo_corpus::ReferenceCheck check;
};

struct SetResult {
  const PhotoSet* set = nullptr;
  std::vector<PhotoResult> photos;
  Calibration linecal, opencv, linecal_common, opencv_common;
  std::vector<photo_corpus::FalseDetection> false_detections;  // sweep and wrong corners
  int verified = 0;                         // linecal's board found and matched to OpenCV's corners
  std::vector<std::string> unverified;      // linecal's board found where OpenCV found none
  std::vector<Disagreement> disagreements;  // the same grid, corners over 2 px apart
};

// Calibrates one camera with the lens's model; the pose of each view in rvecs, tvecs.
// Throws what OpenCV throws on a degenerate set.
void RunCalibration(const std::vector<std::vector<cv::Point3d>>& object,
                    const std::vector<std::vector<cv::Point2d>>& image, cv::Size size, Lens lens,
                    cv::Mat* k, cv::Mat* d, std::vector<cv::Mat>* rvecs,
                    std::vector<cv::Mat>* tvecs) {
  const cv::TermCriteria stop(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, 1e-10);
  if (lens == Lens::kFisheye) {
    // CALIB_CHECK_COND: a view far off the axis can start the fisheye solver in a wrong
    // pose (100 px residuals on photos 4 and 5 of BoofCV's set); the check names it instead.
    cv::fisheye::calibrate(object, image, size, *k, *d, *rvecs, *tvecs,
                           cv::fisheye::CALIB_RECOMPUTE_EXTRINSIC | cv::fisheye::CALIB_FIX_SKEW |
                               cv::fisheye::CALIB_CHECK_COND,
                           stop);
    return;
  }
  // calibrateCamera reads float points; its default model is k1 k2 p1 p2 k3.
  std::vector<std::vector<cv::Point3f>> object_f(object.size());
  std::vector<std::vector<cv::Point2f>> image_f(image.size());
  for (std::size_t i = 0; i < object.size(); ++i) {
    for (const cv::Point3d& p : object[i]) object_f[i].emplace_back(p);
    for (const cv::Point2d& p : image[i]) image_f[i].emplace_back(p);
  }
  cv::calibrateCamera(object_f, image_f, size, *k, *d, *rvecs, *tvecs, 0, stop);
}

// The view that CALIB_CHECK_COND names in its message ("... for input array 8 ..."), or -1.
int IllConditionedView(const cv::Exception& e) {
  const std::string::size_type at = e.err.find("input array ");
  return at == std::string::npos ? -1 : std::atoi(e.err.c_str() + at + 12);
}

// Calibrates one camera's views, leaving out (into c->dropped) the views the fisheye solver
// cannot start from and those in `exclude`; adds the squared residuals of each view to
// c->view_rms_px (as sums, made RMS by the caller) and to *sum_sq, *points.
void CalibrateCamera(std::vector<const View*> views, cv::Size size, Lens lens,
                     const std::set<std::string>& exclude, Calibration* c, double* sum_sq,
                     int* points) {
  std::erase_if(views, [&](const View* v) { return exclude.contains(v->photo); });
  while (static_cast<int>(views.size()) >= kMinViewsPerCamera) {
    std::vector<std::vector<cv::Point3d>> object;
    std::vector<std::vector<cv::Point2d>> image;
    for (const View* v : views) {
      object.push_back(v->object);
      image.push_back(v->image);
    }
    cv::Mat k, d;
    std::vector<cv::Mat> rvecs, tvecs;
    try {
      RunCalibration(object, image, size, lens, &k, &d, &rvecs, &tvecs);
    } catch (const cv::Exception& e) {
      const int bad = IllConditionedView(e);
      if (bad < 0 || bad >= static_cast<int>(views.size())) throw;
      c->dropped.insert(views[bad]->photo);
      views.erase(views.begin() + bad);
      continue;
    }
    for (std::size_t i = 0; i < object.size(); ++i) {
      std::vector<cv::Point2d> projected;
      if (lens == Lens::kFisheye) {
        cv::fisheye::projectPoints(object[i], projected, rvecs[i], tvecs[i], k, d);
      } else {
        cv::projectPoints(object[i], rvecs[i], tvecs[i], k, d, projected);
      }
      double view_sq = 0.0;
      for (std::size_t j = 0; j < projected.size(); ++j) {
        const cv::Point2d e = projected[j] - image[i][j];
        view_sq += e.dot(e);
      }
      c->view_rms_px[views[i]->photo] = std::sqrt(view_sq / projected.size());
      *sum_sq += view_sq;
      *points += static_cast<int>(projected.size());
    }
    c->views += static_cast<int>(views.size());
    return;
  }
}

// Calibrates each camera of `views` (but the photos in `exclude`) that keeps
// kMinViewsPerCamera views; the RMS pooled over the cameras, sqrt(sum of squares / points).
// A camera whose calibration OpenCV refuses is left out (reported on stderr).
Calibration Calibrate(const std::vector<View>& views, cv::Size size, Lens lens,
                      const std::set<std::string>& exclude = {}) {
  std::map<std::string, std::vector<const View*>> by_camera;
  for (const View& v : views) by_camera[v.camera].push_back(&v);
  Calibration c;
  double sum_sq = 0.0;
  int points = 0;
  for (const auto& [camera, camera_views] : by_camera) {
    try {
      CalibrateCamera(camera_views, size, lens, exclude, &c, &sum_sq, &points);
    } catch (const cv::Exception& e) {
      std::fprintf(stderr, "calibration of camera '%s' failed: %s\n", camera.c_str(), e.what());
    }
  }
  if (points > 0) c.rms_px = std::sqrt(sum_sq / points);
  return c;
}

// Both detectors' calibrations on the same photos: a photo one of them has to leave out is
// left out of the other too, until both keep the same set.
void CalibrateCommon(const std::vector<View>& linecal, const std::vector<View>& opencv,
                     cv::Size size, Lens lens, Calibration* l, Calibration* o) {
  std::set<std::string> exclude;
  for (int round = 0; round < 10; ++round) {
    *l = Calibrate(linecal, size, lens, exclude);
    *o = Calibrate(opencv, size, lens, exclude);
    const std::size_t before = exclude.size();
    exclude.insert(l->dropped.begin(), l->dropped.end());
    exclude.insert(o->dropped.begin(), o->dropped.end());
    if (exclude.size() == before) break;
  }
  l->dropped = o->dropped = exclude;
}

View LinecalView(const PhotoResult& p) {
  View v{p.path, p.camera, {}, {}};
  for (const DetectedFeature& f : p.linecal->features) {
    v.object.emplace_back(f.p_board.x(), f.p_board.y(), 0.0);
    v.image.emplace_back(f.uv_px.x(), f.uv_px.y());
  }
  return v;
}

// OpenCV's points on OpenCV's own board frame: a symmetric grid of pitch 1, or its
// asymmetric layout (every other row shifted by half a pitch along the row).
View OpenCvView(const PhotoResult& p, photo_corpus::Reference kind) {
  View v{p.path, p.camera, {}, {}};
  const ReferencePoints& r = p.reference;
  for (int k = 0; k < r.cols * r.rows; ++k) {
    const int i = k % r.cols, j = k / r.cols;
    const double x = kind == photo_corpus::Reference::kAsymmetricCircles ? 2 * i + j % 2 : i;
    v.object.emplace_back(x, j, 0.0);
    v.image.emplace_back(r.uv_px[k].x(), r.uv_px[k].y());
  }
  return v;
}

bool LinecalFound(const PhotoResult& p) { return p.linecal && p.linecal->found; }

// The views of the photos both detectors found, in the same order.
void CommonViews(const SetResult& s, std::vector<View>* linecal, std::vector<View>* opencv) {
  for (const PhotoResult& p : s.photos) {
    if (LinecalFound(p) && p.reference.found) {
      linecal->push_back(LinecalView(p));
      opencv->push_back(OpenCvView(p, s.set->reference));
    }
  }
}

// The four calibrations of a set: each detector on the photos it found, and on the photos
// both found.
void CalibrateSet(SetResult* s) {
  std::vector<View> linecal, opencv, linecal_common, opencv_common;
  cv::Size size;
  for (const PhotoResult& p : s->photos) {
    size = p.size;
    if (LinecalFound(p)) linecal.push_back(LinecalView(p));
    if (p.reference.found) opencv.push_back(OpenCvView(p, s->set->reference));
    if (LinecalFound(p) && p.reference.found) {
      linecal_common.push_back(linecal.back());
      opencv_common.push_back(opencv.back());
    }
  }
  s->linecal = Calibrate(linecal, size, s->set->lens);
  s->opencv = Calibrate(opencv, size, s->set->lens);
  CalibrateCommon(linecal_common, opencv_common, size, s->set->lens, &s->linecal_common,
                  &s->opencv_common);
}

// Copies a missed photo, as grey PNG, into the misses folder, and lists it in misses.txt.
void WriteMiss(const Options& options, const PhotoSet& set, const PhotoResult& p,
               const Image8& image) {
  std::string stem = set.name + "__" + std::filesystem::path(p.path).stem().string();
  std::replace(stem.begin(), stem.end(), '/', '_');
  const std::string png = options.misses_dir + "/" + stem + ".png";
  const absl::Status written = WritePng8(png, image.view());
  if (!written.ok()) std::fprintf(stderr, "%s\n", written.ToString().c_str());
  std::ofstream list(options.misses_dir + "/misses.txt", std::ios::app);
  list << p.path << " " << DetectReasonName(p.linecal->reason) << (p.partial ? " partial_view" : "")
       << "\n";
}

// Detects linecal's board and OpenCV's reference on one photo, sweeps the other boards and
// checks a found board against OpenCV's corners.
void EvaluatePhoto(const Options& options, const Image8& image, PhotoResult* p, SetResult* s) {
  const PhotoSet& set = *s->set;
  p->size = cv::Size(image.width, image.height);
  p->reference = photo_corpus::DetectReference(image.view(), set);
  for (auto& f : photo_corpus::SweepPhoto(image.view(), set, p->path)) {
    s->false_detections.push_back(std::move(f));
  }
  if (!set.board) return;
  const Board board = *Board::Create(*set.board);
  p->linecal = *DetectBoard(image.view(), board);
  if (!p->linecal->found) {
    if (!options.misses_dir.empty()) WriteMiss(options, set, *p, image);
    return;
  }
  // Where OpenCV's accurate mode finds nothing its fast mode sometimes does (the ECoCheck
  // photos): enough to check the grid, not used for the calibration.
  const ReferencePoints fast = p->reference.found
                                   ? ReferencePoints{}
                                   : photo_corpus::DetectReference(image.view(), set, false);
  const photo_corpus::ReferenceCheck check = photo_corpus::CheckAgainstReference(
      *p->linecal, board, p->reference.found ? p->reference : fast);
  if (!check.wrong.empty()) {
    s->false_detections.push_back({p->path, "own board, wrong corners", check.wrong});
  } else if (!check.compared) {
    s->unverified.push_back(p->path);
  } else {
    ++s->verified;
    if (check.beyond_tol > 0) s->disagreements.push_back({p->path, check});
  }
}

SetResult EvaluateSet(const Options& options, const std::string& corpus, const PhotoSet& set) {
  SetResult s;
  s.set = &set;
  const std::vector<std::string> paths = photo_corpus::ListPhotos(corpus, set);
  if (paths.empty()) std::fprintf(stderr, "%s: no photos in the corpus\n", set.name.c_str());
  for (std::size_t i = 0; i < paths.size(); ++i) {
    PhotoResult p;
    p.path = paths[i];
    p.camera = photo_corpus::CameraOf(set, p.path);
    p.partial = photo_corpus::IsPartialView(set, p.path);
    const absl::StatusOr<Image8> image = ReadImage8(p.path);
    if (!image.ok()) {
      std::fprintf(stderr, "%s\n", image.status().ToString().c_str());
      continue;
    }
    EvaluatePhoto(options, *image, &p, &s);
    const char* linecal = "-";
    if (p.linecal) linecal = p.linecal->found ? "found" : DetectReasonName(p.linecal->reason);
    const char* opencv = "-";
    if (set.reference != photo_corpus::Reference::kNone) {
      opencv = p.reference.found ? "found" : "not found";
    }
    std::fprintf(stderr, "[%s %zu/%zu] %s: linecal %s, OpenCV %s\n", set.name.c_str(), i + 1,
                 paths.size(), photo_corpus::FileName(p.path).c_str(), linecal, opencv);
    s.photos.push_back(std::move(p));
  }
  CalibrateSet(&s);
  return s;
}

// Counts of a set, for the table and the bars.
struct Counts {
  int photos = 0, whole = 0, found = 0, found_whole = 0, opencv = 0;
  std::map<std::string, int> reasons;  // linecal's misses by reason
};

Counts CountSet(const SetResult& s) {
  Counts c;
  for (const PhotoResult& p : s.photos) {
    ++c.photos;
    c.whole += p.partial ? 0 : 1;
    c.opencv += p.reference.found ? 1 : 0;
    if (!p.linecal) continue;
    if (p.linecal->found) {
      ++c.found;
      c.found_whole += p.partial ? 0 : 1;
    } else {
      ++c.reasons[DetectReasonName(p.linecal->reason)];
    }
  }
  return c;
}

// The set's bars (issue 19): empty when met or not applicable, else what is missed.
std::string MissedBars(const SetResult& s, const Counts& c) {
  std::string missed;
  if (!s.set->board) return missed;
  const double rate_bar = s.set->lens == Lens::kMild ? 0.98 : 0.95;
  if (c.whole > 0 && c.found_whole < rate_bar * c.whole) missed += "found ";
  const double rms_factor = s.set->lens == Lens::kMild ? 1.0 : 1.1;
  const double l = s.linecal_common.rms_px, o = s.opencv_common.rms_px;
  if (std::isfinite(l) && std::isfinite(o) && l > rms_factor * o) missed += "rms ";
  if (!s.false_detections.empty()) missed += "false ";
  if (!missed.empty()) missed.pop_back();
  return missed;
}

std::string Rms(const Calibration& c) {
  if (!std::isfinite(c.rms_px)) return "—";
  char text[48];
  std::snprintf(text, sizeof text, "%.4f (%d)", c.rms_px, c.views);
  return text;
}

std::string ReasonsText(const std::map<std::string, int>& reasons) {
  std::string text;
  for (const auto& [name, n] : reasons) {
    if (!text.empty()) text += ", ";
    text += name + " ×" + std::to_string(n);
  }
  return text.empty() ? "—" : text;
}

// linecal's board of a set, "checker 6x4", or "none".
std::string BoardName(const PhotoSet& set) {
  return set.board ? photo_corpus::BoardLabel(*set.board) : "none";
}

// The table's board cell: linecal's board, or what the set shows where linecal has none.
std::string BoardText(const PhotoSet& set) {
  return set.board ? BoardName(set) : "none: " + set.description;
}

void PrintMarkdown(const std::string& corpus, const std::vector<SetResult>& results) {
  std::printf(
      "Real photos (%s): linecal against OpenCV 4.6 on the same photos. RMS: "
      "reprojection RMS px of a camera calibrated per set (per camera of a stereo set; "
      "fisheye: OpenCV's fisheye model, else k1 k2 p1 p2 k3), views in brackets.\n\n",
      corpus.c_str());
  std::printf(
      "| set | lens | linecal board | photos (whole view) | linecal found (whole) | "
      "misses | OpenCV found | RMS linecal | RMS OpenCV | RMS linecal, common | "
      "RMS OpenCV, common | bars |\n");
  std::printf("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (const SetResult& s : results) {
    const Counts c = CountSet(s);
    const bool has = s.set->board.has_value();
    const std::string missed = MissedBars(s, c);
    const std::string found = std::to_string(c.found) + " (" + std::to_string(c.found_whole) + "/" +
                              std::to_string(c.whole) + ")";
    const std::string opencv = std::to_string(c.opencv) + "/" + std::to_string(c.photos);
    const std::string bars = missed.empty() ? "met" : "missed: " + missed;
    std::printf("| %s | %s | %s | %d (%d) | %s | %s | %s | %s | %s | %s | %s | %s |\n",
                s.set->name.c_str(), photo_corpus::LensName(s.set->lens), BoardText(*s.set).c_str(),
                c.photos, c.whole, has ? found.c_str() : "—",
                has ? ReasonsText(c.reasons).c_str() : "—",
                s.set->reference != photo_corpus::Reference::kNone ? opencv.c_str() : "—",
                Rms(s.linecal).c_str(), Rms(s.opencv).c_str(), Rms(s.linecal_common).c_str(),
                Rms(s.opencv_common).c_str(), has ? bars.c_str() : "—");
  }
}

// Per-view RMS of a photo in a calibration, or NaN.
double ViewRms(const Calibration& c, const std::string& photo) {
  const auto it = c.view_rms_px.find(photo);
  return it == c.view_rms_px.end() ? kNaN : it->second;
}

// The file names of a set of paths, space-separated.
std::string FileNames(const std::set<std::string>& paths) {
  std::string text;
  for (const std::string& p : paths) {
    if (!text.empty()) text += ' ';
    text += photo_corpus::FileName(p);
  }
  return text.empty() ? "none" : text;
}

void PrintChecks(const std::vector<SetResult>& results) {
  int photos = 0, verified = 0, unverified = 0;
  std::vector<photo_corpus::FalseDetection> all;
  for (const SetResult& s : results) {
    photos += static_cast<int>(s.photos.size());
    verified += s.verified;
    unverified += static_cast<int>(s.unverified.size());
    all.insert(all.end(), s.false_detections.begin(), s.false_detections.end());
  }
  std::printf("\nFalse-positive sweep: %zu linecal boards (", photo_corpus::SweepBoards().size());
  for (std::size_t i = 0; i < photo_corpus::SweepBoards().size(); ++i) {
    std::printf("%s%s", i ? ", " : "", photo_corpus::SweepBoards()[i].label.c_str());
  }
  std::printf(
      ") on each of the %d photos not showing them, and every found board against "
      "OpenCV's corners: %zu false detections.\n",
      photos, all.size());
  for (const auto& f : all) {
    std::printf("- false: %s on %s (%s)\n", f.board.c_str(), f.photo.c_str(), f.why.c_str());
  }
  std::printf(
      "\nFound boards against OpenCV's corners: %d the same grid, %d without an OpenCV "
      "detection (their view RMS in linecal's calibration shows a consistent grid; it cannot "
      "show a grid shifted by whole squares).\n",
      verified, unverified);
  for (const SetResult& s : results) {
    for (const Disagreement& d : s.disagreements) {
      std::printf(
          "- the same grid, %d corner(s) over 2 px from OpenCV's, at most %.2f px "
          "(corner %d); view RMS linecal %.3f / OpenCV %.3f px: %s\n",
          d.check.beyond_tol, d.check.max_px, d.check.worst_id, ViewRms(s.linecal_common, d.photo),
          ViewRms(s.opencv_common, d.photo), d.photo.c_str());
    }
    for (const std::string& photo : s.unverified) {
      std::printf("- no OpenCV detection, view RMS %.3f px: %s\n", ViewRms(s.linecal, photo),
                  photo.c_str());
    }
  }
  for (const SetResult& s : results) {
    if (s.linecal.dropped.empty() && s.opencv.dropped.empty()) continue;
    std::printf(
        "- %s: left out, OpenCV's fisheye solver cannot start from them: linecal %s; "
        "OpenCV %s; common %s\n",
        s.set->name.c_str(), FileNames(s.linecal.dropped).c_str(),
        FileNames(s.opencv.dropped).c_str(), FileNames(s.linecal_common.dropped).c_str());
  }
}

// A JSON string literal (the texts here hold no control characters).
std::string Quoted(const std::string& s) {
  std::string q = "\"";
  for (char ch : s) {
    if (ch == '"' || ch == '\\') q += '\\';
    q += ch;
  }
  return q + "\"";
}

std::string JsonNumber(double v) {
  if (!std::isfinite(v)) return "null";
  char text[32];
  std::snprintf(text, sizeof text, "%.4f", v);
  return text;
}

void PrintJsonSet(const SetResult& s, bool last) {
  const Counts c = CountSet(s);
  std::printf(
      "  {\"set\": %s, \"lens\": %s, \"board\": %s, \"description\": %s, \"photos\": %d, "
      "\"whole_view\": %d, "
      "\"linecal_found\": %d, \"linecal_found_whole\": %d, \"opencv_found\": %d, "
      "\"misses\": {",
      Quoted(s.set->name).c_str(), Quoted(photo_corpus::LensName(s.set->lens)).c_str(),
      Quoted(BoardName(*s.set)).c_str(), Quoted(s.set->description).c_str(), c.photos, c.whole,
      c.found, c.found_whole, c.opencv);
  bool first = true;
  for (const auto& [name, n] : c.reasons) {
    std::printf("%s%s: %d", first ? "" : ", ", Quoted(name).c_str(), n);
    first = false;
  }
  std::printf(
      "}, \"rms_linecal\": %s, \"rms_opencv\": %s, \"rms_linecal_common\": %s, "
      "\"rms_opencv_common\": %s, \"common_views\": %d, \"false_detections\": [",
      JsonNumber(s.linecal.rms_px).c_str(), JsonNumber(s.opencv.rms_px).c_str(),
      JsonNumber(s.linecal_common.rms_px).c_str(), JsonNumber(s.opencv_common.rms_px).c_str(),
      s.linecal_common.views);
  for (std::size_t i = 0; i < s.false_detections.size(); ++i) {
    const auto& f = s.false_detections[i];
    std::printf("%s{\"photo\": %s, \"board\": %s, \"why\": %s}", i ? ", " : "",
                Quoted(f.photo).c_str(), Quoted(f.board).c_str(), Quoted(f.why).c_str());
  }
  std::printf(
      "], \"verified_against_opencv\": %d, \"unverified\": %zu, "
      "\"over_2px_from_opencv\": %zu, \"bars_missed\": %s}%s\n",
      s.verified, s.unverified.size(), s.disagreements.size(), Quoted(MissedBars(s, c)).c_str(),
      last ? "" : ",");
}

void PrintJson(const std::string& corpus, const std::vector<SetResult>& results) {
  std::printf("{\"corpus\": %s, \"sets\": [\n", Quoted(corpus).c_str());
  for (std::size_t i = 0; i < results.size(); ++i) {
    PrintJsonSet(results[i], i + 1 == results.size());
  }
  std::printf("]}\n");
}

// The paired bootstrap of a set's comparison: `n` resamples (with replacement, seeded) of
// the photos both detectors found, each calibrated from either detector's points of the same
// photos; the ratio RMS linecal / RMS OpenCV of each. It tells how much the comparison owes
// to the particular photos: a bar met or missed by less than the spread of the ratio is
// not a difference between the detectors that another sample of photos would keep.
void PrintBootstrap(const SetResult& s, int n) {
  std::vector<View> linecal, opencv;
  CommonViews(s, &linecal, &opencv);
  std::erase_if(linecal, [&](const View& v) { return s.linecal_common.dropped.contains(v.photo); });
  std::erase_if(opencv, [&](const View& v) { return s.linecal_common.dropped.contains(v.photo); });
  if (linecal.size() < static_cast<std::size_t>(kMinViewsPerCamera) ||
      !std::isfinite(s.linecal_common.rms_px) || !std::isfinite(s.opencv_common.rms_px)) {
    return;
  }
  const cv::Size size = s.photos.front().size;
  std::mt19937_64 random(1);
  std::uniform_int_distribution<std::size_t> pick(0, linecal.size() - 1);
  std::vector<double> ratios;
  for (int r = 0; r < n; ++r) {
    std::vector<View> l, o;
    for (std::size_t k = 0; k < linecal.size(); ++k) {
      const std::size_t i = pick(random);
      l.push_back(linecal[i]);
      o.push_back(opencv[i]);
    }
    const double rl = Calibrate(l, size, s.set->lens).rms_px;
    const double ro = Calibrate(o, size, s.set->lens).rms_px;
    if (std::isfinite(rl) && std::isfinite(ro)) ratios.push_back(rl / ro);
  }
  if (ratios.empty()) return;
  std::sort(ratios.begin(), ratios.end());
  auto quantile = [&](double q) {
    return ratios[static_cast<std::size_t>(q * (ratios.size() - 1) + 0.5)];
  };
  const auto not_above =
      std::count_if(ratios.begin(), ratios.end(), [](double v) { return v <= 1.0; });
  std::printf(
      "- %s: RMS linecal / OpenCV %.4f on the %zu common photos; over %zu resamples median "
      "%.4f, 95%% of them %.4f-%.4f, linecal <= OpenCV in %.0f%%\n",
      s.set->name.c_str(), s.linecal_common.rms_px / s.opencv_common.rms_px, linecal.size(),
      ratios.size(), quantile(0.5), quantile(0.025), quantile(0.975),
      100.0 * not_above / ratios.size());
}

int Run(const Options& options) {
  const std::string corpus =
      options.photos.empty() ? testing_support::ExternalPath("camera_real") : options.photos;
  if (const std::string missing = testing_support::MissingExternalMessage(corpus);
      !missing.empty()) {
    std::printf("skipped: %s\n", missing.c_str());
    return 0;
  }
  if (!options.misses_dir.empty()) {
    // A fresh list per run; WriteMiss appends to it.
    std::filesystem::create_directories(options.misses_dir);
    std::ofstream(options.misses_dir + "/misses.txt", std::ios::trunc);
  }
  std::vector<SetResult> results;
  for (const PhotoSet& set : photo_corpus::Sets()) {
    if (!options.set.empty() && set.name != options.set) continue;
    results.push_back(EvaluateSet(options, corpus, set));
  }
  if (options.json) {
    PrintJson(corpus, results);
  } else {
    PrintMarkdown(corpus, results);
    PrintChecks(results);
    if (options.bootstrap > 0) {
      std::printf("\nBootstrap over the photos both found (%d resamples each):\n",
                  options.bootstrap);
      for (const SetResult& s : results) PrintBootstrap(s, options.bootstrap);
    }
  }
  bool met = true;
  for (const SetResult& s : results) met = met && MissedBars(s, CountSet(s)).empty();
  for (const SetResult& s : results) met = met && s.false_detections.empty();
  return options.check && !met ? 1 : 0;
}

bool ParseArgs(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--photos" && has_value) {
      o->photos = argv[++i];
    } else if (a == "--set" && has_value) {
      o->set = argv[++i];
      if (photo_corpus::FindSet(o->set) == nullptr) {
        std::fprintf(stderr, "photos_eval: --set: unknown set '%s'; the sets:\n", o->set.c_str());
        for (const PhotoSet& s : photo_corpus::Sets()) {
          std::fprintf(stderr, "  %s\n", s.name.c_str());
        }
        return false;
      }
    } else if (a == "--json") {
      o->json = true;
    } else if (a == "--check") {
      o->check = true;
    } else if (a == "--misses" && has_value) {
      o->misses_dir = argv[++i];
    } else if (a == "--bootstrap" && has_value && std::atoi(argv[i + 1]) > 0) {
      o->bootstrap = std::atoi(argv[++i]);
    } else {
      std::fprintf(stderr,
                   "photos_eval: unknown or incomplete argument '%s'\n"
                   "usage: photos_eval [--photos DIR] [--set NAME] [--json] [--check] "
                   "[--misses DIR] [--bootstrap N]\n",
                   a.c_str());
      return false;
    }
  }
  return true;
}

}  // namespace
}  // namespace linecal

int main(int argc, char** argv) {
  linecal::Options options;
  if (!linecal::ParseArgs(argc, argv, &options)) return 2;
  return linecal::Run(options);
}

// The cycle page's data and the operator's actions (docs/console.md, "Cycle views",
// "Operator actions") on 127.0.0.1 over the real core, store and simulator with the full
// reference car: a recorded cycle's capture files and their bytes, each sensor's view against
// what the cycle computed (the camera features of CalibrateCapture, the store's feature
// counts, a reprojected board feature computed here from the stored mounting, the LiDAR holes
// of CalibrateLidarFrames, the radar's reflectors), the whole capture as one tar archive,
// refusals of bad ids; operator POSTs refused for read-only sessions and cross-site requests,
// taken for an operator.
#include "station/pipeline/cycle_views.h"

#include <archive.h>
#include <archive_entry.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>

#include "daemon/web/operator_actions.h"
#include "daemon/web/web_server.h"
#include "station/camera/camera_model.h"
#include "station/pipeline/capture_calibration.h"
#include "tests/daemon/scratch_dir.h"
#include "tests/daemon/web/reference_core.h"

// After Eigen: httplib.h brings <resolv.h>, whose _res macro breaks Eigen's parameter names.
#include <httplib.h>

namespace linecal {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string FileBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

// A tar archive's members in order, name -> bytes, read with libarchive; `ok` false when the
// archive does not read to its end.
std::vector<std::pair<std::string, std::string>> TarMembers(const std::string& tar, bool* ok) {
  std::vector<std::pair<std::string, std::string>> members;
  archive* a = archive_read_new();
  archive_read_support_format_tar(a);
  *ok = archive_read_open_memory(a, tar.data(), tar.size()) == ARCHIVE_OK;
  archive_entry* entry = nullptr;
  int r = ARCHIVE_OK;
  while (*ok && (r = archive_read_next_header(a, &entry)) == ARCHIVE_OK) {
    std::string bytes(static_cast<size_t>(archive_entry_size(entry)), '\0');
    *ok = archive_entry_filetype(entry) == AE_IFREG &&
          archive_read_data(a, bytes.data(), bytes.size()) == static_cast<la_ssize_t>(bytes.size());
    members.emplace_back(archive_entry_pathname(entry), std::move(bytes));
  }
  *ok = *ok && r == ARCHIVE_EOF;
  archive_read_free(a);
  return members;
}

using testing_web::kStatic;
constexpr char kVin[] = "1M8GDM9AXKP042788";
constexpr char kToken[] = "line-3-viewers";
constexpr char kOperatorToken[] = "line-3-operators";

class CycleViewsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_daemon::FreshTestDir("web_views");
    absl::StatusOr<std::unique_ptr<StationCore>> core = testing_web::ReferenceCore(dir_);
    ASSERT_TRUE(core.ok()) << core.status();
    core_ = *std::move(core);
    WebServerOptions options{"127.0.0.1:0", std::nullopt, kStatic, kToken, "test"};
    options.operator_token = kOperatorToken;
    absl::StatusOr<std::unique_ptr<WebServer>> web = WebServer::Start(core_.get(), options);
    ASSERT_TRUE(web.ok()) << web.status();
    web_ = *std::move(web);
    reader_ = Login(kToken);
    operator_ = Login(kOperatorToken);
  }
  void TearDown() override {
    if (core_) core_->WaitIdle();
    web_.reset();
    core_.reset();
    fs::remove_all(dir_);
  }
  httplib::Client Client() const { return httplib::Client("127.0.0.1", web_->port()); }
  std::string Login(const std::string& token) const {
    httplib::Result r =
        Client().Post("/api/login", json{{"token", token}}.dump(), "application/json");
    EXPECT_TRUE(r && r->status == 200);
    if (!r) return "";
    const std::string cookie = r->get_header_value("Set-Cookie");
    return cookie.substr(0, cookie.find(';'));
  }
  std::pair<int, json> GetJson(const std::string& path) const {
    httplib::Result r = Client().Get(path.c_str(), {{"Cookie", reader_}});
    EXPECT_TRUE(r) << path;
    if (!r) return {0, json()};
    return {r->status, json::parse(r->body)};
  }
  // POST `body` to `path` with `cookie`, the action header unless `action` is false, and
  // `origin` when not empty.
  std::pair<int, json> Post(const std::string& path, const json& body, const std::string& cookie,
                            bool action = true, const std::string& origin = "") const {
    httplib::Headers headers{{"Cookie", cookie}};
    if (action) headers.emplace(kActionHeader, kActionHeaderValue);
    if (!origin.empty()) headers.emplace("Origin", origin);
    httplib::Result r = Client().Post(path.c_str(), headers, body.dump(), "application/json");
    EXPECT_TRUE(r) << path;
    if (!r) return {0, json()};
    return {r->status, json::parse(r->body)};
  }
  int64_t RecordedCycle() {
    CycleRequest request;
    request.vin = kVin;
    request.car_model_id = "reference";
    request.aligner.lateral_offset_m = 0.01;
    request.record_capture = true;
    absl::StatusOr<int64_t> id = core_->StartCycle(request);
    EXPECT_TRUE(id.ok()) << id.status();
    core_->WaitIdle();
    return id.ok() ? *id : 0;
  }

  // A camera's view in cycle `id` equals what the cycle computed: every detected feature in
  // order, the frame under the overlay byte for byte, and a reprojected feature computed here
  // from the stored 4x4 mounting.
  void ExpectCameraView(const json& view, const SensorCalibration& s,
                        const StoredSensorResult& result, const Capture& capture,
                        const std::vector<CaptureFileEntry>& list, int64_t id) {
    const std::string base = "/api/cycles/" + std::to_string(id);
    EXPECT_EQ(view["mounting"], "solved");
    // Every feature the cycle detected in the frame, in order, as equal doubles.
    std::vector<json> expected;
    for (const BoardObservation& o : s.first_frame_observations) {
      for (const DetectedFeature& f : o.features)
        expected.push_back({o.board_id, f.id, f.uv_px.x(), f.uv_px.y()});
    }
    std::vector<json> shown;
    for (const json& b : view["boards"]) {
      for (const json& f : b["detected"]) shown.push_back({b["id"], f[0], f[1], f[2]});
    }
    EXPECT_EQ(shown, expected);
    EXPECT_EQ(view["detected_features"], result.features_used);
    // The frame under the overlay is the capture's file, byte for byte.
    const size_t image = view["image"].get<size_t>();
    EXPECT_EQ(list[image].path, view["file"]);
    httplib::Result png =
        Client().Get((base + "/capture/" + std::to_string(image)).c_str(), {{"Cookie", reader_}});
    ASSERT_TRUE(png);
    EXPECT_EQ(png->status, 200);
    EXPECT_EQ(png->get_header_value("Content-Type"), "image/png");
    std::string name = list[image].path;
    std::replace(name.begin(), name.end(), '/', '_');
    EXPECT_EQ(png->get_header_value("Content-Disposition"),
              "attachment; filename=\"cycle-" + std::to_string(id) + "-" + name + "\"");
    std::ifstream in(fs::path(capture.dir) / list[image].path, std::ios::binary);
    std::ostringstream bytes;
    bytes << in.rdbuf();
    EXPECT_EQ(png->body, bytes.str());
    // One reprojected feature, computed here from the stored 4x4 mounting.
    ASSERT_FALSE(view["boards"].empty());
    const json& board_view = view["boards"][0];
    ASSERT_FALSE(board_view["reprojected"].empty());
    const json& first = board_view["reprojected"][0];
    const StationBoard* board = capture.station.FindBoard(board_view["id"]);
    ASSERT_NE(board, nullptr);
    Eigen::Matrix4d T_car_camera;
    for (int i = 0; i < 16; ++i)
      T_car_camera(i / 4, i % 4) = result.T_car_sensor[static_cast<size_t>(i)];
    const Eigen::Matrix4d T_camera_board =
        T_car_camera.inverse() * capture.manifest.aligner.T_station_car().Matrix().inverse() *
        board->T_station_board.Matrix();
    const Eigen::Vector2d p_board = board->board.features()[first[0].get<size_t>()].p_board;
    const Eigen::Vector4d p = T_camera_board * Eigen::Vector4d(p_board.x(), p_board.y(), 0, 1);
    absl::StatusOr<CameraModel> camera =
        CameraModel::Create(*capture.car.FindSensor(s.name)->intrinsics);
    ASSERT_TRUE(camera.ok());
    Eigen::Vector2d uv;
    ASSERT_TRUE(camera->Project(p.head<3>(), &uv));
    EXPECT_NEAR(first[1].get<double>(), uv.x(), 1e-6);
    EXPECT_NEAR(first[2].get<double>(), uv.y(), 1e-6);
  }

  // A LiDAR's view equals the cycle's detections (found boards and their holes, exactly) and
  // holds at most kMaxViewPoints points.
  static void ExpectLidarView(const json& view, const SensorCalibration& s,
                              const StoredSensorResult& result, const Capture& capture) {
    const SensorModel& model = *capture.car.FindSensor(s.name);
    std::vector<std::vector<RoundHoleCloudPoint>> frames;
    for (const CaptureFile& f : capture.manifest.FindSensor(s.name)->frames) {
      absl::StatusOr<PcdCloud> cloud = ReadCaptureScan(capture, f);
      ASSERT_TRUE(cloud.ok());
      auto& points = frames.emplace_back();
      for (const LidarPoint& p : cloud->points) points.push_back({p.x, p.y, p.z, p.ring});
    }
    const std::vector<std::span<const RoundHoleCloudPoint>> spans(frames.begin(), frames.end());
    std::vector<RoundHoleCloudDetection> detections;
    CalibrateLidarFrames(capture.station, capture.manifest.aligner.T_station_car(), model, spans,
                         &detections);
    ASSERT_EQ(view["boards"].size(), detections.size());
    int holes = 0;
    for (size_t b = 0; b < detections.size(); ++b) {
      ASSERT_EQ(view["boards"][b]["found"], detections[b].found);
      if (!detections[b].found) continue;
      const json& shown = view["boards"][b]["holes"];
      ASSERT_EQ(shown.size(), detections[b].holes.size());
      for (size_t h = 0; h < shown.size(); ++h) {
        EXPECT_EQ(shown[h]["id"], detections[b].holes[h].id);
        for (int k = 0; k < 3; ++k) EXPECT_EQ(shown[h]["p"][k], detections[b].holes[h].p_lidar[k]);
      }
      holes += static_cast<int>(shown.size());
    }
    EXPECT_EQ(holes, result.features_used);
    EXPECT_LE(view["points"].size(), static_cast<size_t>(kMaxViewPoints));
    EXPECT_GT(view["points"].size(), 0u);
  }

  fs::path dir_;
  std::unique_ptr<StationCore> core_;
  std::unique_ptr<WebServer> web_;
  std::string reader_, operator_;
};

TEST_F(CycleViewsTest, ViewsEqualWhatTheCycleComputed) {
  const int64_t id = RecordedCycle();
  absl::StatusOr<StoredCycle> stored = core_->GetCycle(id);
  ASSERT_TRUE(stored.ok()) << stored.status();
  ASSERT_EQ(stored->state, CycleState::kDone);
  absl::StatusOr<Capture> capture = ReadCapture((dir_ / "data" / stored->capture_path).string());
  ASSERT_TRUE(capture.ok()) << capture.status();
  CaptureCalibrationOptions options;
  options.keep_first_frame_features = true;
  absl::StatusOr<CycleCalibration> cycle = CalibrateCapture(*capture, options);
  ASSERT_TRUE(cycle.ok()) << cycle.status();

  const std::string base = "/api/cycles/" + std::to_string(id);
  const auto [files_status, files] = GetJson(base + "/capture");
  ASSERT_EQ(files_status, 200) << files;
  EXPECT_TRUE(files["kept"]);
  const std::vector<CaptureFileEntry> list = CaptureFileList(*capture);
  ASSERT_EQ(files["files"].size(), list.size());
  for (size_t i = 0; i < list.size(); ++i) {
    EXPECT_EQ(files["files"][i]["path"], list[i].path);
    EXPECT_EQ(files["files"][i]["bytes"], fs::file_size(fs::path(capture->dir) / list[i].path));
  }

  int cameras = 0, lidars = 0, radars = 0;
  for (const SensorCalibration& s : cycle->sensors) {
    SCOPED_TRACE(s.name);
    const StoredSensorResult* result = nullptr;
    for (const StoredSensorResult& r : stored->sensors) {
      if (r.sensor == s.name) result = &r;
    }
    ASSERT_NE(result, nullptr);
    const auto [status, view] = GetJson(base + "/views/" + s.name);
    ASSERT_EQ(status, 200) << view;
    EXPECT_EQ(view["cycle_id"], std::to_string(id));
    if (s.kind == SensorKind::kCamera) {
      ++cameras;
      ASSERT_NO_FATAL_FAILURE(ExpectCameraView(view, s, *result, *capture, list, id));
    } else if (s.kind == SensorKind::kLidar) {
      ++lidars;
      ASSERT_NO_FATAL_FAILURE(ExpectLidarView(view, s, *result, *capture));
    } else {
      ++radars;
      int found = 0;
      for (const json& r : view["reflectors"]) found += r["status"] == "found" ? 1 : 0;
      EXPECT_EQ(found, result->features_used);
      EXPECT_LE(view["detections"].size(), static_cast<size_t>(kMaxViewPoints));
      EXPECT_GT(view["detections_total"].get<int>(), 0);
    }
  }
  EXPECT_GT(cameras, 0);
  EXPECT_GT(lidars, 0);
  EXPECT_GT(radars, 0);
}

TEST_F(CycleViewsTest, RefusesWhatIsNotThere) {
  const int64_t id = RecordedCycle();
  const std::string base = "/api/cycles/" + std::to_string(id);
  auto [status, body] = GetJson(base + "/capture");
  const size_t files = body["files"].size();
  std::tie(status, body) = GetJson(base + "/capture/" + std::to_string(files));
  EXPECT_EQ(status, 400);
  EXPECT_EQ(body["error"], "file = '" + std::to_string(files) + "': must be in [0, " +
                               std::to_string(files) + ")");
  std::tie(status, body) = GetJson(base + "/capture/-1");
  EXPECT_EQ(status, 400);
  std::tie(status, body) = GetJson(base + "/views/no_such_sensor");
  EXPECT_EQ(status, 404);
  EXPECT_EQ(body["error"],
            "sensor: 'no_such_sensor' is not in cycle " + std::to_string(id) + "'s capture");
  std::tie(status, body) = GetJson(base + "/views/front_camera?frame=1");
  EXPECT_EQ(status, 400);
  EXPECT_EQ(body["error"], "frame = 1: front_camera has 1 frames");
  std::tie(status, body) = GetJson("/api/cycles/77/capture");
  EXPECT_EQ(status, 404);
  // A path instead of an index never reaches a file.
  httplib::Result r =
      Client().Get((base + "/capture/..%2Fstation.db").c_str(), {{"Cookie", reader_}});
  ASSERT_TRUE(r);
  EXPECT_NE(r->status, 200);

  // A cycle run without record_capture has no capture: an answer saying so, not an error.
  CycleRequest request;
  request.vin = kVin;
  request.car_model_id = "reference";
  ASSERT_TRUE(core_->StartCycle(request).ok());
  core_->WaitIdle();
  const std::string plain = "/api/cycles/" + std::to_string(id + 1);
  std::tie(status, body) = GetJson(plain + "/capture");
  EXPECT_EQ(status, 200);
  EXPECT_FALSE(body["kept"]);
  EXPECT_EQ(body["reason"],
            "capture_not_kept: cycle " + std::to_string(id + 1) +
                "'s capture was not kept (the cycle was started without record_capture)");
  std::tie(status, body) = GetJson(plain + "/views/front_camera");
  EXPECT_EQ(status, 409);

  // While a cycle runs its capture is not shown yet: said, not refused.
  ASSERT_TRUE(core_->StartCycle(request).ok());
  const std::string running = "/api/cycles/" + std::to_string(id + 2);
  std::tie(status, body) = GetJson(running + "/capture");
  EXPECT_EQ(status, 200);
  EXPECT_FALSE(body["kept"]);
  EXPECT_EQ(body["reason"], "cycle " + std::to_string(id + 2) + " is running");
}

// The capture's download as one archive: every file of the capture's folder, byte for byte,
// the manifest's list first; nothing a link in the folder points at; 404 without a capture.
TEST_F(CycleViewsTest, CaptureArchiveHoldsEveryFileOfTheCapture) {
  const int64_t id = RecordedCycle();
  const std::string top = "cycle-" + std::to_string(id);
  absl::StatusOr<StoredCycle> stored = core_->GetCycle(id);
  ASSERT_TRUE(stored.ok());
  const fs::path dir = dir_ / "data" / stored->capture_path;
  absl::StatusOr<Capture> capture = ReadCapture(dir.string());
  ASSERT_TRUE(capture.ok()) << capture.status();
  // Links to what is outside the capture (a file and a folder) must not be followed.
  const fs::path secret = dir_ / "secret";
  fs::create_directories(secret);
  { std::ofstream(secret / "token.txt") << "not for download"; }
  fs::create_symlink(secret / "token.txt", dir / "linked.txt");
  fs::create_directory_symlink(secret, dir / "linked_folder");
  std::vector<std::pair<std::string, std::string>> expected;
  std::set<std::string> listed;
  for (const CaptureFileEntry& f : CaptureFileList(*capture)) {
    expected.emplace_back(top + "/" + f.path, FileBytes(dir / f.path));
    listed.insert(f.path);
  }
  std::vector<std::string> others;
  for (const fs::directory_entry& e : fs::recursive_directory_iterator(dir)) {
    const std::string name = e.path().lexically_relative(dir).generic_string();
    if (fs::is_regular_file(e.symlink_status()) && !listed.contains(name)) others.push_back(name);
  }
  std::sort(others.begin(), others.end());
  for (const std::string& name : others)
    expected.emplace_back(top + "/" + name, FileBytes(dir / name));
  ASSERT_GT(expected.size(), 10u);

  httplib::Result r = Client().Get(("/api/cycles/" + std::to_string(id) + "/capture.tar").c_str(),
                                   {{"Cookie", reader_}});
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  EXPECT_EQ(r->get_header_value("Content-Type"), "application/x-tar");
  EXPECT_EQ(r->get_header_value("Content-Disposition"),
            "attachment; filename=\"" + top + "-capture.tar\"");
  bool ok = false;
  const std::vector<std::pair<std::string, std::string>> members = TarMembers(r->body, &ok);
  EXPECT_TRUE(ok);
  ASSERT_EQ(members.size(), expected.size());
  for (size_t i = 0; i < members.size(); ++i) {
    EXPECT_EQ(members[i].first, expected[i].first);
    EXPECT_TRUE(members[i].second == expected[i].second) << members[i].first;
  }
  std::cout << members.size() << " files, " << r->body.size() << " bytes of tar\n";

  // Without a session, for a malformed or unknown cycle, and for one that kept no capture.
  httplib::Result anonymous =
      Client().Get(("/api/cycles/" + std::to_string(id) + "/capture.tar").c_str());
  ASSERT_TRUE(anonymous);
  EXPECT_EQ(anonymous->status, 401);
  auto [status, body] = GetJson("/api/cycles/abc/capture.tar");
  EXPECT_EQ(status, 400);
  EXPECT_EQ(body["error"], "cycle_id: 'abc' is not a cycle id");
  std::tie(status, body) = GetJson("/api/cycles/77/capture.tar");
  EXPECT_EQ(status, 404);
  CycleRequest request;
  request.vin = kVin;
  request.car_model_id = "reference";
  ASSERT_TRUE(core_->StartCycle(request).ok());
  core_->WaitIdle();
  std::tie(status, body) = GetJson("/api/cycles/" + std::to_string(id + 1) + "/capture.tar");
  EXPECT_EQ(status, 404);
  EXPECT_EQ(body["error"],
            "capture_not_kept: cycle " + std::to_string(id + 1) +
                "'s capture was not kept (the cycle was started without record_capture)");
}

TEST_F(CycleViewsTest, OnlyOperatorsStartAndCancelCycles) {
  const json start{{"vin", kVin}, {"car_model_id", "reference"}, {"record_capture", true}};
  // Read-only: refused whatever it sends.
  auto [status, body] = Post("/api/cycles", start, reader_);
  EXPECT_EQ(status, 403);
  EXPECT_EQ(body["code"], "permission_denied");
  EXPECT_EQ(body["error"],
            "operator role required: this session is read-only; log in with the operator token");
  // An operator's cookie without the action header (a form of another site) or from another
  // origin: refused before anything else.
  std::tie(status, body) = Post("/api/cycles", start, operator_, false);
  EXPECT_EQ(status, 403);
  EXPECT_EQ(body["error"],
            "csrf: the request lacks the header X-Linecal-Action: 1 that the console's pages send");
  std::tie(status, body) = Post("/api/cycles", start, operator_, true, "http://evil.example");
  EXPECT_EQ(status, 403);
  EXPECT_EQ(body["error"], "csrf: Origin 'http://evil.example' is not this console's");
  absl::StatusOr<CyclePage> none = core_->ListCycles({});
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(none->cycles.empty());
  // Sessions say their role.
  httplib::Result session = Client().Get("/api/session", {{"Cookie", operator_}});
  ASSERT_TRUE(session);
  EXPECT_EQ(json::parse(session->body)["role"], "operator");
  std::tie(status, body) = GetJson("/api/session");
  EXPECT_EQ(body["role"], "read-only");

  // The operator, from this console's own origin: the cycle runs and is stored as asked.
  const std::string origin = "http://127.0.0.1:" + std::to_string(web_->port());
  std::tie(status, body) = Post("/api/cycles", start, operator_, true, origin);
  ASSERT_EQ(status, 200) << body;
  const int64_t id = std::stoll(body["cycle_id"].get<std::string>());
  core_->WaitIdle();
  absl::StatusOr<StoredCycle> stored = core_->GetCycle(id);
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ(stored->vin, kVin);
  EXPECT_EQ(stored->state, CycleState::kDone);
  EXPECT_EQ(stored->sensors.size(), 10u);
  EXPECT_EQ(json::parse(stored->request_json)["record_capture"], true);

  // Bad requests name the field; StartCycle's own checks answer as for gRPC.
  std::tie(status, body) = Post("/api/cycles", {{"vin", kVin}}, operator_);
  EXPECT_EQ(status, 400);
  EXPECT_EQ(body["error"], "request: car_model_id: missing");
  std::tie(status, body) =
      Post("/api/cycles", {{"vin", "123"}, {"car_model_id", "reference"}}, operator_);
  EXPECT_EQ(status, 400);
  EXPECT_EQ(body["error"].get<std::string>().rfind("vin: ", 0), 0u) << body;

  // Cancel: read-only refused, the operator's accepted, the cycle ends cancelled; a second
  // cancel of the ended cycle is 409 as CancelCycle's FailedPrecondition.
  std::tie(status, body) =
      Post("/api/cycles", {{"vin", kVin}, {"car_model_id", "reference"}}, operator_);
  ASSERT_EQ(status, 200) << body;
  const std::string running = body["cycle_id"];
  std::tie(status, body) = Post("/api/cycles/" + running + "/cancel", json::object(), reader_);
  EXPECT_EQ(status, 403);
  std::tie(status, body) = Post("/api/cycles/" + running + "/cancel", json::object(), operator_);
  EXPECT_EQ(status, 200) << body;
  core_->WaitIdle();
  stored = core_->GetCycle(std::stoll(running));
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ(stored->state, CycleState::kCancelled);
  std::tie(status, body) = Post("/api/cycles/" + running + "/cancel", json::object(), operator_);
  EXPECT_EQ(status, 409);
}

TEST(OperatorActionsTest, SameSiteCheck) {
  EXPECT_TRUE(CheckSameSiteAction("1", "", "station:8080", false).ok());
  EXPECT_TRUE(CheckSameSiteAction("1", "http://station:8080", "station:8080", false).ok());
  EXPECT_TRUE(CheckSameSiteAction("1", "https://station:8443", "station:8443", true).ok());
  EXPECT_TRUE(absl::IsPermissionDenied(
      CheckSameSiteAction("1", "http://station:8443", "station:8443", true)));
  EXPECT_TRUE(absl::IsPermissionDenied(CheckSameSiteAction("", "", "station:8080", false)));
  EXPECT_TRUE(absl::IsPermissionDenied(CheckSameSiteAction("1", "null", "station:8080", false)));
}

}  // namespace
}  // namespace linecal

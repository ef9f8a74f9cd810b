// The after-sale page's API (daemon/web/aftersale_api.h) through the console's HTTP server on
// 127.0.0.1 over the real core with the reference car: a lane scene of `linecal sim lanes`
// solved by POST /api/aftersale equals `linecal aftersale --json` on the same input (every
// number, as doubles) and its export equals `--export`'s files byte for byte; the overlay's
// lines; the photo upload's size and its refusals (not an image, empty, too large, a form, a
// header claiming too many pixels); the command's refusals with the command's messages; the
// bird's-eye PNG of a kept photo equal to the command's --out file and its refusals; and no
// call without a session.
// First: httplib.h brings resolv.h, whose `_res` macro breaks Eigen's headers after it.
#include "daemon/web/aftersale_api.h"

#include <gtest/gtest.h>
#include <httplib.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "daemon/web/web_server.h"
#include "station/aftersale/document.h"
#include "station/aftersale/overlay.h"
#include "station/io/json_reader.h"
#include "tests/daemon/scratch_dir.h"
#include "tests/daemon/web/reference_core.h"
#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using testing_tools::RunLinecal;

using testing_web::kDeploy;
using testing_web::kStatic;
constexpr char kToken[] = "workshop-7-token";

std::string ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// PNG's CRC-32 (ISO 3309, the reflected polynomial 0xEDB88320) of `bytes`.
uint32_t PngCrc(std::string_view bytes) {
  uint32_t c = 0xFFFFFFFFu;
  for (const char b : bytes) {
    c ^= static_cast<uint8_t>(b);
    for (int k = 0; k < 8; ++k) c = c & 1 ? 0xEDB88320u ^ (c >> 1) : c >> 1;
  }
  return c ^ 0xFFFFFFFFu;
}

class AftersaleApiTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_daemon::FreshTestDir("web_aftersale");
    absl::StatusOr<std::unique_ptr<StationCore>> core = testing_web::ReferenceCore(dir_);
    ASSERT_TRUE(core.ok()) << core.status();
    core_ = *std::move(core);
    absl::StatusOr<std::unique_ptr<WebServer>> web =
        WebServer::Start(core_.get(), {"127.0.0.1:0", std::nullopt, kStatic, kToken, "test"});
    ASSERT_TRUE(web.ok()) << web.status();
    web_ = *std::move(web);
    httplib::Result r =
        Client().Post("/api/login", json{{"token", kToken}}.dump(), "application/json");
    ASSERT_TRUE(r && r->status == 200);
    const std::string cookie = r->get_header_value("Set-Cookie");
    cookie_ = cookie.substr(0, cookie.find(';'));
  }
  void TearDown() override {
    web_.reset();
    core_.reset();
    fs::remove_all(dir_);
  }
  httplib::Client Client() const { return httplib::Client("127.0.0.1", web_->port()); }
  httplib::Headers Cookie() const { return {{"Cookie", cookie_}}; }
  // POST `body` to `path` with the session; the status and the parsed JSON answer.
  std::pair<int, json> Post(const std::string& path, const std::string& body,
                            const std::string& type = "application/json") const {
    httplib::Result r = Client().Post(path.c_str(), Cookie(), body, type.c_str());
    EXPECT_TRUE(r) << path << ": " << httplib::to_string(r.error());
    if (!r) return {0, json()};
    EXPECT_EQ(r->get_header_value("Content-Type"), "application/json") << path;
    return {r->status, json::parse(r->body)};
  }
  // A lane scene of the reference car's `camera` by `linecal sim lanes` into dir_/scene.
  fs::path SimLanes(const std::string& camera, const std::string& options) const {
    const fs::path scene = dir_ / "scene";
    const testing_tools::LinecalRun run =
        RunLinecal("sim lanes --car " + kDeploy + "/cars/reference.json --camera " + camera + " " +
                   options + " --out " + scene.string());
    EXPECT_EQ(run.exit_code, 0) << run.err;
    return scene;
  }
  // The scene's input as the API takes it: without `image`, with the photo's size.
  static json ApiRequest(const fs::path& scene, int width, int height) {
    json input = json::parse(ReadBytes(scene / "aftersale.json"));
    input.erase("image");
    return {{"image_size", {width, height}}, {"input", input}};
  }

  fs::path dir_;
  std::unique_ptr<StationCore> core_;
  std::unique_ptr<WebServer> web_;
  std::string cookie_;
};

// The worked example of docs/aftersale.md and the rear fisheye of its accuracy section.
TEST_F(AftersaleApiTest, SolveEqualsTheCommandAndExportsItsBytes) {
  struct Case {
    std::string camera, options;
    int width, height;
  };
  for (const Case& c :
       {Case{"front_camera",
             "--ypr-deg 0.8,2.1,-0.6 --xyz-m 1.9,0,1.35 --points-m 5,10,20,30 "
             "--point-noise-px 0.3 --blur 0.7 --seed 3",
             1920, 1080},
        Case{"surround_rear",
             "--points-m 3,5,8,12 --roll-line-m 4 --marked-point-m 6 --point-noise-px 0.3 "
             "--seed 5",
             1280, 960}}) {
    SCOPED_TRACE(c.camera);
    fs::remove_all(dir_ / "scene");
    const fs::path scene = SimLanes(c.camera, c.options);
    // The photo as the page uploads it: its bytes; the answer is the size the command reads.
    const auto [photo_status, photo] =
        Post("/api/aftersale/photo", ReadBytes(scene / (c.camera + ".png")), "image/png");
    ASSERT_EQ(photo_status, 200) << photo.dump();
    const std::string photo_id = photo.value("photo_id", "");
    EXPECT_EQ(photo_id.size(), 32u);
    EXPECT_EQ(photo_id.find_first_not_of("0123456789abcdef"), std::string::npos) << photo_id;
    EXPECT_EQ(photo, (json{{"width", c.width}, {"height", c.height}, {"photo_id", photo_id}}));

    const testing_tools::LinecalRun cli = RunLinecal(
        "aftersale --input " + (scene / "aftersale.json").string() + " --json" + " --export " +
        (scene / "export").string() + " --out " + (scene / "out").string());
    ASSERT_EQ(cli.exit_code, 0) << cli.err;
    json expected = json::parse(cli.out);
    for (const char* file_key : {"image", "export", "overlay_png", "birdseye_png"})
      expected.erase(file_key);

    const auto [status, answer] =
        Post("/api/aftersale", ApiRequest(scene, c.width, c.height).dump());
    ASSERT_EQ(status, 200) << answer.dump();
    // Equal as parsed JSON: every number the same double, every key and string the same.
    EXPECT_EQ(answer["result"], expected) << answer["result"].dump(2) << "\nvs\n"
                                          << expected.dump(2);
    ASSERT_EQ(answer["export"].size(), 3u);
    for (const json& file : answer["export"]) {
      const fs::path written = scene / "export" / file["file"].get<std::string>();
      ASSERT_TRUE(fs::exists(written)) << written;
      EXPECT_EQ(file["text"].get<std::string>(), ReadBytes(written)) << written;
    }
    EXPECT_FALSE(answer.contains("birdseye"));  // no photo_id: nothing kept for the answer

    // With the photo's id: the bird's-eye PNG of the uploaded photo through this solve is the
    // command's <name>-birdseye.png byte for byte (the same picture, encoder and settings).
    json request = ApiRequest(scene, c.width, c.height);
    request["photo_id"] = photo_id;
    const auto [with_status, with_photo] = Post("/api/aftersale", request.dump());
    ASSERT_EQ(with_status, 200) << with_photo.dump();
    EXPECT_EQ(with_photo["result"], answer["result"]);
    EXPECT_EQ(with_photo["birdseye"],
              "/api/aftersale/photos/" + photo_id + "/birdseye.png?solve=1");
    httplib::Result png = Client().Get(with_photo["birdseye"].get<std::string>().c_str(), Cookie());
    ASSERT_TRUE(png);
    ASSERT_EQ(png->status, 200) << png->body;
    EXPECT_EQ(png->get_header_value("Content-Type"), "image/png");
    const std::string birdseye = ReadBytes(scene / "out" / (c.camera + "-birdseye.png"));
    ASSERT_FALSE(birdseye.empty());
    EXPECT_TRUE(png->body == birdseye) << png->body.size() << " vs " << birdseye.size() << " bytes";
  }
}

// The bird's-eye view's refusals: each names what is missing.
TEST_F(AftersaleApiTest, BirdsEyeNeedsAKeptPhotoAndASolution) {
  const fs::path scene = SimLanes("front_camera", "--points-m 5,10,20,30 --seed 3");
  const auto get = [&](const std::string& path) {
    httplib::Result r = Client().Get(path.c_str(), Cookie());
    EXPECT_TRUE(r) << path;
    if (!r) return std::make_pair(0, json());
    return std::make_pair(r->status, json::parse(r->body));
  };
  // No such photo.
  const std::string unknown = "0123456789abcdef0123456789abcdef";
  auto [status, body] = get("/api/aftersale/photos/" + unknown + "/birdseye.png");
  EXPECT_EQ(status, 404);
  EXPECT_EQ(body["error"], "photo_id: '" + unknown +
                               "' is not kept (never uploaded, or dropped for newer photos): "
                               "upload the photo again (POST /api/aftersale/photo)");
  json request = ApiRequest(scene, 1920, 1080);
  request["photo_id"] = unknown;
  std::tie(status, body) = Post("/api/aftersale", request.dump());
  EXPECT_EQ(status, 404);
  EXPECT_EQ(body["code"], "not_found");
  // A photo, no solution yet.
  const auto [photo_status, photo] =
      Post("/api/aftersale/photo", ReadBytes(scene / "front_camera.png"), "image/png");
  ASSERT_EQ(photo_status, 200);
  const std::string id = photo["photo_id"];
  const std::string path = "/api/aftersale/photos/" + id + "/birdseye.png";
  std::tie(status, body) = get(path);
  EXPECT_EQ(status, 409);
  EXPECT_EQ(body["error"], "birdseye: photo '" + id +
                               "' has no solution yet: solve its lane points first (POST "
                               "/api/aftersale with its photo_id)");
  // A solve for another image size than the photo's.
  request["photo_id"] = id;
  request["image_size"] = {1280, 960};
  std::tie(status, body) = Post("/api/aftersale", request.dump());
  EXPECT_EQ(status, 400);
  EXPECT_EQ(body["error"],
            "request: image_size: [1280, 960] differs from photo " + id + "'s 1920 x 1080");
  // Solved: a picture; then a refused solve (parallel lines): no solution any more.
  request["image_size"] = {1920, 1080};
  std::tie(status, body) = Post("/api/aftersale", request.dump());
  ASSERT_EQ(status, 200);
  httplib::Result png = Client().Get(path.c_str(), Cookie());
  ASSERT_TRUE(png);
  EXPECT_EQ(png->status, 200);
  request["input"]["lanes"] = {{{500, 900}, {600, 300}}, {{900, 900}, {1000.5, 300}}};
  std::tie(status, body) = Post("/api/aftersale", request.dump());
  EXPECT_EQ(status, 400);
  std::tie(status, body) = get(path);
  EXPECT_EQ(status, 409);
  EXPECT_EQ(body["error"],
            "birdseye: photo '" + id + "' has no solution: its latest solve was refused");
  // Not without a session.
  httplib::Result anonymous = Client().Get(path.c_str());
  ASSERT_TRUE(anonymous);
  EXPECT_EQ(anonymous->status, 401);
}

// Photos are kept within kMaxKeptPhotoPixels: the least recently used go first.
TEST(AftersalePhotosTest, KeepsTheMostRecentlyUsedWithinTheBound) {
  AftersalePhotos photos;
  // 1920 x 1080: 24 fit in 50 Mpx.
  std::vector<std::string> ids;
  for (int i = 0; i < 25; ++i) {
    absl::StatusOr<std::string> id = photos.Keep(Image8(1920, 1080, 0));
    ASSERT_TRUE(id.ok());
    ids.push_back(*id);
    if (i == 0) continue;
    ASSERT_TRUE(photos.Size(ids[0]).ok());  // used at each upload: never the least recent
  }
  EXPECT_TRUE(photos.Size(ids[0]).ok());
  EXPECT_EQ(photos.Size(ids[1]).status().code(), absl::StatusCode::kNotFound);
  for (int i = 2; i < 25; ++i) EXPECT_TRUE(photos.Size(ids[i]).ok()) << i;
}

TEST_F(AftersaleApiTest, OverlayIsTheCommandsLinesAtThePagesDensity) {
  const fs::path scene = SimLanes("front_camera", "--points-m 5,10,20,30 --seed 3");
  const json request = ApiRequest(scene, 1920, 1080);
  const auto [status, answer] = Post("/api/aftersale", request.dump());
  ASSERT_EQ(status, 200) << answer.dump();
  const json& overlay = answer["overlay"];
  // 10 lines across every 5 m from 5 to 50 m, 11 along every metre from -5 to 5 m.
  ASSERT_EQ(overlay["ground_grid"].size(), 21u);
  for (const json& line : overlay["ground_grid"]) {
    EXPECT_EQ(line.size(), static_cast<size_t>(kPageOverlaySegments + 1));
  }
  EXPECT_EQ(overlay["horizon"].size(), 121u);  // every degree from 60 left to 60 right
  ASSERT_EQ(overlay["lane_lines"].size(), 2u);
  // Each lane line ends at the vanishing point: the result's, through the lens, as drawn
  // (rounded to 0.01 px, so within half of that of each other).
  const json& vp = overlay["vanishing_point"];
  ASSERT_TRUE(vp.is_array());
  for (const json& line : overlay["lane_lines"]) {
    ASSERT_EQ(line.size(), static_cast<size_t>(kPageOverlaySegments + 1));
    EXPECT_EQ(line.back(), vp);
  }
  // Recomputed here with station/aftersale on the result's input: the same lines.
  AftersaleRequest r;
  absl::StatusOr<JsonDocument> doc = JsonDocument::FromText(request["input"].dump(), "input");
  ASSERT_TRUE(doc.ok());
  ASSERT_TRUE(ReadAftersaleInput(*doc->Root(), &r).ok());
  absl::StatusOr<LaneCalibrationInput> in = AftersaleSolverInput(r, 1920, 1080);
  ASSERT_TRUE(in.ok());
  absl::StatusOr<LaneCalibrationResult> result = CalibrateFromLanes(*in);
  ASSERT_TRUE(result.ok());
  const LaneOverlay lines = LaneOverlayOf(*CameraModel::Create(in->intrinsics), *in, *result,
                                          {.segments = kPageOverlaySegments});
  // 0.005 px: half the answer's rounding step.
  constexpr double kRounding = 0.005 + 1e-9;
  ASSERT_TRUE(lines.vanishing_point_uv.has_value());
  EXPECT_NEAR(vp[0].get<double>(), lines.vanishing_point_uv->x(), kRounding);
  EXPECT_NEAR(vp[1].get<double>(), lines.vanishing_point_uv->y(), kRounding);
  int drawn = 0;
  for (size_t i = 0; i < lines.ground_grid.size(); ++i) {
    for (size_t j = 0; j < lines.ground_grid[i].size(); ++j) {
      const json& p = overlay["ground_grid"][i][j];
      ASSERT_EQ(p.is_null(), !lines.ground_grid[i][j].has_value()) << i << "," << j;
      if (p.is_null()) continue;
      EXPECT_NEAR(p[0].get<double>(), lines.ground_grid[i][j]->x(), kRounding);
      EXPECT_NEAR(p[1].get<double>(), lines.ground_grid[i][j]->y(), kRounding);
      ++drawn;
    }
  }
  // The front camera sees most of the grid: more than half of its points are in the image.
  EXPECT_GT(drawn, 21 * (kPageOverlaySegments + 1) / 2);
}

TEST_F(AftersaleApiTest, CamerasAreTheCarModelsCamerasAtTheirNominalMounting) {
  httplib::Result r = Client().Get("/api/aftersale/cameras", Cookie());
  ASSERT_TRUE(r && r->status == 200);
  const json answer = json::parse(r->body);
  EXPECT_EQ(answer["max_photo_bytes"], kMaxPhotoBytes);
  const json cameras = answer["cameras"];
  const json car = json::parse(ReadBytes(kDeploy + "/cars/reference.json"));
  size_t expected = 0;
  for (const json& s : car["sensors"]) expected += s["kind"] == "camera" ? 1 : 0;
  ASSERT_EQ(cameras.size(), expected);
  bool front = false, rear = false;
  for (const json& c : cameras) {
    EXPECT_EQ(c["car_model_id"], "reference");
    const SensorModel* s = core_->car_models()[0].FindSensor(c["camera"].get<std::string>());
    ASSERT_NE(s, nullptr);
    const json& in = c["input"];
    EXPECT_EQ(in["name"], c["camera"]);
    EXPECT_EQ(c["image_size"], (json{s->intrinsics->width, s->intrinsics->height}));
    EXPECT_EQ(in["intrinsics"]["fx"].get<double>(), s->intrinsics->fx);
    EXPECT_EQ(in["intrinsics"]["cy"].get<double>(), s->intrinsics->cy);
    EXPECT_EQ(in["camera_height_m"].get<double>(), s->T_car_sensor_nominal.translation().z());
    EXPECT_EQ(in["longitudinal_offset_m"].get<double>(), s->T_car_sensor_nominal.translation().x());
    if (c["camera"] == "front_camera") front = !in["looking_backward"].get<bool>();
    if (c["camera"] == "surround_rear") rear = in["looking_backward"].get<bool>();
  }
  EXPECT_TRUE(front) << "front_camera listed, looking forward";
  EXPECT_TRUE(rear) << "surround_rear listed, looking backward";
}

TEST_F(AftersaleApiTest, RefusalsCarryTheCommandsMessages) {
  const fs::path scene = SimLanes("front_camera", "--points-m 5,10,20,30 --seed 3");
  const json base = ApiRequest(scene, 1920, 1080);
  struct Case {
    std::string what;
    json request;
    // The API's message; "" for the command's on the same input (its stderr after
    // "linecal aftersale: ").
    std::string message;
  };
  // The points of tests/tools/cmd_aftersale_test.cc's refusals.
  json parallel = base;
  parallel["input"]["lanes"] = {{{500, 900}, {600, 300}}, {{900, 900}, {1000.5, 300}}};
  json above = base;
  above["input"]["lanes"] = {{{580, 200}, {880, 420}}, {{1380, 200}, {1080, 420}}};
  json no_height = base;
  no_height["input"].erase("camera_height_m");
  json with_image = base;
  with_image["input"]["image"] = "front_camera.png";
  json bad_size = base;
  bad_size["image_size"] = {1920.5, 1080};
  json unknown = base;
  unknown["input"]["camera_heigth_m"] = 1.2;
  for (const Case& c :
       {Case{"parallel lines", parallel, ""}, Case{"above the horizon", above, ""},
        Case{"no height", no_height, ""},
        Case{"an image", with_image,
             "request: input.image: not taken here: the photo is uploaded (POST "
             "/api/aftersale/photo) and its size given as image_size"},
        Case{"a fraction of a pixel", bad_size,
             "request: image_size: must be two whole numbers of pixels in [1, 16384], got "
             "1920.5"}}) {
    SCOPED_TRACE(c.what);
    const auto [status, answer] = Post("/api/aftersale", c.request.dump());
    EXPECT_EQ(status, 400) << answer.dump();
    EXPECT_EQ(answer["code"], "invalid_argument");
    const std::string message = answer["error"].get<std::string>();
    if (!c.message.empty()) {
      EXPECT_EQ(message, c.message);
      continue;
    }
    const fs::path input = dir_ / "refused.json";
    json doc = c.request["input"];
    doc["image"] = (scene / "front_camera.png").string();
    std::ofstream(input) << doc.dump();
    const testing_tools::LinecalRun cli = RunLinecal("aftersale --input " + input.string());
    EXPECT_EQ(cli.exit_code, 2);
    EXPECT_EQ(cli.err, "linecal aftersale: " + message + "\n");
  }
  // A misspelt key is named (the command's file names it the same, with its file's name).
  const auto [status, answer] = Post("/api/aftersale", unknown.dump());
  EXPECT_EQ(status, 400);
  EXPECT_EQ(answer["error"].get<std::string>().rfind(
                "request: input.camera_heigth_m: unknown field (known: name, image, ", 0),
            0u)
      << answer.dump();
  EXPECT_EQ(Post("/api/aftersale", "{\"image_size\": [1920, 1080],").first, 400);
}

TEST_F(AftersaleApiTest, PhotoRefusals) {
  const auto refused = [&](const std::string& body, const std::string& type) {
    const auto [status, answer] = Post("/api/aftersale/photo", body, type);
    return std::make_pair(status, answer.value("error", std::string()));
  };
  EXPECT_EQ(refused("%PDF-1.7 not a photo", "application/pdf"),
            std::make_pair(400, std::string("photo: not a PNG or JPEG file")));
  EXPECT_EQ(refused("", "image/png"), std::make_pair(400, std::string("photo: empty")));
  // One byte over the bound: 413, and the connection still answers (the body was drained).
  const auto [status, answer] =
      Post("/api/aftersale/photo", std::string(kMaxPhotoBytes + 1, 'x'), "image/png");
  EXPECT_EQ(status, 413);
  EXPECT_EQ(answer["error"], "photo: larger than 33554432 bytes");
  EXPECT_EQ(answer["code"], "resource_exhausted");
  // A PNG whose header claims 30000 x 30000 pixels: refused before decoding.
  const fs::path scene = SimLanes("front_camera", "--seed 3");
  std::string png = ReadBytes(scene / "front_camera.png");
  for (int i = 0; i < 2; ++i) {
    // IHDR's width and height, big-endian at bytes 16..23; 30000 = 0x7530.
    png[16 + 4 * i] = 0, png[17 + 4 * i] = 0, png[18 + 4 * i] = 0x75, png[19 + 4 * i] = 0x30;
  }
  // The chunk's CRC (over its type and data, bytes 12..28) after it, so that only the size lies.
  const uint32_t crc = PngCrc(std::string_view(png).substr(12, 17));
  for (int i = 0; i < 4; ++i) png[29 + i] = static_cast<char>(crc >> (24 - 8 * i));
  const auto [big_status, big] = refused(png, "image/png");
  EXPECT_EQ(big_status, 400);
  EXPECT_NE(big.find("photo: 900000000 pixels exceed the budget of 25000000"), std::string::npos)
      << big;
  // A truncated PNG: libpng's complaint, named as the photo.
  const std::string whole = ReadBytes(scene / "front_camera.png");
  const auto [cut_status, cut] = refused(whole.substr(0, whole.size() / 2), "image/png");
  EXPECT_EQ(cut_status, 400);
  EXPECT_EQ(cut.rfind("photo: ", 0), 0u) << cut;
  // A form: the page sends the file's bytes, a form is refused by name.
  httplib::MultipartFormDataItems form = {{"photo", whole, "front_camera.png", "image/png"}};
  httplib::Result r = Client().Post("/api/aftersale/photo", Cookie(), form);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 415);
  EXPECT_EQ(json::parse(r->body)["error"], "photo: send the file's bytes as the body, not a form");
  // The solve's request is bounded too.
  EXPECT_EQ(Post("/api/aftersale", std::string(kMaxAftersaleRequestBytes + 1, ' ')).first, 413);
}

TEST_F(AftersaleApiTest, NothingWithoutASession) {
  for (const char* path : {"/api/aftersale/cameras"}) {
    httplib::Result r = Client().Get(path);
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 401) << path;
  }
  for (const char* path : {"/api/aftersale/photo", "/api/aftersale"}) {
    httplib::Result r = Client().Post(path, "{}", "application/json");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 401) << path;
  }
}

}  // namespace
}  // namespace linecal

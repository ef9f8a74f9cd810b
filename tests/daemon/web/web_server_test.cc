// The station console's HTTP server (daemon/web) on 127.0.0.1 over the real core, store and
// simulator, beside the real gRPC server on the same core: login and sessions, the JSON API's
// numbers against gRPC GetCycle / ListCycles, the event streams against the stored events and
// their delay, static files and their types, and HTTPS with the test PKI's certificates.
#include "daemon/web/web_server.h"

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <httplib.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_split.h"
#include "daemon/service/station_service.h"
#include "daemon/web/console_json.h"
#include "station/io/json_reader.h"
#include "tests/daemon/scratch_dir.h"
#include "tests/daemon/test_car.h"
#include "tests/daemon/test_pki.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
const std::string kStatic = std::string(LINECAL_SOURCE_DIR) + "/daemon/web/static";
constexpr char kVin[] = "1M8GDM9AXKP042788";
constexpr char kToken[] = "line-3-secret";
// The bar (docs/console.md, "Bars"): a sensor's verdict on the page within 200 ms of
// its event; the stream's share of it is measured here, from the event's stored time.
constexpr std::chrono::milliseconds kEventDelayBar{200};

// One Server-Sent Event: its `event:`, `id:` and `data:` fields.
struct SseMessage {
  std::string event, id;
  json data;
};

// The messages of a stream's text so far (complete ones: ended by a blank line).
std::vector<SseMessage> ParseSse(const std::string& text) {
  std::vector<SseMessage> out;
  for (absl::string_view block : absl::StrSplit(text, "\n\n")) {
    SseMessage m;
    bool any = false;
    for (absl::string_view line : absl::StrSplit(block, '\n')) {
      if (absl::ConsumePrefix(&line, "event: ")) m.event = std::string(line), any = true;
      if (absl::ConsumePrefix(&line, "id: ")) m.id = std::string(line);
      if (absl::ConsumePrefix(&line, "data: ")) m.data = json::parse(line);
    }
    if (any) out.push_back(std::move(m));
  }
  return out;
}

class WebServerTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = testing_daemon::FreshTestDir("web"); }
  void Start(const std::string& token, const std::optional<TlsConfig>& tls = std::nullopt) {
    testing_daemon::WriteTwoSensorCar((dir_ / "car.json").string());
    StationCoreConfig config;
    config.station_path = kDeploy + "/stations/reference.json";
    config.car_model_paths = {(dir_ / "car.json").string()};
    config.db_path = (dir_ / "station.db").string();
    config.data_root = (dir_ / "data").string();
    absl::StatusOr<std::unique_ptr<StationCore>> core = StationCore::Create(config);
    ASSERT_TRUE(core.ok()) << core.status();
    core_ = *std::move(core);
    absl::StatusOr<RunningServer> grpc_server =
        StartServer(core_.get(), "127.0.0.1:0", token, "test");
    ASSERT_TRUE(grpc_server.ok()) << grpc_server.status();
    grpc_ = std::move(*grpc_server);
    stub_ = v1::Station::NewStub(grpc::CreateChannel("127.0.0.1:" + std::to_string(grpc_.port),
                                                     grpc::InsecureChannelCredentials()));
    absl::StatusOr<std::unique_ptr<WebServer>> web =
        WebServer::Start(core_.get(), {"127.0.0.1:0", tls, kStatic, token, "test"});
    ASSERT_TRUE(web.ok()) << web.status();
    web_ = *std::move(web);
  }
  void TearDown() override {
    if (core_) core_->WaitIdle();
    web_.reset();
    if (grpc_.server) grpc_.server->Shutdown();
    grpc_ = {};
    core_.reset();
    fs::remove_all(dir_);
  }
  httplib::Client Client() const { return httplib::Client("127.0.0.1", web_->port()); }
  // POST /api/login with `token`; the session cookie ("linecal_session=...") or "".
  std::string Login(const std::string& token, int* status = nullptr) const {
    httplib::Result r =
        Client().Post("/api/login", json{{"token", token}}.dump(), "application/json");
    EXPECT_TRUE(r) << httplib::to_string(r.error());
    if (!r) return "";
    if (status) *status = r->status;
    const std::string cookie = r->get_header_value("Set-Cookie");
    return cookie.substr(0, cookie.find(';'));
  }
  // GET `path` with the cookie; the status and the parsed JSON body.
  std::pair<int, json> GetJson(const std::string& path, const std::string& cookie = "") const {
    httplib::Headers headers;
    if (!cookie.empty()) headers.emplace("Cookie", cookie);
    httplib::Result r = Client().Get(path.c_str(), headers);
    EXPECT_TRUE(r) << path << ": " << httplib::to_string(r.error());
    if (!r) return {0, json()};
    EXPECT_EQ(r->get_header_value("Content-Type"), "application/json") << path;
    return {r->status, json::parse(r->body)};
  }
  int64_t StartCycleOverGrpc(const std::string& token = "") {
    grpc::ClientContext context;
    if (!token.empty()) context.AddMetadata("authorization", std::string("Bearer ") + token);
    v1::StartCycleRequest r;
    r.set_vin(kVin);
    r.set_car_model_id("reference");
    r.mutable_aligner()->set_lateral_offset_m(0.01);
    v1::StartCycleResponse started;
    const grpc::Status s = stub_->StartCycle(&context, r, &started);
    EXPECT_TRUE(s.ok()) << s.error_message();
    return std::stoll(started.cycle_id());
  }
  v1::Cycle GetCycleOverGrpc(int64_t id, const std::string& token = "") {
    grpc::ClientContext context;
    if (!token.empty()) context.AddMetadata("authorization", std::string("Bearer ") + token);
    v1::GetCycleRequest r;
    r.set_cycle_id(std::to_string(id));
    v1::Cycle cycle;
    const grpc::Status s = stub_->GetCycle(&context, r, &cycle);
    EXPECT_TRUE(s.ok()) << s.error_message();
    return cycle;
  }

  fs::path dir_;
  std::unique_ptr<StationCore> core_;
  RunningServer grpc_;
  std::unique_ptr<v1::Station::Stub> stub_;
  std::unique_ptr<WebServer> web_;
};

TEST_F(WebServerTest, LoginWithTheTokenGivesASessionCookie) {
  Start(kToken);
  // Without a session: 401 JSON for the API, a redirect to the login page for pages.
  const auto [refused, body] = GetJson("/api/status");
  EXPECT_EQ(refused, 401);
  EXPECT_EQ(body["code"], "unauthenticated");
  httplib::Result page = Client().Get("/cycle.html?id=3");
  ASSERT_TRUE(page);
  EXPECT_EQ(page->status, 303);
  // Sent percent-encoded ("next=%2fcycle.html%3fid%3d3"); httplib's client decodes Location.
  EXPECT_EQ(page->get_header_value("Location"), "/login.html?next=/cycle.html?id=3");
  httplib::Result login_page = Client().Get("/login.html");
  ASSERT_TRUE(login_page);
  EXPECT_EQ(login_page->status, 200);

  // A wrong token: 401, no cookie; a body without a token: 400.
  int status = 0;
  EXPECT_EQ(Login("line-3-secreT", &status), "");
  EXPECT_EQ(status, 401);
  EXPECT_EQ(Login("", &status), "");
  EXPECT_EQ(status, 401);
  httplib::Result no_token =
      Client().Post("/api/login", "token=x", "application/x-www-form-urlencoded");
  ASSERT_TRUE(no_token);
  EXPECT_EQ(no_token->status, 400);

  // The right token: a cookie with a random session id (not the token), HttpOnly and
  // SameSite=Strict, no Secure on plain HTTP.
  httplib::Result ok =
      Client().Post("/api/login", json{{"token", kToken}}.dump(), "application/json");
  ASSERT_TRUE(ok);
  EXPECT_EQ(ok->status, 200);
  const std::string set_cookie = ok->get_header_value("Set-Cookie");
  EXPECT_EQ(set_cookie.find(kToken), std::string::npos) << set_cookie;
  const std::string cookie = set_cookie.substr(0, set_cookie.find(';'));
  ASSERT_EQ(cookie.size(), std::string("linecal_session=").size() + 64) << set_cookie;
  EXPECT_EQ(set_cookie.substr(cookie.size()), "; Path=/; HttpOnly; SameSite=Strict");
  EXPECT_NE(Login(kToken), cookie);  // every login its own session

  const auto [allowed, status_json] = GetJson("/api/status", cookie);
  EXPECT_EQ(allowed, 200);
  EXPECT_EQ(status_json["version"], "test");
  EXPECT_EQ(status_json["running_cycle_id"], "");
  ASSERT_EQ(status_json["sensors"].size(), 2u);
  EXPECT_EQ(status_json["sensors"][0],
            (json{{"name", "front_camera"}, {"kind", "camera"}, {"source", "simulator"}}));
  EXPECT_EQ(GetJson("/api/session", cookie).second, (json{{"login_required", true},
                                                          {"logged_in", true},
                                                          {"operator_login", false},
                                                          {"role", "read-only"}}));

  // A made-up session id is refused; a logged-out one too.
  EXPECT_EQ(GetJson("/api/status", "linecal_session=" + std::string(64, 'a')).first, 401);
  httplib::Result out =
      Client().Post("/api/logout", httplib::Headers{{"Cookie", cookie}}, "", "text/plain");
  ASSERT_TRUE(out);
  EXPECT_EQ(out->status, 200);
  EXPECT_EQ(GetJson("/api/status", cookie).first, 401);
}

TEST_F(WebServerTest, WithoutATokenNoLoginIsNeeded) {
  Start("");
  EXPECT_EQ(GetJson("/api/status").first, 200);
  EXPECT_EQ(GetJson("/api/session").second, (json{{"login_required", false},
                                                  {"logged_in", true},
                                                  {"operator_login", false},
                                                  {"role", "read-only"}}));
  int status = 0;
  EXPECT_EQ(Login("anything", &status), "");
  EXPECT_EQ(status, 409);
  httplib::Result page = Client().Get("/");
  ASSERT_TRUE(page);
  EXPECT_EQ(page->status, 200);
}

// The console's JSON of sensor `i` of a cycle (camera first, then radar) carries exactly the
// numbers of gRPC GetCycle's SensorResult.
void ExpectSensorEqualsGrpc(const json& s, const v1::SensorResult& gs, int i) {
  SCOPED_TRACE(gs.name());
  EXPECT_EQ(s["name"], gs.name());
  EXPECT_EQ(s["kind"], i == 0 ? "camera" : "radar");
  EXPECT_EQ(s["reason"], gs.reason());
  EXPECT_EQ(s["message"], gs.message());
  // Exactly equal doubles: JSON carries the shortest text that reads back to the same double.
  ASSERT_EQ(s["t_car_sensor"].size(), static_cast<size_t>(gs.t_car_sensor().m_size()));
  for (int k = 0; k < gs.t_car_sensor().m_size(); ++k) {
    EXPECT_EQ(s["t_car_sensor"][k].get<double>(), gs.t_car_sensor().m(k)) << k;
  }
  const std::pair<const char*, const v1::MountingAngles*> groups[] = {
      {"mounting", &gs.mounting()},
      {"deviation", &gs.deviation()},
      {"uncertainty", &gs.uncertainty()}};
  for (const auto& [key, m] : groups) {
    EXPECT_EQ(s[key]["yaw_deg"].get<double>(), m->yaw_deg()) << key;
    EXPECT_EQ(s[key]["pitch_deg"].get<double>(), m->pitch_deg()) << key;
    EXPECT_EQ(s[key]["roll_deg"].get<double>(), m->roll_deg()) << key;
    EXPECT_EQ(s[key]["x_m"].get<double>(), m->x_m()) << key;
    EXPECT_EQ(s[key]["y_m"].get<double>(), m->y_m()) << key;
    EXPECT_EQ(s[key]["z_m"].get<double>(), m->z_m()) << key;
  }
  EXPECT_EQ(s["residual_rms"].get<double>(), gs.residual_rms());
  EXPECT_EQ(s["features_used"].get<uint32_t>(), gs.features_used());
  // gRPC has no presence for them: 0 when the JSON leaves them out.
  EXPECT_EQ(s.value("vanishing_point_u_px", 0.0), gs.vanishing_point_u_px());
  EXPECT_EQ(s.value("vanishing_point_v_px", 0.0), gs.vanishing_point_v_px());
  ASSERT_EQ(s.value("ground_homography", json::array()).size(),
            static_cast<size_t>(gs.ground_homography_size()));
  for (int k = 0; k < gs.ground_homography_size(); ++k) {
    EXPECT_EQ(s["ground_homography"][k].get<double>(), gs.ground_homography(k));
  }
}

// The console's JSON of a done cycle carries exactly the numbers of gRPC GetCycle's.
void ExpectCycleEqualsGrpc(const json& c, const v1::Cycle& g) {
  EXPECT_EQ(c["cycle_id"], g.cycle_id());
  EXPECT_EQ(c["vin"], g.vin());
  EXPECT_EQ(c["car_model_id"], g.car_model_id());
  EXPECT_EQ(c["state"], "done");
  EXPECT_EQ(g.state(), v1::CYCLE_STATE_DONE);
  EXPECT_EQ(c["verdict"], g.verdict() == v1::VERDICT_PASS   ? "pass"
                          : g.verdict() == v1::VERDICT_FAIL ? "fail"
                                                            : "error");
  EXPECT_EQ(c["reason"], g.reason());
  EXPECT_EQ(c["started_ns"].get<int64_t>(), g.started_ns());
  EXPECT_EQ(c["ended_ns"].get<int64_t>(), g.ended_ns());
  ASSERT_EQ(c["sensors"].size(), static_cast<size_t>(g.sensors_size()));
  ASSERT_EQ(g.sensors_size(), 2);
  for (int i = 0; i < g.sensors_size(); ++i) {
    ASSERT_NO_FATAL_FAILURE(ExpectSensorEqualsGrpc(c["sensors"][i], g.sensors(i), i));
  }
}

TEST_F(WebServerTest, CycleNumbersEqualGrpcGetCycle) {
  Start(kToken);
  const std::string cookie = Login(kToken);
  std::vector<int64_t> ids;
  for (int i = 0; i < 3; ++i) {
    ids.push_back(StartCycleOverGrpc(kToken));
    core_->WaitIdle();
  }
  for (const int64_t id : ids) {
    const v1::Cycle g = GetCycleOverGrpc(id, kToken);
    const auto [status, c] = GetJson("/api/cycles/" + std::to_string(id), cookie);
    ASSERT_EQ(status, 200) << c;
    ASSERT_NO_FATAL_FAILURE(ExpectCycleEqualsGrpc(c, g));
  }

  // Pages of the list, newest first, as gRPC ListCycles pages them.
  const auto [first_status, first] = GetJson("/api/cycles?limit=2", cookie);
  ASSERT_EQ(first_status, 200) << first;
  ASSERT_EQ(first["cycles"].size(), 2u);
  EXPECT_EQ(first["cycles"][0]["cycle_id"], std::to_string(ids[2]));
  EXPECT_EQ(first["cycles"][1]["cycle_id"], std::to_string(ids[1]));
  EXPECT_FALSE(first["cycles"][0].contains("sensors"));
  EXPECT_EQ(first["next_before"], std::to_string(ids[1]));
  const auto [second_status, second] =
      GetJson("/api/cycles?limit=2&before=" + std::to_string(ids[1]), cookie);
  ASSERT_EQ(second_status, 200) << second;
  ASSERT_EQ(second["cycles"].size(), 1u);
  EXPECT_EQ(second["cycles"][0]["cycle_id"], std::to_string(ids[0]));
  EXPECT_EQ(second["next_before"], "");
  grpc::ClientContext list_context;
  list_context.AddMetadata("authorization", std::string("Bearer ") + kToken);
  v1::ListCyclesRequest list;
  v1::ListCyclesResponse listed;
  ASSERT_TRUE(stub_->ListCycles(&list_context, list, &listed).ok());
  const auto [all_status, all] = GetJson("/api/cycles", cookie);
  ASSERT_EQ(all["cycles"].size(), static_cast<size_t>(listed.cycles_size()));
  for (int i = 0; i < listed.cycles_size(); ++i)
    EXPECT_EQ(all["cycles"][i]["cycle_id"], listed.cycles(i).cycle_id());

  // Refusals name the parameter, with the HTTP status of the core's code.
  const std::pair<std::string, std::pair<int, std::string>> bad[] = {
      {"/api/cycles?limit=0", {400, "limit = '0': must be in [1, 1000]"}},
      {"/api/cycles?limit=1001", {400, "limit = '1001'"}},
      {"/api/cycles?before=abc", {400, "before: cycle_id: 'abc' is not a cycle id"}},
      {"/api/cycles?before=999", {404, ""}},
      {"/api/cycles?verdict=maybe", {400, "verdict = 'maybe': must be pass, fail or error"}},
      {"/api/cycles/abc", {400, "cycle_id: 'abc' is not a cycle id"}},
      {"/api/cycles/999", {404, ""}},
      {"/api/cars/truck", {404, "car_model_id: 'truck' is not a car model"}},
  };
  for (const auto& [path, expected] : bad) {
    const auto [code, error] = GetJson(path, cookie);
    EXPECT_EQ(code, expected.first) << path;
    EXPECT_EQ(error["error"].get<std::string>().rfind(expected.second, 0), 0u)
        << path << ": " << error;
  }

  // The car model's nominal mounting is what the deviation is measured from, and its
  // tolerance the car file's.
  const auto [car_status, car] = GetJson("/api/cars/reference", cookie);
  ASSERT_EQ(car_status, 200);
  const v1::Cycle g = GetCycleOverGrpc(ids[0], kToken);
  ASSERT_EQ(car["sensors"].size(), 2u);
  const json camera = car["sensors"][0];
  EXPECT_EQ(camera["name"], "front_camera");
  EXPECT_EQ(camera["tolerance"]["yaw_deg"].get<double>(), 1.0);
  EXPECT_EQ(camera["tolerance"]["x_m"].get<double>(), 0.03);
  // 1e-9: the angles are computed twice from the same rotation, to rounding.
  EXPECT_NEAR(camera["nominal"]["pitch_deg"].get<double>(), 1.5, 1e-9);
  EXPECT_NEAR(camera["nominal"]["pitch_deg"].get<double>(),
              g.sensors(0).mounting().pitch_deg() - g.sensors(0).deviation().pitch_deg(), 1e-9);
  EXPECT_NEAR(camera["nominal"]["x_m"].get<double>(),
              g.sensors(0).mounting().x_m() - g.sensors(0).deviation().x_m(), 1e-12);
}

TEST_F(WebServerTest, EventStreamsDeliverACycleInOrder) {
  Start(kToken);
  const std::string cookie = Login(kToken);
  // The station stream, open before any cycle: it must show each new cycle from its first
  // event, in order, as the events are stored.
  std::mutex mutex;
  std::string text;
  std::vector<std::pair<size_t, std::chrono::system_clock::time_point>>
      arrivals;  // text size, time
  std::atomic<bool> stop{false};
  int ended = 0;
  std::thread follower([&] {
    httplib::Client client = Client();
    client.set_read_timeout(std::chrono::seconds(30));
    client.Get("/api/events", httplib::Headers{{"Cookie", cookie}},
               [&](const char* data, size_t size) {
                 std::lock_guard<std::mutex> lock(mutex);
                 text.append(data, size);
                 arrivals.emplace_back(text.size(), std::chrono::system_clock::now());
                 ended = 0;
                 for (const SseMessage& m : ParseSse(text))
                   ended += m.data.value("type", "") == "cycle_ended";
                 return !stop && ended < 2;
               });
  });
  // Two cycles one after the other, the first started when the stream is surely open.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const int64_t first = StartCycleOverGrpc(kToken);
  core_->WaitIdle();
  const int64_t second = StartCycleOverGrpc(kToken);
  core_->WaitIdle();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (std::chrono::steady_clock::now() < deadline) {
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (ended >= 2) break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  stop = true;
  follower.join();

  const std::vector<SseMessage> messages = ParseSse(text);
  size_t next = 0;
  std::chrono::nanoseconds worst{0};
  for (const int64_t id : {first, second}) {
    SCOPED_TRACE(id);
    absl::StatusOr<std::vector<StoredEvent>> stored = core_->store().Events(id);
    ASSERT_TRUE(stored.ok());
    ASSERT_LT(next, messages.size());
    EXPECT_EQ(messages[next].event, "cycle");
    EXPECT_EQ(messages[next].data["cycle_id"], std::to_string(id));
    EXPECT_EQ(messages[next].data["vin"], kVin);
    EXPECT_EQ(messages[next].data["car_model_id"], "reference");
    ++next;
    ASSERT_GE(stored->size(), 4u);
    for (const StoredEvent& e : *stored) {
      ASSERT_LT(next, messages.size());
      const SseMessage& m = messages[next++];
      EXPECT_EQ(m.event, "cycle_event");
      EXPECT_EQ(m.id, std::to_string(id) + "." + std::to_string(e.sequence));
      EXPECT_EQ(m.data, EventJson(e));
    }
    EXPECT_EQ(stored->back().type, EventType::kCycleEnded);
  }
  EXPECT_EQ(next, messages.size());
  // Each event's delay from its stored time to its arrival here.
  size_t offset = 0;
  for (absl::string_view block : absl::StrSplit(text, "\n\n")) {
    offset += block.size() + 2;
    if (!absl::StrContains(block, "event: cycle_event")) continue;
    const SseMessage m = ParseSse(std::string(block) + "\n\n").front();
    const auto arrival = std::find_if(arrivals.begin(), arrivals.end(),
                                      [&](const auto& a) { return a.first >= offset - 2; });
    ASSERT_NE(arrival, arrivals.end());
    const std::chrono::nanoseconds delay =
        arrival->second.time_since_epoch() -
        std::chrono::nanoseconds(m.data["time_ns"].get<int64_t>());
    worst = std::max(worst, delay);
  }
  std::printf("worst event delay (stored -> received over SSE): %.1f ms over %zu messages\n",
              std::chrono::duration<double, std::milli>(worst).count(), messages.size());
  EXPECT_LT(worst, kEventDelayBar);

  // One cycle's stream: its events from the first, then `end`; an unknown cycle is 404.
  httplib::Result one = Client().Get(("/api/events?cycle=" + std::to_string(first)).c_str(),
                                     httplib::Headers{{"Cookie", cookie}});
  ASSERT_TRUE(one);
  EXPECT_EQ(one->status, 200);
  EXPECT_EQ(one->get_header_value("Content-Type"), "text/event-stream");
  const std::vector<SseMessage> single = ParseSse(one->body);
  absl::StatusOr<std::vector<StoredEvent>> stored = core_->store().Events(first);
  ASSERT_TRUE(stored.ok());
  ASSERT_EQ(single.size(), stored->size() + 1);
  for (size_t i = 0; i < stored->size(); ++i)
    EXPECT_EQ(single[i].data, EventJson((*stored)[i])) << i;
  EXPECT_EQ(single.back().event, "end");
  EXPECT_EQ(GetJson("/api/events?cycle=999", cookie).first, 404);
  EXPECT_EQ(GetJson("/api/events").first, 401);
}

TEST_F(WebServerTest, StaticFilesWithTheirTypes) {
  Start(kToken);
  const std::string cookie = Login(kToken);
  const std::pair<std::string, std::string> files[] = {
      {"/", "text/html; charset=utf-8"},
      {"/index.html", "text/html; charset=utf-8"},
      {"/cycle.html", "text/html; charset=utf-8"},
      {"/login.html", "text/html; charset=utf-8"},
      {"/app.js", "text/javascript; charset=utf-8"},
      {"/cycles.html", "text/html; charset=utf-8"},
      {"/cycles.js", "text/javascript; charset=utf-8"},
      {"/app.css", "text/css; charset=utf-8"},
  };
  for (const auto& [path, type] : files) {
    httplib::Result r = Client().Get(path.c_str(), httplib::Headers{{"Cookie", cookie}});
    ASSERT_TRUE(r) << path;
    EXPECT_EQ(r->status, 200) << path;
    EXPECT_EQ(r->get_header_value("Content-Type"), type) << path;
    const std::string file = path == "/" ? "index.html" : path.substr(1);
    EXPECT_EQ(r->body, *ReadTextFile(kStatic + "/" + file)) << path;
    EXPECT_EQ(r->get_header_value("X-Content-Type-Options"), "nosniff") << path;
  }
  // Debian's Chart.js, for the pages that draw charts.
  httplib::Result chart = Client().Get("/vendor/chart.js", httplib::Headers{{"Cookie", cookie}});
  ASSERT_TRUE(chart);
  EXPECT_EQ(chart->status, 200);
  EXPECT_EQ(chart->get_header_value("Content-Type"), "text/javascript; charset=utf-8");
  EXPECT_EQ(chart->body, *ReadTextFile(kChartJsPath));
  // Revalidated by its entity tag: the same tag answers 304 without a body, another one the file.
  const std::string tag = chart->get_header_value("ETag");
  EXPECT_EQ(chart->get_header_value("Cache-Control"), "no-cache");
  ASSERT_EQ(tag.size() > 2 ? tag.front() + std::string(1, tag.back()) : "", "\"\"") << tag;
  httplib::Result again = Client().Get(
      "/vendor/chart.js", httplib::Headers{{"Cookie", cookie}, {"If-None-Match", tag}});
  ASSERT_TRUE(again);
  EXPECT_EQ(again->status, 304);
  EXPECT_EQ(again->body, "");
  httplib::Result other =
      Client().Get("/app.js", httplib::Headers{{"Cookie", cookie}, {"If-None-Match", tag}});
  ASSERT_TRUE(other);
  EXPECT_EQ(other->status, 200);
  EXPECT_EQ(other->body, *ReadTextFile(kStatic + "/app.js"));
  EXPECT_NE(other->get_header_value("ETag"), tag);
  // Nothing outside the folder, nothing it does not hold.
  for (const std::string path :
       {"/../CMakeLists.txt", "/%2e%2e/CMakeLists.txt", "/nothing.html", "/static/app.js"}) {
    httplib::Result r = Client().Get(path.c_str(), httplib::Headers{{"Cookie", cookie}});
    ASSERT_TRUE(r) << path;
    EXPECT_EQ(r->status, 404) << path;
  }
}

TEST_F(WebServerTest, StartRefusesBadOptions) {
  testing_daemon::WriteTwoSensorCar((dir_ / "car.json").string());
  StationCoreConfig config;
  config.station_path = kDeploy + "/stations/reference.json";
  config.car_model_paths = {(dir_ / "car.json").string()};
  config.db_path = (dir_ / "station.db").string();
  config.data_root = (dir_ / "data").string();
  core_ = *StationCore::Create(config);
  absl::StatusOr<std::unique_ptr<WebServer>> bad_listen =
      WebServer::Start(core_.get(), {"8080", {}, kStatic, "", "t"});
  EXPECT_EQ(bad_listen.status().message(),
            "web.listen: '8080': must be HOST:PORT with a port in 0..65535");
  absl::StatusOr<std::unique_ptr<WebServer>> no_pages =
      WebServer::Start(core_.get(), {"127.0.0.1:0", {}, dir_.string(), "", "t"});
  EXPECT_EQ(no_pages.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(no_pages.status().message()).rfind("web.static_dir: '", 0), 0u)
      << no_pages.status();
  absl::StatusOr<std::unique_ptr<WebServer>> first =
      WebServer::Start(core_.get(), {"127.0.0.1:0", {}, kStatic, "", "t"});
  ASSERT_TRUE(first.ok()) << first.status();
  const std::string taken = "127.0.0.1:" + std::to_string((*first)->port());
  absl::StatusOr<std::unique_ptr<WebServer>> second =
      WebServer::Start(core_.get(), {taken, {}, kStatic, "", "t"});
  EXPECT_EQ(second.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(second.status().message(), "web.listen: cannot listen on '" + taken + "'");
}

// HTTPS with the test PKI: the server's certificate, the Secure cookie, and mutual TLS when
// web.tls has a client CA.
class WebTlsTest : public WebServerTest {
 protected:
  void SetUp() override {
    WebServerTest::SetUp();
    ASSERT_TRUE(testing_daemon::MakeTestPki(dir_, &pki_));
  }
  TlsConfig ServerTls(bool client_ca) const {
    TlsConfig tls;
    tls.cert_path = pki_.server_cert;
    tls.key_path = pki_.server_key;
    tls.cert_pem = *ReadTextFile(pki_.server_cert);
    tls.key_pem = *ReadTextFile(pki_.server_key);
    tls.require_client_cert = client_ca;
    if (client_ca) {
      tls.client_ca_path = pki_.ca_cert;
      tls.client_ca_pem = *ReadTextFile(pki_.ca_cert);
    }
    return tls;
  }
  // A client trusting the test CA, with a client certificate when `cert` is set.
  std::unique_ptr<httplib::SSLClient> Https(const std::string& cert = "",
                                            const std::string& key = "") const {
    auto client = cert.empty()
                      ? std::make_unique<httplib::SSLClient>("127.0.0.1", web_->port())
                      : std::make_unique<httplib::SSLClient>("127.0.0.1", web_->port(), cert, key);
    client->set_ca_cert_path(pki_.ca_cert.c_str());
    client->enable_server_certificate_verification(true);
    return client;
  }
  testing_daemon::TestPki pki_;
};

TEST_F(WebTlsTest, HttpsWithASecureCookie) {
  Start(kToken, ServerTls(false));
  std::unique_ptr<httplib::SSLClient> client = Https();
  httplib::Result login =
      client->Post("/api/login", json{{"token", kToken}}.dump(), "application/json");
  ASSERT_TRUE(login) << httplib::to_string(login.error());
  EXPECT_EQ(login->status, 200);
  const std::string set_cookie = login->get_header_value("Set-Cookie");
  EXPECT_NE(set_cookie.find("; HttpOnly; SameSite=Strict; Secure"), std::string::npos)
      << set_cookie;
  httplib::Result status = client->Get(
      "/api/status", httplib::Headers{{"Cookie", set_cookie.substr(0, set_cookie.find(';'))}});
  ASSERT_TRUE(status);
  EXPECT_EQ(status->status, 200);
  // Plain HTTP on the TLS port gets no answer.
  httplib::Result plain = Client().Get("/api/session");
  EXPECT_FALSE(plain && plain->status == 200);
}

TEST_F(WebTlsTest, MutualTlsNeedsAClientCertificateOfTheCa) {
  Start("", ServerTls(true));
  httplib::Result with = Https(pki_.client_cert, pki_.client_key)->Get("/api/status");
  ASSERT_TRUE(with) << httplib::to_string(with.error());
  EXPECT_EQ(with->status, 200);
  EXPECT_FALSE(Https()->Get("/api/status"));
  EXPECT_FALSE(Https(pki_.other_client_cert, pki_.other_client_key)->Get("/api/status"));
}

TEST_F(WebTlsTest, KeyOfAnotherCertificateIsRefused) {
  testing_daemon::WriteTwoSensorCar((dir_ / "car.json").string());
  StationCoreConfig config;
  config.station_path = kDeploy + "/stations/reference.json";
  config.car_model_paths = {(dir_ / "car.json").string()};
  config.db_path = (dir_ / "station.db").string();
  config.data_root = (dir_ / "data").string();
  core_ = *StationCore::Create(config);
  TlsConfig tls = ServerTls(false);
  tls.key_pem = *ReadTextFile(pki_.client_key);
  tls.key_path = pki_.client_key;
  absl::StatusOr<std::unique_ptr<WebServer>> web =
      WebServer::Start(core_.get(), {"127.0.0.1:0", tls, kStatic, "", "t"});
  EXPECT_EQ(web.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(web.status().message(),
            "web.tls.key: '" + pki_.client_key + "': does not match web.tls.cert");
}

}  // namespace
}  // namespace linecal

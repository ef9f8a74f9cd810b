#pragma once
// The station console's HTTP server inside linecald (docs/console.md): static pages, a JSON
// API mirroring the gRPC read calls and Server-Sent Events of cycles, over the station core.
// cpp-httplib (Debian's libcpp-httplib-dev) parses HTTP and TLS; this file only routes.
//
// Routes (docs/console.md, "API"):
//   POST /api/login   {"token": "..."}: 200 and a session cookie (HttpOnly, SameSite=Strict,
//                     Secure under TLS) when it is the daemon's auth_token (a read-only
//                     session) or the operator token (an operator session); 401 JSON else;
//                     409 when the daemon has neither (nothing to log in to)
//   POST /api/logout  ends the cookie's session
//   GET  /api/session {login_required, logged_in, operator_login, role}: whether the pages
//                     need a login, and the session's role (sessions.h)
//   GET  /api/status  the station (console_json.h StatusJson), as gRPC GetStationStatus
//   GET  /api/cycles?limit=N&before=ID&vin=V&verdict=W
//                     {cycles: [...], next_before: "ID" or ""} newest first, as ListCycles:
//                     limit 1..1000 (default 50), the cycles listed after cycle ID
//   GET  /api/cycles/ID  one cycle with its sensors, as GetCycle
//   GET  /api/cars/ID    a car model's nominal mountings and tolerances (CarModelJson)
//   GET  /api/events  text/event-stream: the newest cycle's events from its first, then
//                     every new cycle's as they happen (an `event: cycle` with the cycle
//                     before its `event: cycle_event`s); ?cycle=ID: that cycle's events
//                     only, then `event: end`. The events are StationCore::WatchCycle's.
//   GET  /api/aftersale/cameras, POST /api/aftersale/photo, POST /api/aftersale,
//   GET  /api/aftersale/photos/ID/birdseye.png
//                     the after-sale page's calls (aftersale_api.h, aftersale_photos.h: the
//                     bird's-eye PNG of a kept photo through its latest solve); a photo over
//                     kMaxPhotoBytes or a request over kMaxAftersaleRequestBytes gets 413,
//                     a multipart form 415
//   GET  /api/cycles/ID/capture        the kept capture's files (capture_views.h), or why none
//   GET  /api/cycles/ID/capture/N      file N of that list (a download; a camera's frame)
//   GET  /api/cycles/ID/capture.tar    the whole capture as one tar archive (capture_archive.h);
//                                      404 when the cycle kept no capture
//   GET  /api/cycles/ID/views/SENSOR?frame=K  the sensor's view (station/pipeline/cycle_views.h)
//   POST /api/cycles            operators: start a cycle (operator_actions.h's body), as
//                               gRPC StartCycle; {"cycle_id": "N"}
//   POST /api/cycles/ID/cancel  operators: cancel it, as gRPC CancelCycle
//                     Both POSTs need an operator session (403 JSON for a read-only one) and
//                     pass CheckSameSiteAction (403 else).
//   GET  /, /NAME.html, /NAME.js, /NAME.css  files of the static folder; /vendor/chart.js
//                     Debian's Chart.js; /favicon.ico 204 (no icon).
// Every /api/ call but login and session needs a live session when the daemon has an
// auth_token: 401 JSON without one; a page without one is redirected (303) to
// /login.html?next=PATH. Errors are JSON {"error": message, "code": word} with the HTTP
// status of the core's absl code (400 invalid argument, 404 not found, 409 failed
// precondition, 503 unavailable, 500 else).

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "absl/status/statusor.h"
#include "daemon/core/daemon_config.h"
#include "daemon/core/station_core.h"
#include "daemon/web/aftersale_photos.h"
#include "daemon/web/capture_views.h"
#include "daemon/web/sessions.h"

namespace httplib {
class Server;
class Request;
class Response;
class DataSink;
}  // namespace httplib

namespace linecal {

// Debian's Chart.js (libjs-chart.js), served at /vendor/chart.js.
inline constexpr char kChartJsPath[] = "/usr/share/javascript/chart.js/chart.min.js";
// Server-Sent Event streams open at once; one more gets 503. Each holds one of the server's
// kWebThreads threads for as long as it is open, and 8 threads stay for the API calls.
inline constexpr int kWebThreads = 32;
inline constexpr int kMaxEventStreams = kWebThreads - 8;
// How often a following event stream looks for a new cycle: a cycle's first event reaches
// the page within this (then WatchCycle's own wake-up) of being stored.
inline constexpr std::chrono::milliseconds kNewCyclePoll{100};
// A comment line on an idle event stream this often, so that a closed page is noticed and
// proxies do not drop the connection.
inline constexpr std::chrono::seconds kEventKeepAlive{15};

// The pages' folder: `configured` when not empty; else the installed one,
// <folder of /proc/self/exe>/../share/linecal/web, when it holds index.html; else
// `source_dir` (linecald run from the build tree). Cost: a few stat calls.
std::string FindStaticDir(const std::string& configured, const std::string& source_dir);

struct WebServerOptions {
  std::string listen;            // HOST:PORT ("[::1]:8080" too); port 0 picks a free one
  std::optional<TlsConfig> tls;  // absent: plain HTTP
  std::string static_dir;        // the pages (FindStaticDir)
  std::string auth_token;        // the daemon's; empty: no login
  std::string version;           // /api/status's version
  std::string chart_js_path = kChartJsPath;
  std::string operator_token = "";  // web.operator_token; empty: no operator sessions
};

class WebServer {
 public:
  // Binds and starts serving on its own threads. InvalidArgument naming web.listen for a
  // malformed address, web.static_dir when the folder has no index.html, web.tls.* when the
  // PEM text does not load or the key does not match the certificate; Unavailable when the
  // address cannot be bound. `core` must outlive the server.
  static absl::StatusOr<std::unique_ptr<WebServer>> Start(StationCore* core,
                                                          WebServerOptions options);
  // Stops listening and waits for the requests in flight; an event stream ends at its next
  // event or poll (kNewCyclePoll), so stop a running cycle first for a quick stop.
  ~WebServer();
  WebServer(const WebServer&) = delete;
  WebServer& operator=(const WebServer&) = delete;

  int port() const { return port_; }

 private:
  WebServer(StationCore* core, WebServerOptions options);
  void Route();
  // The request's session is live (or none is needed).
  bool Authorized(const httplib::Request& req);
  void ServeFile(const std::string& path, const httplib::Request& req, httplib::Response& res);
  void ListCycles(const httplib::Request& req, httplib::Response& res);
  void Events(const httplib::Request& req, httplib::Response& res);
  // Writes events to `sink` until the stream ends or the client goes away.
  void FollowStation(httplib::DataSink& sink);
  void FollowCycle(int64_t cycle_id, httplib::DataSink& sink);
  // The routes of the cycle page's recorded data and of the operator's actions.
  void RouteCycleViews();
  // Streams the archive of a cycle's capture (capture_archive.h) as a download.
  static void SendArchive(CaptureArchiveToSend archive, httplib::Response& res);
  void RouteOperator();
  // The after-sale page's calls (aftersale_api.h) over the kept photos.
  void RouteAftersale();
  // Whether the request may change the station: an operator session and CheckSameSiteAction;
  // else answers 403 and returns false.
  bool OperatorAllowed(const httplib::Request& req, httplib::Response& res);

  StationCore* core_;
  const WebServerOptions options_;
  Sessions sessions_;
  CaptureViews views_;
  AftersalePhotos photos_;
  std::unique_ptr<httplib::Server> server_;
  std::thread thread_;
  int port_ = 0;
  std::atomic<bool> stopping_{false};
  std::atomic<int> streams_{0};
};

}  // namespace linecal

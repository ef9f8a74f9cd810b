#include "daemon/web/web_server.h"

#include <httplib.h>
#include <openssl/pem.h>
#include <openssl/ssl.h>
#include <sys/socket.h>
#include <sys/stat.h>

#include <cctype>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <sstream>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "daemon/web/aftersale_api.h"
#include "daemon/web/console_json.h"
#include "daemon/web/operator_actions.h"
#include "daemon/web/trends_json.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

constexpr char kCookie[] = "linecal_session";
constexpr char kJson[] = "application/json";

// The HTTP status of a core error (docs/console.md, "API").
int HttpStatus(absl::StatusCode code) {
  switch (code) {
    case absl::StatusCode::kInvalidArgument:
      return 400;
    case absl::StatusCode::kUnauthenticated:
      return 401;
    case absl::StatusCode::kPermissionDenied:
      return 401;
    case absl::StatusCode::kNotFound:
      return 404;
    case absl::StatusCode::kFailedPrecondition:
      return 409;
    case absl::StatusCode::kUnavailable:
      return 503;
    case absl::StatusCode::kResourceExhausted:
      return 503;
    default:
      return 500;
  }
}

void SendJson(httplib::Response& res, const nlohmann::json& body, int status = 200) {
  res.status = status;
  res.set_header("Cache-Control", "no-store");
  // dump's error handler `replace`: a VIN or a reason with invalid UTF-8 (they are request
  // data) must not throw.
  res.set_content(body.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace), kJson);
}

// `status` 0: the HTTP status of the error's code (HttpStatus).
void SendError(httplib::Response& res, const absl::Status& s, int status = 0) {
  std::string code = absl::StatusCodeToString(s.code());
  for (char& c : code) c = c == ' ' ? '_' : static_cast<char>(std::tolower(c));
  SendJson(res, {{"error", std::string(s.message())}, {"code", code}},
           status != 0 ? status : HttpStatus(s.code()));
}

// The request's body through `read`, at most `max_bytes` of it kept: false when it is longer
// (the rest is read and dropped, so that the client, still sending, gets the answer) or is a
// multipart form (not taken: its parts are dropped the same way).
bool ReadBoundedBody(const httplib::Request& req, const httplib::ContentReader& read,
                     std::int64_t max_bytes, std::string* body) {
  bool fits = !req.is_multipart_form_data();
  const auto keep = [&](const char* data, size_t n) {
    if (fits && static_cast<std::int64_t>(body->size() + n) <= max_bytes) {
      body->append(data, n);
    } else {
      fits = false;
      body->clear();
    }
    return true;
  };
  if (req.is_multipart_form_data()) {
    read([](const httplib::MultipartFormData&) { return true; }, keep);
  } else {
    read(keep);
  }
  return fits;
}

// The after-sale page's POSTs (aftersale_api.h): the body under `max_bytes`, then `answer`.
void ServeBoundedPost(
    const httplib::Request& req, httplib::Response& res, const httplib::ContentReader& read,
    std::int64_t max_bytes, const std::string& what,
    const std::function<absl::StatusOr<nlohmann::json>(std::string_view)>& answer) {
  std::string body;
  if (!ReadBoundedBody(req, read, max_bytes, &body)) {
    if (req.is_multipart_form_data()) {
      return SendError(res,
                       absl::InvalidArgumentError(
                           absl::StrCat(what, ": send the file's bytes as the body, not a form")),
                       415);
    }
    return SendError(
        res,
        absl::ResourceExhaustedError(absl::StrCat(what, ": larger than ", max_bytes, " bytes")),
        413);
  }
  absl::StatusOr<nlohmann::json> j = answer(body);
  if (!j.ok()) return SendError(res, j.status());
  SendJson(res, *j);
}

const char* ContentType(const std::string& extension) {
  if (extension == ".html") return "text/html; charset=utf-8";
  if (extension == ".js") return "text/javascript; charset=utf-8";
  if (extension == ".css") return "text/css; charset=utf-8";
  return "application/octet-stream";
}

// cpp-httplib 0.11 compresses every text, JavaScript and JSON answer with Brotli at its
// slowest quality (11) when the browser accepts "br", as Chromium always does: measured 0.9 s
// for Chart.js and 1.8 s for a list of 1,000 cycles, against 50 ms and 20 ms with its gzip
// (level 6). The library has no setting for it, so "br" is taken out of the request's
// Accept-Encoding before routing; the Request object httplib passes is its own non-const
// local, so the const_cast is defined.
void RefuseBrotli(const httplib::Request& req) {
  auto& headers = const_cast<httplib::Headers&>(req.headers);
  auto accepted = headers.find("Accept-Encoding");
  if (accepted == headers.end()) return;
  std::vector<std::string> kept;
  for (absl::string_view e : absl::StrSplit(accepted->second, ',')) {
    e = absl::StripAsciiWhitespace(e);
    if (!e.empty() && !absl::StartsWith(e, "br")) kept.emplace_back(e);
  }
  accepted->second = absl::StrJoin(kept, ", ");
}

// A static file's entity tag: its size and modification time, "" when it cannot be read.
// Cost: one stat.
std::string FileTag(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return "";
  return absl::StrCat("\"", absl::Hex(st.st_size), "-", absl::Hex(st.st_mtim.tv_sec), "-",
                      absl::Hex(st.st_mtim.tv_nsec), "\"");
}

// The value of cookie `name` in a Cookie header ("a=1; linecal_session=abc"), or "".
std::string CookieValue(const std::string& header, const std::string& name) {
  for (absl::string_view part : absl::StrSplit(header, ';')) {
    part = absl::StripAsciiWhitespace(part);
    if (absl::ConsumePrefix(&part, name) && absl::ConsumePrefix(&part, "="))
      return std::string(part);
  }
  return "";
}

// `text` with every byte but RFC 3986's unreserved ones as %XX: a query parameter's value.
std::string PercentEncoded(const std::string& text) {
  std::string out;
  for (const unsigned char c : text) {
    if (std::isalnum(c) || c == '-' || c == '.' || c == '_' || c == '~') {
      out += static_cast<char>(c);
    } else {
      absl::StrAppend(&out, "%", absl::Hex(c, absl::kZeroPad2));
    }
  }
  return out;
}

std::string SseMessage(const std::string& event, const nlohmann::json& data,
                       const std::string& id = "") {
  std::string m = id.empty() ? "" : absl::StrCat("id: ", id, "\n");
  // One line of JSON: dump without indentation never holds a newline.
  absl::StrAppend(&m, "event: ", event,
                  "\ndata: ", data.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace),
                  "\n\n");
  return m;
}

// A PEM text's certificates in order; empty when it holds none.
std::vector<X509*> ReadCertificates(const std::string& pem) {
  std::vector<X509*> certs;
  BIO* bio = BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size()));
  if (bio == nullptr) return certs;
  while (X509* cert = PEM_read_bio_X509(bio, nullptr, nullptr, nullptr)) certs.push_back(cert);
  BIO_free(bio);
  return certs;
}

// Loads the `web.tls` files into httplib's SSL context: the certificate chain and key, and
// the clients' CA with verification as the gRPC port does it (daemon_config.h TlsConfig).
// Returns "" or what is wrong, naming the key.
std::string SetUpTls(const TlsConfig& tls, SSL_CTX& ctx) {
  std::vector<X509*> chain = ReadCertificates(tls.cert_pem);
  if (chain.empty()) return absl::StrCat("web.tls.cert: '", tls.cert_path, "': no PEM certificate");
  const bool used = SSL_CTX_use_certificate(&ctx, chain[0]) == 1;
  X509_free(chain[0]);
  bool chained = true;
  // SSL_CTX_add_extra_chain_cert takes ownership of the intermediates it accepts.
  for (size_t i = 1; i < chain.size(); ++i) {
    if (SSL_CTX_add_extra_chain_cert(&ctx, chain[i]) != 1) {
      X509_free(chain[i]);
      chained = false;
    }
  }
  if (!used || !chained) return absl::StrCat("web.tls.cert: '", tls.cert_path, "': not usable");
  BIO* bio = BIO_new_mem_buf(tls.key_pem.data(), static_cast<int>(tls.key_pem.size()));
  EVP_PKEY* key = bio ? PEM_read_bio_PrivateKey(bio, nullptr, nullptr, nullptr) : nullptr;
  BIO_free(bio);
  if (key == nullptr) return absl::StrCat("web.tls.key: '", tls.key_path, "': no PEM private key");
  // OpenSSL refuses a key of another certificate already here (for EC and RSA keys).
  const bool key_used = SSL_CTX_use_PrivateKey(&ctx, key) == 1;
  EVP_PKEY_free(key);
  if (!key_used || SSL_CTX_check_private_key(&ctx) != 1) {
    return absl::StrCat("web.tls.key: '", tls.key_path, "': does not match web.tls.cert");
  }
  if (tls.client_ca_pem.empty()) return "";
  std::vector<X509*> cas = ReadCertificates(tls.client_ca_pem);
  if (cas.empty())
    return absl::StrCat("web.tls.client_ca: '", tls.client_ca_path, "': no PEM certificate");
  X509_STORE* store = SSL_CTX_get_cert_store(&ctx);
  for (X509* ca : cas) {
    X509_STORE_add_cert(store, ca);
    SSL_CTX_add_client_CA(&ctx, ca);
    X509_free(ca);
  }
  SSL_CTX_set_verify(
      &ctx, SSL_VERIFY_PEER | (tls.require_client_cert ? SSL_VERIFY_FAIL_IF_NO_PEER_CERT : 0),
      nullptr);
  return "";
}

}  // namespace

std::string FindStaticDir(const std::string& configured, const std::string& source_dir) {
  if (!configured.empty()) return configured;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const fs::path installed =
        (exe.parent_path() / ".." / "share" / "linecal" / "web").lexically_normal();
    if (fs::is_regular_file(installed / "index.html", ec)) return installed.string();
  }
  return source_dir;
}

WebServer::WebServer(StationCore* core, WebServerOptions options)
    : core_(core),
      options_(std::move(options)),
      sessions_(options_.auth_token, options_.operator_token),
      views_(core) {}

absl::StatusOr<std::unique_ptr<WebServer>> WebServer::Start(StationCore* core,
                                                            WebServerOptions options) {
  if (absl::Status s = CheckListenAddress(options.listen, "web.listen"); !s.ok()) return s;
  std::error_code ec;
  if (!fs::is_regular_file(fs::path(options.static_dir) / "index.html", ec)) {
    return absl::InvalidArgumentError(absl::StrCat("web.static_dir: '", options.static_dir,
                                                   "': no index.html (the console's pages)"));
  }
  std::unique_ptr<WebServer> web(new WebServer(core, std::move(options)));
  if (web->options_.tls) {
    std::string problem;
    auto server = std::make_unique<httplib::SSLServer>(
        [&](SSL_CTX& ctx) { return (problem = SetUpTls(*web->options_.tls, ctx)).empty(); });
    if (!server->is_valid()) {
      return absl::InvalidArgumentError(problem.empty() ? "web.tls: OpenSSL refused the context"
                                                        : problem);
    }
    web->server_ = std::move(server);
  } else {
    web->server_ = std::make_unique<httplib::Server>();
  }
  web->server_->new_task_queue = [] { return new httplib::ThreadPool(kWebThreads); };
  // httplib's default sets SO_REUSEPORT: a second linecald would bind the same port and the
  // kernel would split the browsers between the two. SO_REUSEADDR alone lets a restarted
  // daemon bind while the old connections linger in TIME_WAIT.
  web->server_->set_socket_options([](int socket) {
    const int yes = 1;
    setsockopt(socket, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  });
  web->Route();
  const std::string& listen = web->options_.listen;
  std::string host = listen.substr(0, listen.rfind(':'));
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']')
    host = host.substr(1, host.size() - 2);
  int port = 0;
  // CheckListenAddress held: the port is digits in 0..65535.
  (void)absl::SimpleAtoi(listen.substr(listen.rfind(':') + 1), &port);
  web->port_ = port == 0                                ? web->server_->bind_to_any_port(host)
               : web->server_->bind_to_port(host, port) ? port
                                                        : -1;
  if (web->port_ <= 0)
    return absl::UnavailableError(absl::StrCat("web.listen: cannot listen on '", listen, "'"));
  web->thread_ = std::thread([server = web->server_.get()] { server->listen_after_bind(); });
  // httplib's stop() does nothing until the loop runs, and the loop would then run forever:
  // a server destroyed right after Start would hang in the destructor. The loop starts at
  // once; 5 s is beyond any scheduling delay.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (!web->server_->is_running() && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  if (!web->server_->is_running()) {
    return absl::InternalError(
        absl::StrCat("web.listen: the server on '", listen, "' did not start"));
  }
  return web;
}

WebServer::~WebServer() {
  stopping_ = true;
  if (server_) server_->stop();
  if (thread_.joinable()) thread_.join();
}

bool WebServer::Authorized(const httplib::Request& req) {
  return sessions_.Check(CookieValue(req.get_header_value("Cookie"), kCookie));
}

void WebServer::Route() {
  httplib::Server& s = *server_;
  // Every answer: no sniffing of types, no framing by other sites, scripts only from here.
  s.set_default_headers(
      {{"X-Content-Type-Options", "nosniff"},
       {"X-Frame-Options", "DENY"},
       {"Content-Security-Policy", "default-src 'self'; frame-ancestors 'none'"}});
  s.Post("/api/login", [this](const httplib::Request& req, httplib::Response& res) {
    const nlohmann::json body = nlohmann::json::parse(req.body, nullptr, false);
    if (!body.is_object() || !body.contains("token") || !body["token"].is_string()) {
      return SendError(
          res, absl::InvalidArgumentError("token: a JSON body {\"token\": \"...\"} is required"));
    }
    absl::StatusOr<std::string> id = sessions_.Login(body["token"].get<std::string>());
    if (!id.ok()) return SendError(res, id.status());
    res.set_header("Set-Cookie",
                   absl::StrCat(kCookie, "=", *id, "; Path=/; HttpOnly; SameSite=Strict",
                                options_.tls ? "; Secure" : ""));
    SendJson(res, {{"role", RoleName(sessions_.RoleOf(*id))}});
  });
  s.Post("/api/logout", [this](const httplib::Request& req, httplib::Response& res) {
    sessions_.Logout(CookieValue(req.get_header_value("Cookie"), kCookie));
    res.set_header("Set-Cookie",
                   absl::StrCat(kCookie, "=; Path=/; HttpOnly; SameSite=Strict; Max-Age=0"));
    SendJson(res, nlohmann::json::object());
  });
  s.Get("/api/session", [this](const httplib::Request& req, httplib::Response& res) {
    SendJson(res,
             {{"login_required", sessions_.login_required()},
              {"operator_login", !options_.operator_token.empty()},
              {"logged_in", Authorized(req)},
              {"role",
               RoleName(sessions_.RoleOf(CookieValue(req.get_header_value("Cookie"), kCookie)))}});
  });
  // The API below needs a session: checked before routing.
  s.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
    RefuseBrotli(req);
    const bool open =
        req.path == "/api/login" || req.path == "/api/logout" || req.path == "/api/session";
    if (open || Authorized(req)) return httplib::Server::HandlerResponse::Unhandled;
    if (req.path.rfind("/api/", 0) == 0) {
      SendError(res, absl::UnauthenticatedError(
                         "login required: POST /api/login with the daemon's auth_token"));
      return httplib::Server::HandlerResponse::Handled;
    }
    const bool page = req.path == "/" || (req.path.size() > 5 && req.path.ends_with(".html") &&
                                          req.path != "/login.html");
    if (!page) return httplib::Server::HandlerResponse::Unhandled;
    res.set_redirect(absl::StrCat("/login.html?next=", PercentEncoded(req.target)), 303);
    return httplib::Server::HandlerResponse::Handled;
  });
  s.Get("/api/status", [this](const httplib::Request&, httplib::Response& res) {
    SendJson(res, StatusJson(core_->Status(), options_.version));
  });
  s.Get("/api/cycles",
        [this](const httplib::Request& req, httplib::Response& res) { ListCycles(req, res); });
  s.Get(R"(/api/cycles/([^/]+))", [this](const httplib::Request& req, httplib::Response& res) {
    absl::StatusOr<int64_t> id = ParseCycleId(req.matches[1]);
    if (!id.ok()) return SendError(res, id.status());
    absl::StatusOr<StoredCycle> cycle = core_->GetCycle(*id);
    if (!cycle.ok()) return SendError(res, cycle.status());
    SendJson(res, CycleJson(*cycle, true));
  });
  s.Get(R"(/api/cars/([^/]+))", [this](const httplib::Request& req, httplib::Response& res) {
    const std::string id = req.matches[1];
    for (const CarModel& car : core_->car_models()) {
      if (car.id == id) return SendJson(res, CarModelJson(car));
    }
    SendError(res, absl::NotFoundError(absl::StrCat("car_model_id: ", QuoteInput(id),
                                                    " is not a car model of the station")));
  });
  s.Get("/api/events",
        [this](const httplib::Request& req, httplib::Response& res) { Events(req, res); });
  // The after-sale page: computations over the request, nothing of the station changes.
  s.Get("/api/aftersale/cameras", [this](const httplib::Request&, httplib::Response& res) {
    SendJson(res, AftersaleCamerasJson(core_->car_models()));
  });
  RouteAftersale();
  RouteCycleViews();
  RouteOperator();
  // Trends and station health (docs/console.md): ?cycles=N (1..100000, default 200), &sensor=S.
  s.Get("/api/trends", [this](const httplib::Request& req, httplib::Response& res) {
    int cycles = kHealthWindowCycles;
    if (req.has_param("cycles")) {
      const std::string n = req.get_param_value("cycles");
      if (!absl::SimpleAtoi(n, &cycles) || cycles < 1 || cycles > 100000) {
        return SendError(res, absl::InvalidArgumentError(absl::StrCat("cycles = ", QuoteInput(n),
                                                                      ": must be in [1, 100000]")));
      }
    }
    absl::StatusOr<StationHealth> health = core_->Trends(cycles);
    if (!health.ok()) return SendError(res, health.status());
    SendJson(res, TrendsJson(*health, req.get_param_value("sensor")));
  });
  s.Get("/vendor/chart.js", [this](const httplib::Request& req, httplib::Response& res) {
    ServeFile(options_.chart_js_path, req, res);
  });
  // Browsers ask for it unprompted; no icon, and no 404 in the page's console.
  s.Get("/favicon.ico", [](const httplib::Request&, httplib::Response& res) { res.status = 204; });
  s.Get("/", [this](const httplib::Request& req, httplib::Response& res) {
    ServeFile((fs::path(options_.static_dir) / "index.html").string(), req, res);
  });
  // Files of the static folder by plain names only: no '/' and no "..", so nothing outside it.
  s.Get(R"(/([a-z0-9_-]+\.(html|js|css)))", [this](const httplib::Request& req,
                                                   httplib::Response& res) {
    ServeFile((fs::path(options_.static_dir) / std::string(req.matches[1])).string(), req, res);
  });
}

void WebServer::RouteAftersale() {
  httplib::Server& s = *server_;
  s.Post("/api/aftersale/photo", [this](const httplib::Request& req, httplib::Response& res,
                                        const httplib::ContentReader& read) {
    ServeBoundedPost(req, res, read, kMaxPhotoBytes, "photo",
                     [this](std::string_view body) { return AftersalePhotoJson(body, photos_); });
  });
  s.Post("/api/aftersale", [this](const httplib::Request& req, httplib::Response& res,
                                  const httplib::ContentReader& read) {
    ServeBoundedPost(req, res, read, kMaxAftersaleRequestBytes, "request",
                     [this](std::string_view body) { return AftersaleSolveJson(body, photos_); });
  });
  s.Get(R"(/api/aftersale/photos/([^/]+)/birdseye\.png)",
        [this](const httplib::Request& req, httplib::Response& res) {
          absl::StatusOr<std::string> png = photos_.BirdsEyePng(req.matches[1]);
          if (!png.ok()) return SendError(res, png.status());
          // The path names a solve (?solve=N), and a newer one gets a new path.
          res.set_header("Cache-Control", "no-store");
          res.set_content(*std::move(png), "image/png");
        });
}

void WebServer::ServeFile(const std::string& path, const httplib::Request& req,
                          httplib::Response& res) {
  std::ifstream in(path, std::ios::binary);
  const std::string tag = FileTag(path);
  if (!in || tag.empty()) {
    res.status = 404;
    res.set_content("not found\n", "text/plain; charset=utf-8");
    return;
  }
  // Pages change with the daemon (and Chart.js with its package): revalidated at every load,
  // which the tag answers with a 304 and no body, so a page's scripts come from the browser's
  // cache (and its compiled code cache) instead of being read, compressed and parsed again.
  res.set_header("Cache-Control", "no-cache");
  res.set_header("ETag", tag);
  if (req.get_header_value("If-None-Match") == tag) {
    res.status = 304;
    return;
  }
  std::ostringstream text;
  text << in.rdbuf();
  res.set_content(text.str(), ContentType(fs::path(path).extension().string()));
}

void WebServer::ListCycles(const httplib::Request& req, httplib::Response& res) {
  CycleFilter filter;
  if (req.has_param("limit")) {
    const std::string limit = req.get_param_value("limit");
    // 1000: the store's largest page, as gRPC's kMaxPageSize.
    if (!absl::SimpleAtoi(limit, &filter.page_size) || filter.page_size < 1 ||
        filter.page_size > 1000) {
      return SendError(res, absl::InvalidArgumentError(absl::StrCat("limit = ", QuoteInput(limit),
                                                                    ": must be in [1, 1000]")));
    }
  }
  filter.vin = req.get_param_value("vin");
  if (req.has_param("verdict")) {
    const std::string word = req.get_param_value("verdict");
    const std::optional<Verdict> v = ParseVerdict(word);
    if (!v) {
      return SendError(res, absl::InvalidArgumentError(absl::StrCat(
                                "verdict = ", QuoteInput(word), ": must be pass, fail or error")));
    }
    filter.verdict = v;
  }
  if (req.has_param("before")) {
    // The store pages by (start, id) of the last cycle listed: the cycle's own.
    absl::StatusOr<int64_t> id = ParseCycleId(req.get_param_value("before"));
    if (!id.ok())
      return SendError(res,
                       absl::InvalidArgumentError(absl::StrCat("before: ", id.status().message())));
    absl::StatusOr<StoredCycle> before = core_->GetCycle(*id);
    if (!before.ok()) return SendError(res, before.status());
    filter.page_token = absl::StrCat(before->started_ns, ".", before->id);
  }
  absl::StatusOr<CyclePage> page = core_->ListCycles(filter);
  if (!page.ok()) return SendError(res, page.status());
  nlohmann::json cycles = nlohmann::json::array();
  for (const StoredCycle& c : page->cycles) cycles.push_back(CycleJson(c, false));
  SendJson(res, {{"cycles", std::move(cycles)},
                 {"next_before",
                  page->next_page_token.empty() ? "" : std::to_string(page->cycles.back().id)}});
}

void WebServer::SendArchive(CaptureArchiveToSend archive, httplib::Response& res) {
  res.set_header("Cache-Control", "private, max-age=3600");
  res.set_header("Content-Disposition",
                 absl::StrCat("attachment; filename=\"", archive.download_name, "\""));
  // Written as it is sent (chunked: the size of a tar with pax headers is known only once
  // written). A file that fails to read mid-way cuts the download short, which the browser
  // reports as a failed download rather than saving a truncated archive as complete.
  auto members = std::make_shared<std::vector<ArchiveMember>>(std::move(archive.members));
  res.set_chunked_content_provider("application/x-tar", [members](size_t, httplib::DataSink& sink) {
    const absl::Status s = WriteTarArchive(*members, [&sink](std::string_view piece) {
      return sink.write(piece.data(), piece.size());
    });
    if (s.ok()) sink.done();
    return s.ok();
  });
}

void WebServer::Events(const httplib::Request& req, httplib::Response& res) {
  std::optional<int64_t> cycle;
  if (req.has_param("cycle")) {
    absl::StatusOr<int64_t> id = ParseCycleId(req.get_param_value("cycle"));
    if (!id.ok()) return SendError(res, id.status());
    if (absl::StatusOr<StoredCycle> c = core_->GetCycle(*id); !c.ok())
      return SendError(res, c.status());
    cycle = *id;
  }
  if (++streams_ > kMaxEventStreams) {
    --streams_;
    return SendError(res, absl::UnavailableError(absl::StrCat("events: ", kMaxEventStreams,
                                                              " streams are open already")));
  }
  res.set_header("Cache-Control", "no-store");
  res.set_chunked_content_provider(
      "text/event-stream",
      [this, cycle](size_t, httplib::DataSink& sink) {
        // The browser reconnects this long after a stream ends or breaks.
        const std::string retry = "retry: 1000\n\n";
        if (sink.write(retry.data(), retry.size())) {
          if (cycle) {
            FollowCycle(*cycle, sink);
          } else {
            FollowStation(sink);
          }
        }
        sink.done();
        return true;
      },
      [this](bool) { --streams_; });
}

void WebServer::FollowCycle(int64_t cycle_id, httplib::DataSink& sink) {
  const absl::Status s = core_->WatchCycle(cycle_id, [&](const StoredEvent& e) {
    const std::string m =
        SseMessage("cycle_event", EventJson(e), absl::StrCat(e.cycle_id, ".", e.sequence));
    return !stopping_ && sink.write(m.data(), m.size());
  });
  if (!s.ok()) return;  // the client went away, or the store failed: the page reconnects
  const std::string end = SseMessage("end", {{"cycle_id", std::to_string(cycle_id)}});
  sink.write(end.data(), end.size());
}

void WebServer::FollowStation(httplib::DataSink& sink) {
  // The newest cycle is shown from its first event, so a page opened mid-cycle or after it
  // sees the car in the station; then each newer cycle in id order.
  int64_t last = 0;
  bool first = true;
  auto idle_since = std::chrono::steady_clock::now();
  while (!stopping_) {
    CycleFilter filter;
    // 10 newest: more cycles than this between two polls (100 ms) cannot happen on a line,
    // and the page shows the newest anyway.
    filter.page_size = 10;
    absl::StatusOr<CyclePage> page = core_->ListCycles(filter);
    if (!page.ok()) return;
    std::optional<StoredCycle> next;
    for (const StoredCycle& c : page->cycles) {
      if (first ? !next || c.id > next->id : c.id > last && (!next || c.id < next->id)) next = c;
    }
    first = false;
    if (next) {
      last = next->id;
      const std::string m = SseMessage("cycle", CycleJson(*next, false));
      if (!sink.write(m.data(), m.size())) return;
      const absl::Status s = core_->WatchCycle(next->id, [&](const StoredEvent& e) {
        const std::string em =
            SseMessage("cycle_event", EventJson(e), absl::StrCat(e.cycle_id, ".", e.sequence));
        return !stopping_ && sink.write(em.data(), em.size());
      });
      if (!s.ok()) return;
      idle_since = std::chrono::steady_clock::now();
      continue;
    }
    if (std::chrono::steady_clock::now() - idle_since > kEventKeepAlive) {
      const std::string ping = ": keep-alive\n\n";
      if (!sink.write(ping.data(), ping.size())) return;
      idle_since = std::chrono::steady_clock::now();
    }
    std::this_thread::sleep_for(kNewCyclePoll);
  }
}

void WebServer::RouteCycleViews() {
  httplib::Server& s = *server_;
  s.Get(R"(/api/cycles/([^/]+)/capture)",
        [this](const httplib::Request& req, httplib::Response& res) {
          absl::StatusOr<int64_t> id = ParseCycleId(req.matches[1]);
          if (!id.ok()) return SendError(res, id.status());
          absl::StatusOr<nlohmann::json> files = views_.Files(*id);
          if (!files.ok()) return SendError(res, files.status());
          SendJson(res, *files);
        });
  s.Get(R"(/api/cycles/([^/]+)/capture/([^/]+))",
        [this](const httplib::Request& req, httplib::Response& res) {
          absl::StatusOr<int64_t> id = ParseCycleId(req.matches[1]);
          if (!id.ok()) return SendError(res, id.status());
          absl::StatusOr<CaptureFileToSend> file = views_.File(*id, req.matches[2]);
          if (!file.ok()) return SendError(res, file.status());
          auto in = std::make_shared<std::ifstream>(file->path, std::ios::binary);
          if (!*in) return SendError(res, absl::NotFoundError("file: cannot open it"));
          // The capture's files are up to input_budget.max_file_bytes: sent in pieces, never whole
          // in memory. A finished cycle's capture does not change, so the browser may keep it.
          res.set_header("Cache-Control", "private, max-age=3600");
          res.set_header("Content-Disposition",
                         absl::StrCat("attachment; filename=\"", file->download_name, "\""));
          res.set_content_provider(
              file->bytes, file->content_type,
              [in](size_t offset, size_t length, httplib::DataSink& sink) {
                std::vector<char> buffer(std::min<size_t>(length, 1 << 16));
                in->seekg(static_cast<std::streamoff>(offset));
                in->read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
                const std::streamsize got = in->gcount();
                return got > 0 && sink.write(buffer.data(), static_cast<size_t>(got));
              });
        });
  s.Get(R"(/api/cycles/([^/]+)/capture\.tar)",
        [this](const httplib::Request& req, httplib::Response& res) {
          absl::StatusOr<int64_t> id = ParseCycleId(req.matches[1]);
          if (!id.ok()) return SendError(res, id.status());
          absl::StatusOr<CaptureArchiveToSend> archive = views_.Archive(*id);
          if (!archive.ok()) return SendError(res, archive.status());
          SendArchive(*std::move(archive), res);
        });
  s.Get(R"(/api/cycles/([^/]+)/views/([^/]+))",
        [this](const httplib::Request& req, httplib::Response& res) {
          absl::StatusOr<int64_t> id = ParseCycleId(req.matches[1]);
          if (!id.ok()) return SendError(res, id.status());
          absl::StatusOr<std::string> view =
              views_.View(*id, req.matches[2], req.get_param_value("frame"));
          if (!view.ok()) return SendError(res, view.status());
          res.set_header("Cache-Control", "no-store");
          res.set_content(*view, kJson);
        });
}

bool WebServer::OperatorAllowed(const httplib::Request& req, httplib::Response& res) {
  if (absl::Status s =
          CheckSameSiteAction(req.get_header_value(kActionHeader), req.get_header_value("Origin"),
                              req.get_header_value("Host"), options_.tls.has_value());
      !s.ok()) {
    SendError(res, s, 403);
    return false;
  }
  const std::string session = CookieValue(req.get_header_value("Cookie"), kCookie);
  if (sessions_.RoleOf(session) != Role::kOperator) {
    SendError(res,
              absl::PermissionDeniedError(
                  options_.operator_token.empty()
                      ? "operator role required: the daemon has no web.operator_token, so "
                        "cycles are started over gRPC only"
                      : "operator role required: this session is read-only; log in with the "
                        "operator token"),
              403);
    return false;
  }
  return true;
}

void WebServer::RouteOperator() {
  httplib::Server& s = *server_;
  s.Post("/api/cycles", [this](const httplib::Request& req, httplib::Response& res) {
    if (!OperatorAllowed(req, res)) return;
    absl::StatusOr<CycleRequest> request = CycleRequestFromJson(req.body);
    if (!request.ok()) return SendError(res, request.status());
    absl::StatusOr<int64_t> id = core_->StartCycle(*request);
    if (!id.ok()) return SendError(res, id.status());
    SendJson(res, {{"cycle_id", std::to_string(*id)}});
  });
  s.Post(R"(/api/cycles/([^/]+)/cancel)",
         [this](const httplib::Request& req, httplib::Response& res) {
           if (!OperatorAllowed(req, res)) return;
           absl::StatusOr<int64_t> id = ParseCycleId(req.matches[1]);
           if (!id.ok()) return SendError(res, id.status());
           if (absl::Status c = core_->CancelCycle(*id); !c.ok()) return SendError(res, c);
           SendJson(res, {{"cycle_id", std::to_string(*id)}, {"cancel", "accepted"}});
         });
}

}  // namespace linecal

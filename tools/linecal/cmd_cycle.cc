// The station client: linecal cycle start / cycle show / cycles list / status, over the
// daemon's gRPC API. The daemon is found by --address or LINECAL_ADDRESS (default
// 127.0.0.1:50051); a token by --token or LINECAL_TOKEN; TLS (docs/daemon.md,
// "Authentication") by --tls-ca, --tls-cert, --tls-key or LINECAL_TLS_CA, _CERT, _KEY.
#include <google/protobuf/util/json_util.h>
#include <grpcpp/grpcpp.h>

#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "linecal/v1/station.grpc.pb.h"
#include "station/io/json_reader.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"

namespace linecal::tools {
namespace {

constexpr char kDefaultAddress[] = "127.0.0.1:50051";

std::vector<cli::OptionSpec> ConnectionOptions(std::vector<cli::OptionSpec> options) {
  options.push_back(
      {"address", "HOST:PORT", "the daemon (default $LINECAL_ADDRESS or 127.0.0.1:50051)"});
  options.push_back({"token", "TOKEN", "authentication token (default $LINECAL_TOKEN)"});
  options.push_back(
      {"tls-ca", "PEM", "TLS: the CA of the daemon's certificate (default $LINECAL_TLS_CA)"});
  options.push_back(
      {"tls-cert", "PEM", "TLS: this client's certificate (default $LINECAL_TLS_CERT)"});
  options.push_back(
      {"tls-key", "PEM", "TLS: this client's private key (default $LINECAL_TLS_KEY)"});
  options.push_back(
      {"tls-server-name", "NAME",
       "TLS: the name the daemon's certificate must carry (default: the address's host)"});
  options.push_back({"json", "", "print JSON"});
  return options;
}

struct Client {
  std::unique_ptr<v1::Station::Stub> stub;
  std::string token;
  std::string address;
  bool tls = false;
  void Prepare(grpc::ClientContext* c) const {
    if (!token.empty()) c->AddMetadata("authorization", "Bearer " + token);
  }
};

// The flag's value, else the environment variable's, else "".
std::string FlagOrEnv(const cli::CommandLine& cl, const char* flag, const char* env) {
  const char* from_env = std::getenv(env);
  return cl.Get(flag, from_env ? from_env : "");
}

// The channel to the daemon: TLS when any of --tls-ca, --tls-cert, --tls-key is given
// (without --tls-ca the system's CAs verify the daemon), else insecure. An unreadable file
// is an error naming the flag and the file.
absl::StatusOr<Client> Connect(const cli::CommandLine& cl) {
  const char* env_address = std::getenv("LINECAL_ADDRESS");
  Client c;
  c.address = cl.Get("address", env_address ? env_address : kDefaultAddress);
  c.token = FlagOrEnv(cl, "token", "LINECAL_TOKEN");
  grpc::SslCredentialsOptions pem;
  const struct {
    const char* flag;
    const char* env;
    std::string* text;
  } files[] = {{"tls-ca", "LINECAL_TLS_CA", &pem.pem_root_certs},
               {"tls-cert", "LINECAL_TLS_CERT", &pem.pem_cert_chain},
               {"tls-key", "LINECAL_TLS_KEY", &pem.pem_private_key}};
  for (const auto& f : files) {
    const std::string path = FlagOrEnv(cl, f.flag, f.env);
    if (path.empty()) continue;
    absl::StatusOr<std::string> text = ReadTextFile(path);
    if (!text.ok())
      return absl::InvalidArgumentError(absl::StrCat("--", f.flag, ": ", text.status().message()));
    *f.text = *std::move(text);
    c.tls = true;
  }
  if (pem.pem_cert_chain.empty() != pem.pem_private_key.empty()) {
    return absl::InvalidArgumentError("--tls-cert and --tls-key: give both or neither");
  }
  const std::string server_name = cl.Get("tls-server-name");
  if (!server_name.empty() && !c.tls)
    return absl::InvalidArgumentError("--tls-server-name: needs --tls-ca or --tls-cert");
  grpc::ChannelArguments arguments;
  if (!server_name.empty()) arguments.SetSslTargetNameOverride(server_name);
  c.stub = v1::Station::NewStub(grpc::CreateCustomChannel(
      c.address, c.tls ? grpc::SslCredentials(pem) : grpc::InsecureChannelCredentials(),
      arguments));
  return c;
}

// A failed call as a one-line message; UNAVAILABLE (no daemon, or over TLS also a failed
// handshake, which gRPC reports the same way) and bad requests are bad input (2), the rest
// negative answers (1).
int CallFailed(const char* command, const Client& client, const grpc::Status& s) {
  const char* why = "refused";
  if (s.error_code() == grpc::StatusCode::UNAVAILABLE) {
    why = client.tls ? "no daemon answers or the TLS handshake failed" : "no daemon answers";
  }
  std::fprintf(stderr, "linecal %s: %s (%s): %s\n", command, client.address.c_str(), why,
               s.error_message().c_str());
  return s.error_code() == grpc::StatusCode::NOT_FOUND ? cli::kExitNegative : cli::kExitBadInput;
}

std::string Json(const google::protobuf::Message& m) {
  std::string out;
  google::protobuf::util::JsonPrintOptions options;
  options.add_whitespace = true;
  options.preserve_proto_field_names = true;
  // Our own messages always convert; a failure would leave out empty, which the caller prints.
  (void)google::protobuf::util::MessageToJsonString(m, &out, options);
  return out;
}

const char* VerdictWord(v1::Verdict v) {
  switch (v) {
    case v1::VERDICT_PASS:
      return "pass";
    case v1::VERDICT_FAIL:
      return "fail";
    case v1::VERDICT_ERROR:
      return "error";
    default:
      return "-";
  }
}

void PrintCycle(const v1::Cycle& c) {
  // "CYCLE_STATE_DONE" -> "done".
  std::string state = v1::CycleState_Name(c.state()).substr(std::string("CYCLE_STATE_").size());
  for (char& ch : state) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  std::printf("cycle %s  VIN %s  car %s  %s  verdict %s%s%s\n", c.cycle_id().c_str(),
              c.vin().c_str(), c.car_model_id().c_str(), state.c_str(), VerdictWord(c.verdict()),
              c.reason().empty() ? "" : "  ", c.reason().c_str());
  if (c.sensors_size() == 0) return;
  std::printf("  %-20s %-7s %-26s %9s %9s %9s %8s %8s %8s %6s\n", "sensor", "verdict", "reason",
              "dyaw_deg", "dpitch_deg", "droll_deg", "dx_mm", "dy_mm", "dz_mm", "feat");
  for (const v1::SensorResult& s : c.sensors()) {
    const v1::MountingAngles& d = s.deviation();
    std::printf("  %-20s %-7s %-26s %+9.3f %+9.3f %+9.3f %+8.1f %+8.1f %+8.1f %6u\n",
                s.name().c_str(), VerdictWord(s.verdict()),
                s.reason().empty() ? "-" : s.reason().c_str(), d.yaw_deg(), d.pitch_deg(),
                d.roll_deg(), d.x_m() * 1e3, d.y_m() * 1e3, d.z_m() * 1e3, s.features_used());
  }
}

}  // namespace

int RunCycleStart(const Args& args) {
  cli::CommandLine cl(
      "linecal cycle start --vin VIN --car MODEL [--lateral-m M] [--longitudinal-m M] "
      "[--thrust-deg D] "
      "[--record] [--frames N] [--wait] [--json]",
      "Starts a calibration cycle for one car on the station's daemon and prints its id. With "
      "--wait, follows its progress on stderr and prints the per-sensor table (or the cycle as "
      "JSON) when it ends; exit 0 when it passed, 1 when it failed or ended in error.",
      ConnectionOptions({{"vin", "VIN", "the car's VIN (ISO 3779)", true},
                         {"car", "MODEL", "car model id", true},
                         {"lateral-m", "M", "aligner lateral offset, metres (default 0)"},
                         {"longitudinal-m", "M", "aligner longitudinal offset, metres (default 0)"},
                         {"thrust-deg", "D", "aligner thrust angle, degrees (default 0)"},
                         {"record", "", "keep the cycle's raw inputs as a capture"},
                         {"frames", "N", "frames per sensor (default: the station's)"},
                         {"wait", "", "wait for the end and print the results"}}));
  if (const std::optional<int> exit = cli::ParseOrExit(cl, "cycle start", args)) return *exit;
  v1::StartCycleRequest request;
  request.set_vin(cl.Get("vin"));
  request.set_car_model_id(cl.Get("car"));
  const absl::StatusOr<double> lateral = cl.GetDouble("lateral-m", 0);
  const absl::StatusOr<double> longitudinal = cl.GetDouble("longitudinal-m", 0);
  const absl::StatusOr<double> thrust = cl.GetDouble("thrust-deg", 0);
  const absl::StatusOr<int> frames = cl.GetInt("frames", 0);
  for (const absl::Status& s :
       {lateral.status(), longitudinal.status(), thrust.status(), frames.status()}) {
    if (!s.ok()) return cli::BadInput("cycle start", std::string(s.message()));
  }
  if (*frames < 0) return cli::BadInput("cycle start", "--frames: must be >= 0");
  request.mutable_aligner()->set_lateral_offset_m(*lateral);
  request.mutable_aligner()->set_longitudinal_offset_m(*longitudinal);
  request.mutable_aligner()->set_thrust_angle_deg(*thrust);
  request.mutable_options()->set_record_capture(cl.Has("record"));
  request.mutable_options()->set_frames_per_sensor(static_cast<uint32_t>(*frames));
  const absl::StatusOr<Client> connected = Connect(cl);
  if (!connected.ok())
    return cli::BadInput("cycle start", std::string(connected.status().message()));
  const Client& client = *connected;
  grpc::ClientContext context;
  client.Prepare(&context);
  v1::StartCycleResponse started;
  if (grpc::Status s = client.stub->StartCycle(&context, request, &started); !s.ok()) {
    return CallFailed("cycle start", client, s);
  }
  if (!cl.Has("wait")) {
    std::printf("%s\n", started.cycle_id().c_str());
    return cli::kExitOk;
  }
  std::fprintf(stderr, "cycle %s started\n", started.cycle_id().c_str());
  {
    grpc::ClientContext watch_context;
    client.Prepare(&watch_context);
    v1::WatchCycleRequest watch;
    watch.set_cycle_id(started.cycle_id());
    std::unique_ptr<grpc::ClientReader<v1::CycleEvent>> reader =
        client.stub->WatchCycle(&watch_context, watch);
    v1::CycleEvent e;
    while (reader->Read(&e)) {
      std::fprintf(stderr, "  %-22s %-20s %s%s%s\n",
                   v1::CycleEvent::Type_Name(e.type()).c_str() + 5, e.sensor().c_str(),
                   e.verdict() == v1::VERDICT_UNSPECIFIED ? "" : VerdictWord(e.verdict()),
                   e.detail().empty() ? "" : " ", e.detail().c_str());
    }
    if (grpc::Status s = reader->Finish(); !s.ok()) return CallFailed("cycle start", client, s);
  }
  grpc::ClientContext get_context;
  client.Prepare(&get_context);
  v1::GetCycleRequest get;
  get.set_cycle_id(started.cycle_id());
  v1::Cycle cycle;
  if (grpc::Status s = client.stub->GetCycle(&get_context, get, &cycle); !s.ok()) {
    return CallFailed("cycle start", client, s);
  }
  if (cl.Has("json")) {
    std::printf("%s\n", Json(cycle).c_str());
  } else {
    PrintCycle(cycle);
  }
  return cycle.verdict() == v1::VERDICT_PASS ? cli::kExitOk : cli::kExitNegative;
}

int RunCycleShow(const Args& args) {
  cli::CommandLine cl("linecal cycle show ID [--json]",
                      "Prints one stored cycle with its per-sensor results.",
                      ConnectionOptions({{"id", "ID", "cycle id", true, false, true}}));
  if (const std::optional<int> exit = cli::ParseOrExit(cl, "cycle show", args)) return *exit;
  const absl::StatusOr<Client> connected = Connect(cl);
  if (!connected.ok())
    return cli::BadInput("cycle show", std::string(connected.status().message()));
  const Client& client = *connected;
  grpc::ClientContext context;
  client.Prepare(&context);
  v1::GetCycleRequest get;
  get.set_cycle_id(cl.Get("id"));
  v1::Cycle cycle;
  if (grpc::Status s = client.stub->GetCycle(&context, get, &cycle); !s.ok())
    return CallFailed("cycle show", client, s);
  if (cl.Has("json")) {
    std::printf("%s\n", Json(cycle).c_str());
  } else {
    PrintCycle(cycle);
  }
  return cli::kExitOk;
}

int RunCyclesList(const Args& args) {
  cli::CommandLine cl(
      "linecal cycles list [--vin VIN] [--verdict pass|fail|error] [--limit N] [--json]",
      "Lists stored cycles, newest first.",
      ConnectionOptions({{"vin", "VIN", "only this car"},
                         {"verdict", "V", "only cycles with this verdict"},
                         {"limit", "N", "at most N cycles (default 50)"}}));
  if (const std::optional<int> exit = cli::ParseOrExit(cl, "cycles list", args)) return *exit;
  v1::ListCyclesRequest request;
  request.set_vin(cl.Get("vin"));
  const std::string verdict = cl.Get("verdict");
  if (verdict == "pass") {
    request.set_verdict(v1::VERDICT_PASS);
  } else if (verdict == "fail") {
    request.set_verdict(v1::VERDICT_FAIL);
  } else if (verdict == "error") {
    request.set_verdict(v1::VERDICT_ERROR);
  } else if (!verdict.empty()) {
    return cli::BadInput("cycles list",
                         absl::StrCat("--verdict: '", verdict, "': must be pass, fail or error"));
  }
  const absl::StatusOr<int> limit = cl.GetInt("limit", 50);
  if (!limit.ok() || *limit < 1 || *limit > 1000)
    return cli::BadInput("cycles list", "--limit: must be in [1, 1000]");
  request.set_page_size(static_cast<uint32_t>(*limit));
  const absl::StatusOr<Client> connected = Connect(cl);
  if (!connected.ok())
    return cli::BadInput("cycles list", std::string(connected.status().message()));
  const Client& client = *connected;
  grpc::ClientContext context;
  client.Prepare(&context);
  v1::ListCyclesResponse response;
  if (grpc::Status s = client.stub->ListCycles(&context, request, &response); !s.ok()) {
    return CallFailed("cycles list", client, s);
  }
  if (cl.Has("json")) {
    std::printf("%s\n", Json(response).c_str());
    return cli::kExitOk;
  }
  for (const v1::Cycle& c : response.cycles()) PrintCycle(c);
  return cli::kExitOk;
}

int RunStatus(const Args& args) {
  cli::CommandLine cl("linecal status [--json]",
                      "The daemon's station: version, car models, sensors, database.",
                      ConnectionOptions({}));
  if (const std::optional<int> exit = cli::ParseOrExit(cl, "status", args)) return *exit;
  const absl::StatusOr<Client> connected = Connect(cl);
  if (!connected.ok()) return cli::BadInput("status", std::string(connected.status().message()));
  const Client& client = *connected;
  grpc::ClientContext context;
  client.Prepare(&context);
  v1::StationStatus status;
  if (grpc::Status s = client.stub->GetStationStatus(&context, {}, &status); !s.ok()) {
    return CallFailed("status", client, s);
  }
  if (cl.Has("json")) {
    std::printf("%s\n", Json(status).c_str());
    return cli::kExitOk;
  }
  std::printf("linecald %s, station %s, database %s (%.1f GB free)\n", status.version().c_str(),
              status.station_id().c_str(), status.database_path().c_str(),
              status.disk_free_bytes() / 1e9);
  std::printf("running cycle: %s\n",
              status.running_cycle_id().empty() ? "none" : status.running_cycle_id().c_str());
  if (status.has_plant()) {
    const v1::PlantForwarding& plant = status.plant();
    std::printf(
        "plant database: %lld cycles queued, oldest %.0f s (NOT_SERVING past %.0f s), %lld "
        "shipped since start%s%s\n",
        static_cast<long long>(plant.backlog()), plant.oldest_unshipped_age_ns() / 1e9,
        plant.max_backlog_age_ns() / 1e9, static_cast<long long>(plant.shipped()),
        plant.last_error().empty() ? "" : ", last error: ", plant.last_error().c_str());
  }
  for (const v1::TargetAlarm& a : status.target_alarms()) {
    std::printf("ALARM: target %s (car model %s) has likely moved since cycle %s: its residual in",
                absl::StrJoin(a.targets(), " or ").c_str(), a.car_model().c_str(),
                a.since_cycle_id().c_str());
    for (const v1::ShiftedSensor& x : a.sensors()) {
      std::printf(" %s %+.1f sigma (%.4g -> %.4g)", x.sensor().c_str(), x.shift_sigmas(),
                  x.baseline_residual(), x.recent_residual());
    }
    std::printf(", EWMA %.1f sigma over the limit %.1f, cycle %s\n", a.statistic_sigmas(),
                a.alarm_sigmas(), a.last_cycle_id().c_str());
  }
  for (const v1::SensorStatus& s : status.sensors()) {
    std::printf("  %-20s %-7s %s%s\n", s.name().c_str(), v1::SensorKind_Name(s.kind()).c_str() + 12,
                s.source().c_str(), s.connected() ? "" : "  (not connected)");
  }
  return cli::kExitOk;
}

}  // namespace linecal::tools

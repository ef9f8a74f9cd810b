// The gRPC service on a real server on 127.0.0.1 (a free port) over the real core, store and
// simulator: a cycle started, watched to its end and read back; every RPC's error codes;
// authentication on and off (token, mutual TLS with certificates made by openssl, both); two
// clients watching one cycle.
#include <google/protobuf/descriptor.pb.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <future>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "daemon/service/station_service.h"
#include "grpc/reflection/v1alpha/reflection.grpc.pb.h"
#include "station/io/json_reader.h"
#include "tests/daemon/scratch_dir.h"
#include "tests/daemon/test_car.h"
#include "tests/daemon/test_pki.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
constexpr char kVin[] = "1M8GDM9AXKP042788";

class ServiceTest : public ::testing::Test {
 protected:
  // A scratch directory per test and process (ctest runs tests in parallel processes).
  void MakeDir() { dir_ = testing_daemon::FreshTestDir("service"); }
  void CreateCore() {
    if (dir_.empty()) MakeDir();
    // The reference car with two sensors: a short cycle.
    testing_daemon::WriteTwoSensorCar((dir_ / "car.json").string());
    StationCoreConfig config;
    config.station_path = kDeploy + "/stations/reference.json";
    config.car_model_paths = {(dir_ / "car.json").string()};
    config.db_path = (dir_ / "station.db").string();
    config.data_root = (dir_ / "data").string();
    core_ = std::move(*StationCore::Create(config));
  }
  void Start(const std::string& token, const std::optional<TlsConfig>& tls = std::nullopt) {
    CreateCore();
    absl::StatusOr<RunningServer> server =
        StartServer(core_.get(), "127.0.0.1:0", token, "test", tls);
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = std::move(*server);
    channel_ = grpc::CreateChannel("127.0.0.1:" + std::to_string(server_.port),
                                   grpc::InsecureChannelCredentials());
    stub_ = v1::Station::NewStub(channel_);
  }
  void TearDown() override {
    if (server_.server) server_.server->Shutdown();
    if (core_) core_->WaitIdle();
    server_ = {};
    core_.reset();
    fs::remove_all(dir_);
  }

  static v1::StartCycleRequest Request() {
    v1::StartCycleRequest r;
    r.set_vin(kVin);
    r.set_car_model_id("reference");
    r.mutable_aligner()->set_lateral_offset_m(0.01);
    r.mutable_aligner()->set_thrust_angle_deg(0.05);
    return r;
  }

  std::vector<v1::CycleEvent> Watch(const std::string& id, const std::string& token = "") {
    grpc::ClientContext context;
    if (!token.empty()) context.AddMetadata("authorization", "Bearer " + token);
    v1::WatchCycleRequest w;
    w.set_cycle_id(id);
    std::unique_ptr<grpc::ClientReader<v1::CycleEvent>> reader = stub_->WatchCycle(&context, w);
    std::vector<v1::CycleEvent> events;
    v1::CycleEvent e;
    while (reader->Read(&e)) events.push_back(e);
    EXPECT_TRUE(reader->Finish().ok());
    return events;
  }

  fs::path dir_;
  std::unique_ptr<StationCore> core_;
  RunningServer server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::Station::Stub> stub_;
};

TEST_F(ServiceTest, CycleStartedWatchedAndReadBack) {
  Start("");
  grpc::ClientContext start_context;
  v1::StartCycleResponse started;
  ASSERT_TRUE(stub_->StartCycle(&start_context, Request(), &started).ok());
  ASSERT_FALSE(started.cycle_id().empty());

  // Two clients watch the same cycle and see the same events, ending with cycle_ended.
  std::vector<v1::CycleEvent> other;
  std::thread second([&] { other = Watch(started.cycle_id()); });
  const std::vector<v1::CycleEvent> events = Watch(started.cycle_id());
  second.join();
  ASSERT_GE(events.size(), 4u);
  EXPECT_EQ(events.front().type(), v1::CycleEvent::TYPE_STARTED);
  EXPECT_EQ(events.back().type(), v1::CycleEvent::TYPE_CYCLE_ENDED);
  ASSERT_EQ(other.size(), events.size());
  for (size_t i = 0; i < events.size(); ++i) {
    EXPECT_EQ(events[i].sequence(), i);
    EXPECT_EQ(other[i].type(), events[i].type());
  }

  grpc::ClientContext get_context;
  v1::GetCycleRequest get;
  get.set_cycle_id(started.cycle_id());
  v1::Cycle cycle;
  ASSERT_TRUE(stub_->GetCycle(&get_context, get, &cycle).ok());
  EXPECT_EQ(cycle.vin(), kVin);
  EXPECT_EQ(cycle.state(), v1::CYCLE_STATE_DONE);
  EXPECT_NE(cycle.verdict(), v1::VERDICT_UNSPECIFIED);
  ASSERT_EQ(cycle.sensors_size(), 2);
  for (const v1::SensorResult& s : cycle.sensors()) {
    if (s.verdict() == v1::VERDICT_ERROR) continue;
    EXPECT_EQ(s.t_car_sensor().m_size(), 16) << s.name();
  }

  grpc::ClientContext list_context;
  v1::ListCyclesRequest list;
  list.set_vin(kVin);
  v1::ListCyclesResponse listed;
  ASSERT_TRUE(stub_->ListCycles(&list_context, list, &listed).ok());
  ASSERT_EQ(listed.cycles_size(), 1);
  EXPECT_EQ(listed.cycles(0).cycle_id(), started.cycle_id());

  grpc::ClientContext status_context;
  v1::StationStatus status;
  ASSERT_TRUE(stub_->GetStationStatus(&status_context, {}, &status).ok());
  EXPECT_EQ(status.version(), "test");
  EXPECT_EQ(status.sensors_size(), 2);
  EXPECT_TRUE(status.running_cycle_id().empty());
}

TEST_F(ServiceTest, ErrorCodesOfEveryRpc) {
  Start("");
  auto start = [&](const v1::StartCycleRequest& r) {
    grpc::ClientContext c;
    v1::StartCycleResponse out;
    return stub_->StartCycle(&c, r, &out);
  };
  v1::StartCycleRequest bad = Request();
  bad.set_vin("SHORT");
  grpc::Status s = start(bad);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(s.error_message().rfind("vin", 0), 0u) << s.error_message();
  bad = Request();
  bad.mutable_aligner()->set_thrust_angle_deg(45);
  s = start(bad);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("thrust"), std::string::npos);
  bad = Request();
  bad.set_car_model_id("truck");
  EXPECT_EQ(start(bad).error_code(), grpc::StatusCode::INVALID_ARGUMENT);

  ASSERT_TRUE(start(Request()).ok());
  EXPECT_EQ(start(Request()).error_code(), grpc::StatusCode::FAILED_PRECONDITION);  // one at a time
  core_->WaitIdle();

  grpc::ClientContext get_context;
  v1::GetCycleRequest get;
  get.set_cycle_id("12345");
  v1::Cycle cycle;
  EXPECT_EQ(stub_->GetCycle(&get_context, get, &cycle).error_code(), grpc::StatusCode::NOT_FOUND);
  grpc::ClientContext malformed_context;
  get.set_cycle_id("abc");
  const grpc::Status malformed = stub_->GetCycle(&malformed_context, get, &cycle);
  EXPECT_EQ(malformed.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(malformed.error_message().find("cycle_id"), std::string::npos);
  grpc::ClientContext cancel_context;
  v1::CancelCycleRequest cancel;
  cancel.set_cycle_id("1");  // ended
  v1::CancelCycleResponse cancelled;
  EXPECT_EQ(stub_->CancelCycle(&cancel_context, cancel, &cancelled).error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);
  grpc::ClientContext watch_context;
  v1::WatchCycleRequest watch;
  watch.set_cycle_id("777");
  std::unique_ptr<grpc::ClientReader<v1::CycleEvent>> reader =
      stub_->WatchCycle(&watch_context, watch);
  v1::CycleEvent e;
  EXPECT_FALSE(reader->Read(&e));
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::NOT_FOUND);
  grpc::ClientContext list_context;
  v1::ListCyclesRequest list;
  list.set_page_token("garbage");
  v1::ListCyclesResponse listed;
  EXPECT_EQ(stub_->ListCycles(&list_context, list, &listed).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

// A second server on a port in use fails to start (gRPC's SO_REUSEPORT is off): two daemons
// would otherwise share the station controller's calls.
TEST_F(ServiceTest, SecondServerOnTheSamePortFailsToStart) {
  Start("");
  absl::StatusOr<RunningServer> second =
      StartServer(core_.get(), "127.0.0.1:" + std::to_string(server_.port), "", "test");
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(
      second.status().message().find("cannot listen on '127.0.0.1:" + std::to_string(server_.port)),
      std::string::npos)
      << second.status();
}

// Values of 10 kB in each string field that can be refused come back quoted in at most
// kMaxQuotedBytes bytes with their size: echoed whole, a 10 kB message exceeded the client's
// metadata limit (RESOURCE_EXHAUSTED instead of the refusal), and a 3 MB one was 3 MB.
TEST_F(ServiceTest, LongInputsAreQuotedShortlyInErrors) {
  Start("");
  const std::string long_value(10240, '7');
  // A refusal's message: the field first, then at most 64 bytes of the value, its size, and
  // the words around it (the car model list, ...): 200 bytes leave room for those.
  const auto expect_short = [&](const grpc::Status& s, const std::string& field) {
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
        << field << ": " << s.error_message();
    EXPECT_EQ(s.error_message().rfind(field, 0), 0u) << s.error_message();
    EXPECT_LE(s.error_message().size(), 200u) << field;
    EXPECT_NE(s.error_message().find("'" + long_value.substr(0, 64) + "…' (10240 bytes)"),
              std::string::npos)
        << s.error_message();
  };
  {
    grpc::ClientContext c;
    v1::GetCycleRequest r;
    r.set_cycle_id(long_value);
    v1::Cycle out;
    expect_short(stub_->GetCycle(&c, r, &out), "cycle_id");
  }
  {
    grpc::ClientContext c;
    v1::CancelCycleRequest r;
    r.set_cycle_id(long_value);
    v1::CancelCycleResponse out;
    expect_short(stub_->CancelCycle(&c, r, &out), "cycle_id");
  }
  {
    grpc::ClientContext c;
    v1::WatchCycleRequest r;
    r.set_cycle_id(long_value);
    std::unique_ptr<grpc::ClientReader<v1::CycleEvent>> reader = stub_->WatchCycle(&c, r);
    v1::CycleEvent e;
    EXPECT_FALSE(reader->Read(&e));
    expect_short(reader->Finish(), "cycle_id");
  }
  {
    grpc::ClientContext c;
    v1::StartCycleRequest r = Request();
    r.set_car_model_id(long_value);
    v1::StartCycleResponse out;
    expect_short(stub_->StartCycle(&c, r, &out), "car_model_id");
  }
  {
    grpc::ClientContext c;
    v1::ListCyclesRequest r;
    r.set_page_token(long_value);
    v1::ListCyclesResponse out;
    expect_short(stub_->ListCycles(&c, r, &out), "page_token");
  }
  // A value of at most 64 bytes is quoted whole, without a size.
  grpc::ClientContext c;
  v1::GetCycleRequest r;
  r.set_cycle_id("x1");
  v1::Cycle out;
  EXPECT_EQ(stub_->GetCycle(&c, r, &out).error_message(), "cycle_id: 'x1' is not a cycle id");
}

// ListCycles' filter refusals through the server name the value the client sent.
TEST_F(ServiceTest, ListFilterRefusalsNameTheValueSent) {
  Start("");
  grpc::ClientContext size_context;
  v1::ListCyclesRequest r;
  r.set_page_size(4'294'967'295u);
  v1::ListCyclesResponse out;
  const grpc::Status size = stub_->ListCycles(&size_context, r, &out);
  EXPECT_EQ(size.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(size.error_message().rfind("page_size = 4294967295: must be in [0, 1000]", 0), 0u)
      << size.error_message();
  grpc::ClientContext verdict_context;
  r.set_page_size(0);
  r.set_verdict(static_cast<v1::Verdict>(99));
  const grpc::Status verdict = stub_->ListCycles(&verdict_context, r, &out);
  EXPECT_EQ(verdict.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(verdict.error_message().rfind("verdict = 99: not a verdict", 0), 0u)
      << verdict.error_message();
}

// A port beyond 65535 is refused before gRPC sees it (gRPC listened on another port).
TEST_F(ServiceTest, ListenPortOutOfRangeIsRefused) {
  CreateCore();
  absl::StatusOr<RunningServer> server = StartServer(core_.get(), "127.0.0.1:99999", "", "test");
  ASSERT_EQ(server.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(server.status().message(),
            "listen: '127.0.0.1:99999': must be HOST:PORT with a port in 0..65535");
  for (const char* bad : {"127.0.0.1:65536", "127.0.0.1:-1", "127.0.0.1:", "127.0.0.1", ":50051",
                          "127.0.0.1:5o051", "127.0.0.1:+5005"}) {
    EXPECT_EQ(CheckListenAddress(bad).code(), absl::StatusCode::kInvalidArgument) << bad;
  }
  for (const char* good : {"127.0.0.1:0", "0.0.0.0:65535", "[::1]:50051", "localhost:50051"}) {
    EXPECT_TRUE(CheckListenAddress(good).ok()) << good;
  }
}

TEST_F(ServiceTest, TokenAuthentication) {
  Start("s3cret");
  {
    grpc::ClientContext c;
    v1::StationStatus status;
    EXPECT_EQ(stub_->GetStationStatus(&c, {}, &status).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
  }
  {
    grpc::ClientContext c;
    c.AddMetadata("authorization", "Bearer wrong");
    v1::StartCycleResponse out;
    EXPECT_EQ(stub_->StartCycle(&c, Request(), &out).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
  }
  {
    grpc::ClientContext c;
    c.AddMetadata("authorization", "Bearer s3cret");
    v1::StationStatus status;
    EXPECT_TRUE(stub_->GetStationStatus(&c, {}, &status).ok());
  }
  EXPECT_TRUE(core_->ListCycles({})->cycles.empty());  // the refused start stored nothing
}

// Server reflection hands out the whole API schema: it needs the token like every Station
// call (it used to answer anyone). Health stays open (HealthServiceIsOn).
TEST_F(ServiceTest, ReflectionNeedsTheToken) {
  Start("s3cret");
  using grpc::reflection::v1alpha::ServerReflection;
  using grpc::reflection::v1alpha::ServerReflectionRequest;
  using grpc::reflection::v1alpha::ServerReflectionResponse;
  std::unique_ptr<ServerReflection::Stub> reflection = ServerReflection::NewStub(channel_);
  // Sends `requests` on one stream; returns the responses and the call's status.
  const auto ask = [&](const std::string& token,
                       const std::vector<ServerReflectionRequest>& requests,
                       std::vector<ServerReflectionResponse>* responses) {
    grpc::ClientContext context;
    if (!token.empty()) context.AddMetadata("authorization", "Bearer " + token);
    auto stream = reflection->ServerReflectionInfo(&context);
    for (const ServerReflectionRequest& r : requests) stream->Write(r);
    stream->WritesDone();
    ServerReflectionResponse response;
    while (stream->Read(&response)) responses->push_back(response);
    return stream->Finish();
  };
  ServerReflectionRequest list;
  list.set_list_services("");
  ServerReflectionRequest file;
  file.set_file_containing_symbol("linecal.v1.Station");
  ServerReflectionRequest unknown;
  unknown.set_file_containing_symbol("linecal.v1.NoSuchThing");

  for (const std::string token : {"", "wrong"}) {
    std::vector<ServerReflectionResponse> refused;
    const grpc::Status s = ask(token, {list, file}, &refused);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED) << token;
    EXPECT_EQ(s.error_message(), "authorization: a valid bearer token is required");
    EXPECT_TRUE(refused.empty()) << token;
  }

  std::vector<ServerReflectionResponse> answers;
  ASSERT_TRUE(ask("s3cret", {list, file, unknown}, &answers).ok());
  ASSERT_EQ(answers.size(), 3u);
  std::vector<std::string> services;
  for (const auto& service : answers[0].list_services_response().service()) {
    services.push_back(service.name());
  }
  EXPECT_EQ(services, (std::vector<std::string>{"linecal.v1.Station", "grpc.health.v1.Health",
                                                "grpc.reflection.v1alpha.ServerReflection"}));
  // The file declaring the service, then what it imports.
  ASSERT_GE(answers[1].file_descriptor_response().file_descriptor_proto_size(), 1);
  google::protobuf::FileDescriptorProto station;
  ASSERT_TRUE(
      station.ParseFromString(answers[1].file_descriptor_response().file_descriptor_proto(0)));
  EXPECT_EQ(station.name(), "linecal/v1/station.proto");
  ASSERT_EQ(station.service_size(), 1);
  EXPECT_EQ(station.service(0).name(), "Station");
  EXPECT_EQ(answers[1].original_request().file_containing_symbol(), "linecal.v1.Station");
  EXPECT_EQ(answers[2].error_response().error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(ServiceTest, HealthServiceIsOn) {
  Start("");
  ASSERT_NE(server_.server->GetHealthCheckService(), nullptr);
}

// grpc.health.v1.Health/Check with an empty request (service ""): the response's bytes,
// "\x08\x01" for SERVING, "\x08\x02" for NOT_SERVING (field 1, the status enum).
std::string HealthCheckBytes(const std::shared_ptr<grpc::Channel>& channel) {
  grpc::GenericStub generic(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  // gRPC refuses a buffer without slices; the empty message is one empty slice.
  grpc::Slice empty_message("");
  grpc::ByteBuffer request(&empty_message, 1);
  grpc::ByteBuffer response;
  std::promise<grpc::Status> done;
  generic.UnaryCall(&context, "/grpc.health.v1.Health/Check", grpc::StubOptions(), &request,
                    &response, [&](grpc::Status s) { done.set_value(s); });
  const grpc::Status status = done.get_future().get();
  if (!status.ok()) return "error: " + status.error_message();
  grpc::Slice slice;
  if (!response.DumpToSingleSlice(&slice).ok()) return "";
  return std::string(reinterpret_cast<const char*>(slice.begin()), slice.size());
}

// Issue 21, items 1 and 7: the health check said SERVING whatever happened to the storage.
// With the data root (and the database in it) deleted it turns NOT_SERVING within a poll
// (kHealthPollInterval), and StartCycle says why.
TEST_F(ServiceTest, HealthIsNotServingOnceTheDataRootIsGone) {
  MakeDir();
  testing_daemon::WriteTwoSensorCar((dir_ / "car.json").string());
  StationCoreConfig config;
  config.station_path = kDeploy + "/stations/reference.json";
  config.car_model_paths = {(dir_ / "car.json").string()};
  config.data_root = (dir_ / "data").string();
  config.db_path = (dir_ / "data" / "station.db").string();
  fs::create_directories(config.data_root);
  config.log = [](const LogRecord&) {};
  core_ = std::move(*StationCore::Create(config));
  absl::StatusOr<RunningServer> server = StartServer(core_.get(), "127.0.0.1:0", "", "test");
  ASSERT_TRUE(server.ok()) << server.status();
  server_ = std::move(*server);
  channel_ = grpc::CreateChannel("127.0.0.1:" + std::to_string(server_.port),
                                 grpc::InsecureChannelCredentials());
  stub_ = v1::Station::NewStub(channel_);
  EXPECT_EQ(HealthCheckBytes(channel_), std::string("\x08\x01", 2));

  fs::remove_all(config.data_root);
  const auto removed = std::chrono::steady_clock::now();
  std::string health;
  while ((health = HealthCheckBytes(channel_)) != std::string("\x08\x02", 2) &&
         std::chrono::steady_clock::now() - removed < std::chrono::seconds(10)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_EQ(health, std::string("\x08\x02", 2));
  // A poll and a call: 2 s is eight polls, for a loaded machine.
  EXPECT_LT(std::chrono::steady_clock::now() - removed, std::chrono::seconds(2));
  grpc::ClientContext context;
  v1::StartCycleResponse started;
  const grpc::Status refused = stub_->StartCycle(&context, Request(), &started);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(refused.error_message().find("was removed while linecald ran"), std::string::npos)
      << refused.error_message();
}

// Mutual TLS: a server with the openssl-made certificates of testing_daemon::MakeTestPki.
class TlsServiceTest : public ServiceTest {
 protected:
  void SetUp() override {
    MakeDir();
    ASSERT_TRUE(testing_daemon::MakeTestPki(dir_, &pki_));
  }
  // The server's `tls` as the configuration file would give it.
  TlsConfig ServerTls(const std::string& cert, const std::string& key) const {
    TlsConfig tls;
    tls.cert_path = cert;
    tls.key_path = key;
    tls.client_ca_path = pki_.ca_cert;
    tls.cert_pem = *ReadTextFile(cert);
    tls.key_pem = *ReadTextFile(key);
    tls.client_ca_pem = *ReadTextFile(pki_.ca_cert);
    return tls;
  }
  // A stub over TLS trusting the test CA, with this client certificate (none when empty).
  std::unique_ptr<v1::Station::Stub> TlsStub(const std::string& cert,
                                             const std::string& key) const {
    return v1::Station::NewStub(TlsChannel(cert, key));
  }
  std::shared_ptr<grpc::Channel> TlsChannel(const std::string& cert, const std::string& key) const {
    grpc::SslCredentialsOptions options;
    options.pem_root_certs = *ReadTextFile(pki_.ca_cert);
    if (!cert.empty()) {
      options.pem_cert_chain = *ReadTextFile(cert);
      options.pem_private_key = *ReadTextFile(key);
    }
    return grpc::CreateChannel("127.0.0.1:" + std::to_string(server_.port),
                               grpc::SslCredentials(options));
  }
  static grpc::Status Status(v1::Station::Stub& stub, const std::string& token = "") {
    grpc::ClientContext c;
    // A refused handshake is retried by gRPC until the deadline; 5 s is far above a loopback
    // handshake (milliseconds) and keeps a hang from stalling the suite.
    c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
    if (!token.empty()) c.AddMetadata("authorization", "Bearer " + token);
    v1::StationStatus status;
    return stub.GetStationStatus(&c, {}, &status);
  }
  // A refused connection: UNAVAILABLE with gRPC's reason, which for TLS names the handshake
  // or the closed connection (docs/daemon.md, "Authentication", lists what clients see).
  static void ExpectRefusedHandshake(const grpc::Status& s) {
    EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAVAILABLE) << s.error_message();
    EXPECT_TRUE(s.error_message().find("andshake") != std::string::npos ||
                s.error_message().find("Socket closed") != std::string::npos ||
                s.error_message().find("Connection reset") != std::string::npos)
        << s.error_message();
  }
  testing_daemon::TestPki pki_;
};

TEST_F(TlsServiceTest, ClientWithCertificateIsServedHealthIncluded) {
  Start("", ServerTls(pki_.server_cert, pki_.server_key));
  const std::shared_ptr<grpc::Channel> channel = TlsChannel(pki_.client_cert, pki_.client_key);
  const std::unique_ptr<v1::Station::Stub> stub = v1::Station::NewStub(channel);
  EXPECT_TRUE(Status(*stub).ok());
  grpc::ClientContext start_context;
  v1::StartCycleResponse started;
  ASSERT_TRUE(stub->StartCycle(&start_context, Request(), &started).ok());
  EXPECT_EQ(started.cycle_id(), "1");
  core_->WaitIdle();

  // The standard health service on the same TLS port: grpc.health.v1.Health/Check with an
  // empty request (service "") answers status SERVING, field 1 = 1: the bytes 08 01.
  grpc::GenericStub generic(channel);
  grpc::ClientContext health_context;
  // gRPC refuses a buffer without slices; the empty message is one empty slice.
  grpc::Slice empty_message("");
  grpc::ByteBuffer request(&empty_message, 1);
  grpc::ByteBuffer response;
  std::promise<grpc::Status> done;
  generic.UnaryCall(&health_context, "/grpc.health.v1.Health/Check", grpc::StubOptions(), &request,
                    &response, [&](grpc::Status s) { done.set_value(s); });
  const grpc::Status health = done.get_future().get();
  ASSERT_TRUE(health.ok()) << health.error_message();
  grpc::Slice slice;
  ASSERT_TRUE(response.DumpToSingleSlice(&slice).ok());
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(slice.begin()), slice.size()),
            std::string("\x08\x01", 2));
}

TEST_F(TlsServiceTest, ClientsWithoutAValidCertificateAreRefused) {
  Start("", ServerTls(pki_.server_cert, pki_.server_key));
  ExpectRefusedHandshake(Status(*TlsStub("", "")));  // no certificate
  ExpectRefusedHandshake(
      Status(*TlsStub(pki_.other_client_cert, pki_.other_client_key)));  // another CA's
  ExpectRefusedHandshake(Status(*stub_));                                // no TLS at all
  EXPECT_TRUE(core_->ListCycles({})->cycles.empty());
}

TEST_F(TlsServiceTest, TokenAndCertificateBothRequired) {
  Start("s3cret", ServerTls(pki_.server_cert, pki_.server_key));
  const std::unique_ptr<v1::Station::Stub> with_cert = TlsStub(pki_.client_cert, pki_.client_key);
  EXPECT_EQ(Status(*with_cert).error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(Status(*with_cert, "wrong").error_code(), grpc::StatusCode::UNAUTHENTICATED);
  ExpectRefusedHandshake(Status(*TlsStub("", ""), "s3cret"));
  EXPECT_TRUE(Status(*with_cert, "s3cret").ok());
}

TEST_F(TlsServiceTest, WrongFilesFailAtStartNamingKeyAndFile) {
  CreateCore();
  // The client's key with the server's certificate.
  absl::StatusOr<RunningServer> mismatched = StartServer(
      core_.get(), "127.0.0.1:0", "", "test", ServerTls(pki_.server_cert, pki_.client_key));
  ASSERT_EQ(mismatched.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(mismatched.status().message(), "tls.key: " + pki_.client_key +
                                               ": does not match the certificate of tls.cert (" +
                                               pki_.server_cert + ")");
  // A key where the certificate belongs.
  absl::StatusOr<RunningServer> swapped = StartServer(core_.get(), "127.0.0.1:0", "", "test",
                                                      ServerTls(pki_.server_key, pki_.server_key));
  ASSERT_EQ(swapped.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(swapped.status().message().rfind(
                "tls.cert: " + pki_.server_key + ": not a PEM certificate", 0),
            0u)
      << swapped.status().message();
  TlsConfig bad_ca = ServerTls(pki_.server_cert, pki_.server_key);
  bad_ca.client_ca_pem = "junk";
  absl::StatusOr<RunningServer> junk = StartServer(core_.get(), "127.0.0.1:0", "", "test", bad_ca);
  ASSERT_EQ(junk.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(junk.status().message().rfind(
                "tls.client_ca: " + pki_.ca_cert + ": not a PEM certificate", 0),
            0u)
      << junk.status().message();
}

// The handlers' translations, without a server (the request fuzzer drives them too).
TEST(RequestTranslation, StartCycleInCoreUnits) {
  v1::StartCycleRequest request;
  request.set_vin(kVin);
  request.set_car_model_id("reference");
  request.mutable_aligner()->set_lateral_offset_m(-0.25);
  request.mutable_aligner()->set_thrust_angle_deg(0.5);
  request.mutable_options()->set_frames_per_sensor(7);
  absl::StatusOr<CycleRequest> r = CycleRequestFromProto(request);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->vin, kVin);
  EXPECT_DOUBLE_EQ(r->aligner.lateral_offset_m, -0.25);
  EXPECT_NEAR(r->aligner.thrust_angle_rad, 0.5 * 3.14159265358979 / 180.0, 1e-12);
  EXPECT_EQ(r->frames_per_sensor, 7);
  // A uint32 that would wrap to a negative int is refused here, naming the field.
  request.mutable_options()->set_frames_per_sensor(4'000'000'000u);
  r = CycleRequestFromProto(request);
  ASSERT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("options.frames_per_sensor"), std::string::npos);
}

TEST(RequestTranslation, ListFilterAndCycleIds) {
  v1::ListCyclesRequest request;
  EXPECT_EQ(CycleFilterFromProto(request)->page_size, 50);
  EXPECT_FALSE(CycleFilterFromProto(request)->verdict.has_value());
  request.set_page_size(1000);
  request.set_verdict(v1::VERDICT_FAIL);
  EXPECT_EQ(CycleFilterFromProto(request)->page_size, 1000);
  EXPECT_EQ(CycleFilterFromProto(request)->verdict, Verdict::kFail);
  // The refusal names the value sent, not a clamped one.
  request.set_page_size(4'294'967'295u);
  absl::StatusOr<CycleFilter> f = CycleFilterFromProto(request);
  ASSERT_EQ(f.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(f.status().message().rfind("page_size = 4294967295: must be in [0, 1000]", 0), 0u)
      << f.status();
  // A verdict number the API does not define is refused, not read as "any verdict".
  request.set_page_size(0);
  request.set_verdict(static_cast<v1::Verdict>(99));
  f = CycleFilterFromProto(request);
  ASSERT_EQ(f.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(f.status().message().rfind("verdict = 99: not a verdict", 0), 0u) << f.status();
  EXPECT_EQ(*ParseCycleId("42"), 42);
  for (const char* bad : {"", "0", "-3", "x1", "99999999999999999999"}) {
    EXPECT_EQ(ParseCycleId(bad).status().code(), absl::StatusCode::kInvalidArgument) << bad;
  }
}

}  // namespace
}  // namespace linecal

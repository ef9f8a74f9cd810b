#pragma once
// The gRPC face of the station core (proto/linecal/v1/station.proto): thin handlers that
// check credentials, translate messages and map absl::Status codes to gRPC's; the work is in
// StationCore.
//
// Authentication: the port may be mutual TLS (StartServer); with a non-empty token, every call must
// carry the metadata "authorization: Bearer <token>", else UNAUTHENTICATED. Cycle ids are the
// store's integer ids in decimal; a malformed one is INVALID_ARGUMENT naming cycle_id, an unknown
// one NOT_FOUND.

#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>

#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "daemon/core/daemon_config.h"
#include "daemon/core/station_core.h"
#include "daemon/service/reflection_service.h"
#include "linecal/v1/station.grpc.pb.h"

namespace linecal {

// The handlers' translations, pure functions (the request fuzzer drives them with the core's
// ValidateCycleRequest and the store's filter checks).
// StartCycleRequest to the core's request (degrees to radians); InvalidArgument only for a
// frames_per_sensor too large for an int; the core validates the rest.
absl::StatusOr<CycleRequest> CycleRequestFromProto(const v1::StartCycleRequest& request);
// ListCyclesRequest to the store's filter: verdict UNSPECIFIED means any, page size 0 the
// default 50. InvalidArgument naming the field and the value sent for a verdict number the
// API does not define ("verdict = 99: ...") and a page size beyond kMaxPageSize
// ("page_size = 4294967295: ...").
inline constexpr uint32_t kMaxPageSize = 1000;  // the store's largest page
absl::StatusOr<CycleFilter> CycleFilterFromProto(const v1::ListCyclesRequest& request);

class StationService final : public v1::Station::Service {
 public:
  // `core` must outlive the service.
  StationService(StationCore* core, std::string auth_token, std::string version);

  grpc::Status StartCycle(grpc::ServerContext* context, const v1::StartCycleRequest* request,
                          v1::StartCycleResponse* response) override;
  grpc::Status WatchCycle(grpc::ServerContext* context, const v1::WatchCycleRequest* request,
                          grpc::ServerWriter<v1::CycleEvent>* writer) override;
  grpc::Status GetCycle(grpc::ServerContext* context, const v1::GetCycleRequest* request,
                        v1::Cycle* response) override;
  grpc::Status ListCycles(grpc::ServerContext* context, const v1::ListCyclesRequest* request,
                          v1::ListCyclesResponse* response) override;
  grpc::Status CancelCycle(grpc::ServerContext* context, const v1::CancelCycleRequest* request,
                           v1::CancelCycleResponse* response) override;
  grpc::Status GetStationStatus(grpc::ServerContext* context,
                                const v1::GetStationStatusRequest* request,
                                v1::StationStatus* response) override;

  // OK when the call carries the token (or none is configured), else UNAUTHENTICATED; the
  // reflection service asks it too.
  grpc::Status Authorize(const grpc::ServerContext& context) const;

 private:
  StationCore* core_;
  std::string auth_token_;
  std::string version_;
};

// A started server: listening on `address` ("127.0.0.1:0" picks a free port), with the
// standard health service (no token needed) and server reflection (the token needed, as for
// every Station call) on the same port. Without `tls` the port is insecure; with it, TLS
// with the credentials of ServerTlsCredentials (tls_credentials.h),
// whose errors (a bad file, a key that does not match the certificate) are returned as they
// are; the token, when set, is required on top. An address CheckListenAddress (daemon_config.h)
// refuses is its InvalidArgument. The health service's answer follows StationCore::Health: SERVING
// while the station can run and store cycles, NOT_SERVING (for every service name) while the disk
// is full or the data root is gone. Polled every kHealthPollInterval on its own thread, which also
// stores a cycle's end that a full disk held back as soon as space returns.
inline constexpr std::chrono::milliseconds kHealthPollInterval{250};
class HealthMonitor {
 public:
  // `core` and `health` must outlive the monitor.
  HealthMonitor(StationCore* core, grpc::HealthCheckServiceInterface* health);
  ~HealthMonitor();
  HealthMonitor(const HealthMonitor&) = delete;
  HealthMonitor& operator=(const HealthMonitor&) = delete;

 private:
  std::mutex mutex_;
  std::condition_variable stop_changed_;
  bool stop_ = false;
  std::thread thread_;
};

struct RunningServer {
  RunningServer() = default;
  RunningServer(RunningServer&&) = default;
  // The monitor goes first, then the server, then what the server uses (in assignment too).
  RunningServer& operator=(RunningServer&& other) {
    health.reset();
    server = std::move(other.server);
    service = std::move(other.service);
    reflection = std::move(other.reflection);
    health = std::move(other.health);
    port = other.port;
    return *this;
  }
  ~RunningServer() { health.reset(); }

  std::unique_ptr<StationService> service;
  std::unique_ptr<ReflectionService> reflection;  // behind the same token
  std::unique_ptr<grpc::Server> server;           // destroyed before the two above
  std::unique_ptr<HealthMonitor> health;          // destroyed first: it sets the server's health
  int port = 0;
};
absl::StatusOr<RunningServer> StartServer(StationCore* core, const std::string& address,
                                          const std::string& auth_token, const std::string& version,
                                          const std::optional<TlsConfig>& tls = std::nullopt);

}  // namespace linecal

#include "daemon/service/station_service.h"

#include <grpcpp/health_check_service_interface.h>

#include <numbers>

#include "absl/strings/str_cat.h"
#include "daemon/service/reflection_service.h"
#include "daemon/service/tls_credentials.h"

namespace linecal {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

grpc::Status ToGrpc(const absl::Status& s) {
  if (s.ok()) return grpc::Status::OK;
  grpc::StatusCode code = grpc::StatusCode::INTERNAL;
  switch (s.code()) {
    case absl::StatusCode::kInvalidArgument:
      code = grpc::StatusCode::INVALID_ARGUMENT;
      break;
    case absl::StatusCode::kNotFound:
      code = grpc::StatusCode::NOT_FOUND;
      break;
    case absl::StatusCode::kFailedPrecondition:
      code = grpc::StatusCode::FAILED_PRECONDITION;
      break;
    case absl::StatusCode::kUnavailable:
      code = grpc::StatusCode::UNAVAILABLE;
      break;
    case absl::StatusCode::kCancelled:
      code = grpc::StatusCode::CANCELLED;
      break;
    case absl::StatusCode::kDataLoss:
      code = grpc::StatusCode::DATA_LOSS;
      break;
    // The disk is full: StartCycle works again once space returns.
    case absl::StatusCode::kResourceExhausted:
      code = grpc::StatusCode::RESOURCE_EXHAUSTED;
      break;
    default:
      break;
  }
  return grpc::Status(code, std::string(s.message()));
}

// The one mapping of the station's verdict (station/model/verdict.h) to the API's, both ways
// (CycleFilterFromProto inverts it); none (a running cycle) is VERDICT_UNSPECIFIED.
v1::Verdict ToProto(std::optional<Verdict> v) {
  if (!v) return v1::VERDICT_UNSPECIFIED;
  switch (*v) {
    case Verdict::kPass:
      return v1::VERDICT_PASS;
    case Verdict::kFail:
      return v1::VERDICT_FAIL;
    case Verdict::kError:
      return v1::VERDICT_ERROR;
  }
  return v1::VERDICT_UNSPECIFIED;
}

v1::CycleState ToProto(CycleState s) {
  switch (s) {
    case CycleState::kRunning:
      return v1::CYCLE_STATE_RUNNING;
    case CycleState::kDone:
      return v1::CYCLE_STATE_DONE;
    case CycleState::kCancelled:
      return v1::CYCLE_STATE_CANCELLED;
    case CycleState::kAborted:
      return v1::CYCLE_STATE_ABORTED;
  }
  return v1::CYCLE_STATE_UNSPECIFIED;
}

v1::SensorKind KindToProto(SensorKind kind) {
  switch (kind) {
    case SensorKind::kCamera:
      return v1::SENSOR_KIND_CAMERA;
    case SensorKind::kLidar:
      return v1::SENSOR_KIND_LIDAR;
    case SensorKind::kRadar:
      return v1::SENSOR_KIND_RADAR;
  }
  return v1::SENSOR_KIND_UNSPECIFIED;
}

v1::CycleEvent::Type EventToProto(EventType type) {
  switch (type) {
    case EventType::kStarted:
      return v1::CycleEvent::TYPE_STARTED;
    case EventType::kSensorAcquired:
      return v1::CycleEvent::TYPE_SENSOR_ACQUIRED;
    case EventType::kBoardFound:
      return v1::CycleEvent::TYPE_BOARD_FOUND;
    case EventType::kSensorSolved:
      return v1::CycleEvent::TYPE_SENSOR_SOLVED;
    case EventType::kSensorVerdict:
      return v1::CycleEvent::TYPE_SENSOR_VERDICT;
    case EventType::kCycleEnded:
      return v1::CycleEvent::TYPE_CYCLE_ENDED;
    case EventType::kSensorError:
      return v1::CycleEvent::TYPE_SENSOR_ERROR;
    case EventType::kSensorProgress:
      return v1::CycleEvent::TYPE_SENSOR_PROGRESS;
  }
  return v1::CycleEvent::TYPE_UNSPECIFIED;
}

void Fill(const MountingValues& m, v1::MountingAngles* out) {
  out->set_yaw_deg(m.yaw_deg);
  out->set_pitch_deg(m.pitch_deg);
  out->set_roll_deg(m.roll_deg);
  out->set_x_m(m.x_m);
  out->set_y_m(m.y_m);
  out->set_z_m(m.z_m);
}

void Fill(const StoredCycle& c, bool with_sensors, v1::Cycle* out) {
  out->set_cycle_id(std::to_string(c.id));
  out->set_vin(c.vin);
  out->set_car_model_id(c.car_model_id);
  out->set_state(ToProto(c.state));
  out->set_verdict(ToProto(c.verdict));
  out->set_reason(c.reason);
  out->set_started_ns(c.started_ns);
  out->set_ended_ns(c.ended_ns);
  out->set_capture_path(c.capture_path);
  if (!with_sensors) return;
  for (const StoredSensorResult& s : c.sensors) {
    v1::SensorResult* r = out->add_sensors();
    r->set_name(s.sensor);
    r->set_kind(KindToProto(s.kind));
    r->set_verdict(ToProto(s.verdict));
    r->set_reason(s.reason);
    r->set_message(s.message);
    for (double v : s.T_car_sensor) r->mutable_t_car_sensor()->add_m(v);
    Fill(s.measured, r->mutable_mounting());
    Fill(s.deviation, r->mutable_deviation());
    Fill(s.sigma, r->mutable_uncertainty());
    r->set_residual_rms(s.residual_rms);
    r->set_features_used(static_cast<uint32_t>(s.features_used));
    if (s.vanishing_point_u_px && s.vanishing_point_v_px) {
      r->set_vanishing_point_u_px(*s.vanishing_point_u_px);
      r->set_vanishing_point_v_px(*s.vanishing_point_v_px);
    }
    for (double v : s.ground_homography) r->add_ground_homography(v);
  }
}

}  // namespace

absl::StatusOr<CycleRequest> CycleRequestFromProto(const v1::StartCycleRequest& request) {
  CycleRequest r;
  r.vin = request.vin();
  r.car_model_id = request.car_model_id();
  r.aligner.longitudinal_offset_m = request.aligner().longitudinal_offset_m();
  r.aligner.lateral_offset_m = request.aligner().lateral_offset_m();
  r.aligner.thrust_angle_rad = request.aligner().thrust_angle_deg() * kDegToRad;
  r.record_capture = request.options().record_capture();
  // The core checks the range; a uint32 beyond it must not wrap into one that passes.
  if (request.options().frames_per_sensor() > 1000) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.frames_per_sensor = ", request.options().frames_per_sensor(),
                     ": must be in [0, 100]"));
  }
  r.frames_per_sensor = static_cast<int>(request.options().frames_per_sensor());
  return r;
}

absl::StatusOr<CycleFilter> CycleFilterFromProto(const v1::ListCyclesRequest& request) {
  CycleFilter f;
  f.vin = request.vin();
  f.since_ns = request.since_ns();
  f.until_ns = request.until_ns();
  for (Verdict v : {Verdict::kPass, Verdict::kFail, Verdict::kError}) {
    if (ToProto(v) == request.verdict()) f.verdict = v;
  }
  if (!f.verdict && request.verdict() != v1::VERDICT_UNSPECIFIED) {
    // proto3 keeps unknown enum numbers: ignoring one would list every cycle.
    return absl::InvalidArgumentError(
        absl::StrCat("verdict = ", static_cast<int>(request.verdict()),
                     ": not a verdict (0 any, 1 pass, 2 fail, 3 error)"));
  }
  // Checked here on the uint32 the client sent, so that the message names that value; the
  // store's own check (1..1000) then holds by construction.
  if (request.page_size() > kMaxPageSize) {
    return absl::InvalidArgumentError(absl::StrCat("page_size = ", request.page_size(),
                                                   ": must be in [0, ", kMaxPageSize,
                                                   "] (0: the default 50)"));
  }
  f.page_size = request.page_size() == 0 ? 50 : static_cast<int>(request.page_size());
  f.page_token = request.page_token();
  return f;
}

StationService::StationService(StationCore* core, std::string auth_token, std::string version)
    : core_(core), auth_token_(std::move(auth_token)), version_(std::move(version)) {}

grpc::Status StationService::Authorize(const grpc::ServerContext& context) const {
  if (auth_token_.empty()) return grpc::Status::OK;
  const auto& metadata = context.client_metadata();
  const auto it = metadata.find("authorization");
  if (it == metadata.end() ||
      std::string(it->second.data(), it->second.size()) != "Bearer " + auth_token_) {
    return grpc::Status(grpc::StatusCode::UNAUTHENTICATED,
                        "authorization: a valid bearer token is required");
  }
  return grpc::Status::OK;
}

grpc::Status StationService::StartCycle(grpc::ServerContext* context,
                                        const v1::StartCycleRequest* request,
                                        v1::StartCycleResponse* response) {
  if (grpc::Status auth = Authorize(*context); !auth.ok()) return auth;
  absl::StatusOr<CycleRequest> r = CycleRequestFromProto(*request);
  if (!r.ok()) return ToGrpc(r.status());
  absl::StatusOr<int64_t> id = core_->StartCycle(*r);
  if (!id.ok()) return ToGrpc(id.status());
  response->set_cycle_id(std::to_string(*id));
  return grpc::Status::OK;
}

grpc::Status StationService::WatchCycle(grpc::ServerContext* context,
                                        const v1::WatchCycleRequest* request,
                                        grpc::ServerWriter<v1::CycleEvent>* writer) {
  if (grpc::Status auth = Authorize(*context); !auth.ok()) return auth;
  absl::StatusOr<int64_t> id = ParseCycleId(request->cycle_id());
  if (!id.ok()) return ToGrpc(id.status());
  return ToGrpc(core_->WatchCycle(*id, [&](const StoredEvent& e) {
    if (context->IsCancelled()) return false;
    v1::CycleEvent event;
    event.set_cycle_id(request->cycle_id());
    event.set_sequence(static_cast<uint64_t>(e.sequence));
    event.set_time_ns(e.time_ns);
    event.set_type(EventToProto(e.type));
    event.set_sensor(e.sensor);
    event.set_detail(e.detail);
    event.set_verdict(ToProto(e.verdict));
    return writer->Write(event);
  }));
}

grpc::Status StationService::GetCycle(grpc::ServerContext* context,
                                      const v1::GetCycleRequest* request, v1::Cycle* response) {
  if (grpc::Status auth = Authorize(*context); !auth.ok()) return auth;
  absl::StatusOr<int64_t> id = ParseCycleId(request->cycle_id());
  if (!id.ok()) return ToGrpc(id.status());
  absl::StatusOr<StoredCycle> cycle = core_->GetCycle(*id);
  if (!cycle.ok()) return ToGrpc(cycle.status());
  Fill(*cycle, true, response);
  return grpc::Status::OK;
}

grpc::Status StationService::ListCycles(grpc::ServerContext* context,
                                        const v1::ListCyclesRequest* request,
                                        v1::ListCyclesResponse* response) {
  if (grpc::Status auth = Authorize(*context); !auth.ok()) return auth;
  absl::StatusOr<CycleFilter> filter = CycleFilterFromProto(*request);
  if (!filter.ok()) return ToGrpc(filter.status());
  absl::StatusOr<CyclePage> page = core_->ListCycles(*filter);
  if (!page.ok()) return ToGrpc(page.status());
  for (const StoredCycle& c : page->cycles) Fill(c, false, response->add_cycles());
  response->set_next_page_token(page->next_page_token);
  return grpc::Status::OK;
}

grpc::Status StationService::CancelCycle(grpc::ServerContext* context,
                                         const v1::CancelCycleRequest* request,
                                         v1::CancelCycleResponse* response) {
  if (grpc::Status auth = Authorize(*context); !auth.ok()) return auth;
  absl::StatusOr<int64_t> id = ParseCycleId(request->cycle_id());
  if (!id.ok()) return ToGrpc(id.status());
  if (absl::Status s = core_->CancelCycle(*id); !s.ok()) return ToGrpc(s);
  response->set_state(v1::CYCLE_STATE_RUNNING);  // it stops at its next step
  return grpc::Status::OK;
}

grpc::Status StationService::GetStationStatus(grpc::ServerContext* context,
                                              const v1::GetStationStatusRequest*,
                                              v1::StationStatus* response) {
  if (grpc::Status auth = Authorize(*context); !auth.ok()) return auth;
  const StationStatusInfo s = core_->Status();
  response->set_version(version_);
  response->set_station_id(s.station_id);
  for (const std::string& c : s.car_models) response->add_car_models(c);
  if (s.running_cycle) response->set_running_cycle_id(std::to_string(*s.running_cycle));
  response->set_database_path(s.database_path);
  response->set_disk_free_bytes(s.disk_free_bytes);
  for (const TargetAlarm& a : s.target_alarms) {
    v1::TargetAlarm* alarm = response->add_target_alarms();
    alarm->set_car_model(a.car_model);
    for (const std::string& t : a.targets) alarm->add_targets(t);
    for (const ShiftedSensor& x : a.sensors) {
      v1::ShiftedSensor* sensor = alarm->add_sensors();
      sensor->set_sensor(x.sensor);
      sensor->set_baseline_residual(x.baseline_residual);
      sensor->set_recent_residual(x.recent_residual);
      sensor->set_shift_sigmas(x.shift_sigmas);
    }
    alarm->set_since_cycle_id(std::to_string(a.since_cycle));
    alarm->set_last_cycle_id(std::to_string(a.last_cycle));
    alarm->set_statistic_sigmas(a.statistic_sigmas);
    alarm->set_alarm_sigmas(a.alarm_sigmas);
  }
  if (s.plant) {
    v1::PlantForwarding* plant = response->mutable_plant();
    plant->set_backlog(s.plant->backlog);
    plant->set_oldest_unshipped_age_ns(s.plant->oldest_unshipped_age.count());
    plant->set_last_error(std::string(s.plant->last_error.message()));
    plant->set_shipped(s.plant->shipped);
    plant->set_max_backlog_age_ns(
        std::chrono::duration_cast<std::chrono::nanoseconds>(s.plant_max_backlog_age).count());
  }
  for (const auto& [name, kind] : s.sensors) {
    v1::SensorStatus* sensor = response->add_sensors();
    sensor->set_name(name);
    sensor->set_kind(KindToProto(kind));
    sensor->set_source(s.SourceOf(name));
    // The simulator and a recorded capture are always there; live devices are not probed
    // here (they are opened at each cycle, where a missing one is that sensor's error).
    sensor->set_connected(true);
  }
  return grpc::Status::OK;
}

absl::StatusOr<RunningServer> StartServer(StationCore* core, const std::string& address,
                                          const std::string& auth_token, const std::string& version,
                                          const std::optional<TlsConfig>& tls) {
  if (absl::Status s = CheckListenAddress(address); !s.ok()) return s;
  std::shared_ptr<grpc::ServerCredentials> credentials = grpc::InsecureServerCredentials();
  if (tls) {
    absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> secure = ServerTlsCredentials(*tls);
    if (!secure.ok()) return secure.status();
    credentials = *std::move(secure);
  }
  grpc::EnableDefaultHealthCheckService(true);
  RunningServer running;
  running.service = std::make_unique<StationService>(core, auth_token, version);
  // Reflection asks the Station service's Authorize; the health service stays without the
  // token: load balancers and probes have none.
  running.reflection = std::make_unique<ReflectionService>(
      [service = running.service.get()](const grpc::ServerContext& context) {
        return service->Authorize(context);
      },
      std::vector<std::string>{v1::Station::service_full_name(), "grpc.health.v1.Health",
                               grpc::reflection::v1alpha::ServerReflection::service_full_name()});
  grpc::ServerBuilder builder;
  // gRPC sets SO_REUSEPORT by default: a second linecald on the same port would start without
  // error and the kernel would split the station controller's calls between the two.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.AddListeningPort(address, credentials, &running.port);
  builder.RegisterService(running.service.get());
  builder.RegisterService(running.reflection.get());
  running.server = builder.BuildAndStart();
  if (!running.server || running.port == 0) {
    return absl::UnavailableError(absl::StrCat("listen: cannot listen on '", address, "'"));
  }
  running.health = std::make_unique<HealthMonitor>(core, running.server->GetHealthCheckService());
  return running;
}

HealthMonitor::HealthMonitor(StationCore* core, grpc::HealthCheckServiceInterface* health) {
  thread_ = std::thread([this, core, health] {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!stop_) {
      lock.unlock();
      health->SetServingStatus(core->Health().ok());
      lock.lock();
      stop_changed_.wait_for(lock, kHealthPollInterval, [this] { return stop_; });
    }
  });
}

HealthMonitor::~HealthMonitor() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  stop_changed_.notify_all();
  thread_.join();
}

}  // namespace linecal

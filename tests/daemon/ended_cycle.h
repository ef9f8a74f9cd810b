#pragma once
// A cycle ended in a station store the way StationCore ends one: begun, a started event, one
// camera result, a cycle_ended event, then EndCycle (which queues it in the outbox when the
// store keeps one). For the outbox and forwarder tests and benchmarks.

#include <cstdint>
#include <string>

#include "daemon/store/store.h"

namespace linecal::testing_daemon {

// Returns the cycle's id; a store error aborts the calling test's expectations (the cycle
// id is then 0). Cost: five fsynced commits.
inline int64_t EndCycleInStore(Store& store, int64_t started_ns, int64_t ended_ns,
                               const std::string& vin = "WVWZZZ1JZXW000001") {
  StoredCycle c;
  c.vin = vin;
  c.car_model_id = "reference";
  c.started_ns = started_ns;
  c.request_json = "{}";
  const absl::StatusOr<int64_t> id = store.BeginCycle(c);
  if (!id.ok()) return 0;
  StoredSensorResult r;
  r.sensor = "front_camera";
  r.kind = SensorKind::kCamera;
  r.verdict = Verdict::kPass;
  r.T_car_sensor = {1, 0, 0, 3.7, 0, 1, 0, 0, 0, 0, 1, 0.5, 0, 0, 0, 1};
  r.sigma.yaw_deg = 0.01;
  const bool stored =
      store.AppendEvent({*id, 0, started_ns, EventType::kStarted, "", "", std::nullopt}).ok() &&
      store.PutSensorResult(*id, r).ok() &&
      store.AppendEvent({*id, 0, ended_ns, EventType::kCycleEnded, "", "", Verdict::kPass}).ok() &&
      store.EndCycle(*id, CycleState::kDone, Verdict::kPass, "", ended_ns).ok();
  return stored ? *id : 0;
}

}  // namespace linecal::testing_daemon

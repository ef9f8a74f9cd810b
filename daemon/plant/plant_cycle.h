#pragma once
// One ended cycle as the station forwards it to the plant database (docs/plant.md): the
// cycle with its per-sensor results and its events, exactly as the station's store keeps
// them. The station's outbox (daemon/store) names the cycles to ship; the forwarder
// (daemon/plant/forwarder.h) reads them from the store into this form and the plant client
// (daemon/plant/plant_db.h) applies them, keyed by station id + cycle id.

#include <vector>

#include "daemon/store/store.h"

namespace linecal {

struct PlantCycle {
  StoredCycle cycle;                // ended (state != kRunning), with its sensors
  std::vector<StoredEvent> events;  // in sequence order
};

}  // namespace linecal

// Fuzzes what linecald does with an API request before any work starts: the handlers'
// translations (daemon/service) and the core's validation (daemon/core), and the store's
// checks of list filters and ids on a real SQLite file. Input byte 0 picks the request, the
// rest is its protobuf wire encoding: 0 StartCycleRequest (bit 4 of byte 0: check digit on),
// 1 ListCyclesRequest, 2 GetCycleRequest. Invariants: no crash; every refusal is
// InvalidArgument (NotFound for an unknown id) and names the field it refuses.
#include <google/protobuf/stubs/logging.h>
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/match.h"
#include "daemon/core/station_core.h"
#include "daemon/service/station_service.h"
#include "daemon/store/store.h"
#include "linecal/v1/station.pb.h"
#include "station/model/car_model.h"

namespace {

namespace fs = std::filesystem;

const std::vector<linecal::CarModel>& Cars() {
  static const std::vector<linecal::CarModel> cars = {
      *linecal::ReadCarModel(LINECAL_SOURCE_DIR "/deploy/cars/reference.json")};
  return cars;
}

// A store with two ended cycles, on a scratch file of this process.
linecal::Store& TheStore() {
  static const std::unique_ptr<linecal::Store> store = [] {
    const fs::path dir =
        fs::is_directory("/dev/shm") ? fs::path("/dev/shm") : fs::temp_directory_path();
    const fs::path path = dir / ("linecal_request_fuzz_" + std::to_string(getpid()) + ".db");
    fs::remove(path);
    std::unique_ptr<linecal::Store> s = *linecal::Store::Open(path.string());
    for (int i = 0; i < 2; ++i) {
      linecal::StoredCycle c;
      c.vin = "1M8GDM9AXKP04278" + std::to_string(i);
      c.car_model_id = "reference";
      c.started_ns = 1'700'000'000'000'000'000 + i;
      const int64_t id = *s->BeginCycle(c);
      (void)s->EndCycle(id, linecal::CycleState::kDone, linecal::Verdict::kPass, "",
                        c.started_ns + 1);
    }
    return s;
  }();
  return *store;
}

void ExpectRefusal(const absl::Status& s, const std::vector<const char*>& fields) {
  if (s.ok()) return;
  if (s.code() != absl::StatusCode::kInvalidArgument && s.code() != absl::StatusCode::kNotFound) {
    __builtin_trap();
  }
  for (const char* f : fields) {
    if (absl::StrContains(s.message(), f)) return;
  }
  __builtin_trap();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // Invalid UTF-8 in a string field is a parse failure, logged by protobuf on every input.
  static const bool quiet = (google::protobuf::SetLogHandler(nullptr), true);
  (void)quiet;
  if (size == 0) return 0;
  const int kind = data[0] % 3;
  const void* body = data + 1;
  const int body_size = static_cast<int>(size - 1);
  if (kind == 0) {
    linecal::v1::StartCycleRequest request;
    if (!request.ParseFromArray(body, body_size)) return 0;
    absl::StatusOr<linecal::CycleRequest> r = linecal::CycleRequestFromProto(request);
    if (!r.ok()) {
      ExpectRefusal(r.status(), {"options.frames_per_sensor"});
      return 0;
    }
    ExpectRefusal(linecal::ValidateCycleRequest(*r, Cars(), (data[0] & 16) != 0),
                  {"vin", "car_model_id", "aligner.", "options.frames_per_sensor"});
  } else if (kind == 1) {
    linecal::v1::ListCyclesRequest request;
    if (!request.ParseFromArray(body, body_size)) return 0;
    absl::StatusOr<linecal::CycleFilter> filter = linecal::CycleFilterFromProto(request);
    if (!filter.ok()) {
      ExpectRefusal(filter.status(), {"page_size", "verdict"});
      return 0;
    }
    absl::StatusOr<linecal::CyclePage> page = TheStore().ListCycles(*filter);
    ExpectRefusal(page.status(), {"page_size", "page_token", "since_ns", "until_ns", "vin"});
    if (page.ok() && page->cycles.size() > 2) __builtin_trap();
  } else {
    linecal::v1::GetCycleRequest request;
    if (!request.ParseFromArray(body, body_size)) return 0;
    absl::StatusOr<int64_t> id = linecal::ParseCycleId(request.cycle_id());
    if (!id.ok()) {
      ExpectRefusal(id.status(), {"cycle_id"});
      return 0;
    }
    ExpectRefusal(TheStore().GetCycle(*id).status(), {"cycle"});
  }
  return 0;
}

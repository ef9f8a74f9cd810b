#pragma once
// The console's write actions (docs/console.md, "Operator actions"): what a POST must carry
// to be taken, and the start request's JSON. The handlers then call the same StationCore
// calls as gRPC's StartCycle and CancelCycle.

#include <string>

#include "absl/status/statusor.h"
#include "daemon/core/station_core.h"

namespace linecal {

// The header every console POST that changes the station must carry, with this value. A
// page of another site cannot send it: a form cannot set headers, and a script's request
// with a custom header needs a CORS preflight that linecald never grants.
inline constexpr char kActionHeader[] = "X-Linecal-Action";
inline constexpr char kActionHeaderValue[] = "1";

// The cross-site request check of a write action (the cookie is SameSite=Strict besides):
// `action_header` must be kActionHeaderValue, and `origin`, when the browser sent one, must
// be this server's own ("http://" or "https://" per `tls`, then `host`, the Host header).
// PermissionDenied saying which check failed. Pure.
absl::Status CheckSameSiteAction(const std::string& action_header, const std::string& origin,
                                 const std::string& host, bool tls);

// The body of POST /api/cycles: {"vin", "car_model_id", "aligner": {"longitudinal_offset_m",
// "lateral_offset_m", "thrust_angle_deg"} (optional, zeros), "record_capture" (optional,
// false), "frames_per_sensor" (optional, 0: the station's)}. InvalidArgument naming the field
// for bad JSON, a missing or mistyped field or an unknown key; StationCore::StartCycle
// validates the values. Pure.
absl::StatusOr<CycleRequest> CycleRequestFromJson(const std::string& body);

}  // namespace linecal

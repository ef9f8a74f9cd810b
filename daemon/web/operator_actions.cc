#include "daemon/web/operator_actions.h"

#include <limits>

#include "absl/strings/str_cat.h"
#include "station/io/json_reader.h"

namespace linecal {

absl::Status CheckSameSiteAction(const std::string& action_header, const std::string& origin,
                                 const std::string& host, bool tls) {
  if (action_header != kActionHeaderValue) {
    return absl::PermissionDeniedError(absl::StrCat("csrf: the request lacks the header ",
                                                    kActionHeader, ": ", kActionHeaderValue,
                                                    " that the console's pages send"));
  }
  if (!origin.empty() && origin != absl::StrCat(tls ? "https://" : "http://", host)) {
    return absl::PermissionDeniedError(
        absl::StrCat("csrf: Origin ", QuoteInput(origin), " is not this console's"));
  }
  return absl::OkStatus();
}

absl::StatusOr<CycleRequest> CycleRequestFromJson(const std::string& body) {
  absl::StatusOr<JsonDocument> doc = JsonDocument::FromText(body, "request");
  if (!doc.ok()) return absl::InvalidArgumentError(doc.status().message());
  absl::StatusOr<JsonField> root = doc->Root();
  if (!root.ok()) return absl::InvalidArgumentError(root.status().message());
  if (absl::Status s = root->AllowOnlyKeys(
          {"vin", "car_model_id", "aligner", "record_capture", "frames_per_sensor"});
      !s.ok()) {
    return s;
  }
  CycleRequest r;
  absl::StatusOr<std::string> vin = root->String("vin");
  if (!vin.ok()) return vin.status();
  r.vin = *vin;
  absl::StatusOr<std::string> car = root->String("car_model_id");
  if (!car.ok()) return car.status();
  r.car_model_id = *car;
  if (root->Has("aligner")) {
    absl::StatusOr<AlignerMeasurement> aligner = ReadAligner(*root, "aligner");
    if (!aligner.ok()) return aligner.status();
    r.aligner = *aligner;
  }
  absl::StatusOr<bool> record = root->BoolOr("record_capture", false);
  if (!record.ok()) return record.status();
  r.record_capture = *record;
  absl::StatusOr<std::int64_t> frames = root->IntegerOr("frames_per_sensor", 0);
  if (!frames.ok()) return frames.status();
  // StartCycle checks [0, 100]; only what fits an int reaches it unchanged.
  if (*frames < 0 || *frames > std::numeric_limits<int>::max()) {
    return root->Error("frames_per_sensor", absl::StrCat(*frames, ": must be in [0, 100]"));
  }
  r.frames_per_sensor = static_cast<int>(*frames);
  return r;
}

}  // namespace linecal

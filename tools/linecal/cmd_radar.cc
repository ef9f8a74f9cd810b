// linecal radar decode: radar detections from a recorded candump log (docs/interfaces.md).
#include <cstdio>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>

#include "absl/strings/str_cat.h"
#include "station/io/candump.h"
#include "station/sensors/radar/radar_decoder.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "radar decode";
constexpr double kDegPerRad = 180.0 / std::numbers::pi;

// Reads a two-valued option into *flag (first value → true). Empty optional on success,
// otherwise the exit code after printing the problem.
std::optional<int> ChoiceOption(const cli::CommandLine& cl, const std::string& name,
                                const std::string& if_true, const std::string& if_false,
                                bool* flag) {
  if (!cl.Has(name)) return std::nullopt;
  const std::string value = cl.Get(name);
  if (value == if_true || value == if_false) {
    *flag = value == if_true;
    return std::nullopt;
  }
  return cli::BadInput(kCommand, absl::StrCat("--", name, ": '", value, "' is neither ", if_true,
                                              " nor ", if_false));
}

int64_t Nanoseconds(CanTime t) { return t.time_since_epoch().count(); }

nlohmann::json DetectionJson(const RadarCycle& cycle, const RadarDetection& d) {
  nlohmann::json j = {{"t_ns", Nanoseconds(cycle.time)},
                      {"sensor_id", cycle.sensor_id},
                      {"kind", RadarDetectionKindName(d.kind)},
                      {"cycle", cycle.counter},
                      {"id", d.id},
                      {"range_m", d.range_m},
                      {"azimuth_deg", d.azimuth_rad * kDegPerRad},
                      {"range_rate_mps", d.range_rate_mps},
                      {"x_m", d.x_m()},
                      {"y_m", d.y_m()}};
  if (d.rcs_dbsm) j["rcs_dbsm"] = *d.rcs_dbsm;
  if (d.cluster_quality) {
    const Ars408ClusterQuality& q = *d.cluster_quality;
    j["quality"] = {{"dist_long_rms", q.dist_long_rms},
                    {"dist_lat_rms", q.dist_lat_rms},
                    {"pdh0", q.pdh0},
                    {"ambig_state", q.ambig_state},
                    {"invalid_state", q.invalid_state}};
  }
  return j;
}

std::string Summary(const std::string& log, const RadarDecodeStats& s) {
  std::string skipped;
  for (int r = 0; r < static_cast<int>(RadarSkipReason::kCount); ++r) {
    if (s.skipped[r] == 0) continue;
    absl::StrAppend(&skipped, skipped.empty() ? "" : ", ",
                    RadarSkipReasonName(static_cast<RadarSkipReason>(r)), " ", s.skipped[r]);
  }
  return absl::StrCat("linecal ", kCommand, ": ", log, ": ", s.frames_read, " frames read, ",
                      s.frames_decoded, " decoded, ", s.skipped_total(), " skipped",
                      skipped.empty() ? "" : absl::StrCat(" (", skipped, ")"), "; ", s.cycles,
                      " cycles (", s.incomplete_cycles, " incomplete), ", s.detections,
                      " detections");
}

}  // namespace

int RunRadarDecode(const Args& args) {
  cli::CommandLine cl(
      "linecal radar decode --model ars408|esr --log FILE [--json] "
      "[--ars408-counter big|little] [--ars408-object-lat left|right] "
      "[--esr-angle clockwise|counterclockwise]",
      "Decodes a candump -l log of an ARS408-21 (cluster and object lists) or a Delphi ESR "
      "(tracks) into detections in the radar frame (x boresight, y left; azimuth counter-"
      "clockwise). Prints a table, or with --json one JSON object per detection per line "
      "(t_ns of the cycle's status frame, id, range_m, azimuth_deg, rcs_dbsm where known, "
      "range_rate_mps, ...). A summary (frames read, skipped with reasons) goes to stderr. "
      "Exit 0 when detections were decoded, 1 when none, 2 on bad usage or input.",
      {{"model", "ars408|esr", "radar model", true},
       {"log", "FILE", "can-utils candump -l log", true},
       {"json", "", "one JSON object per detection per line"},
       {"ars408-counter", "big|little", "byte order of MeasCounter (default big, as the DBC)"},
       {"ars408-object-lat", "left|right",
        "direction of positive object DistLat (default left, as clusters)"},
       {"esr-angle", "clockwise|counterclockwise",
        "direction of positive ESR track angle (default clockwise)"}});
  if (const std::optional<int> exit = cli::ParseOrExit(cl, kCommand, args)) return *exit;

  const std::optional<RadarModel> model = ParseRadarModel(cl.Get("model"));
  if (!model) {
    return cli::BadInput(
        kCommand, absl::StrCat("--model: unknown model '", cl.Get("model"), "' (ars408 or esr)"));
  }
  RadarConventions conventions;
  bool big_endian_counter = true;
  if (auto e = ChoiceOption(cl, "ars408-counter", "big", "little", &big_endian_counter)) return *e;
  conventions.ars408_counter_byte_order =
      big_endian_counter ? ByteOrder::kBigEndian : ByteOrder::kLittleEndian;
  if (auto e = ChoiceOption(cl, "ars408-object-lat", "left", "right",
                            &conventions.ars408_object_lat_left_positive)) {
    return *e;
  }
  if (auto e = ChoiceOption(cl, "esr-angle", "clockwise", "counterclockwise",
                            &conventions.esr_angle_clockwise_positive)) {
    return *e;
  }

  const std::string log = cl.Get("log");
  const absl::StatusOr<std::vector<CanFrame>> frames = ReadCandumpLog(log);
  if (!frames.ok()) return cli::BadInput(kCommand, std::string(frames.status().message()));
  const RadarDecodeResult result = DecodeRadarFrames(*frames, *model, conventions);

  const bool json = cl.Has("json");
  if (!json) {
    std::printf("%-20s %6s %-7s %6s %4s %9s %11s %14s %8s\n", "t_ns", "sensor", "kind", "cycle",
                "id", "range_m", "azimuth_deg", "range_rate_mps", "rcs_dbsm");
  }
  for (const RadarCycle& cycle : result.cycles) {
    for (const RadarDetection& d : cycle.detections) {
      if (json) {
        std::printf("%s\n", DetectionJson(cycle, d).dump().c_str());
        continue;
      }
      const std::string rcs = d.rcs_dbsm ? absl::StrCat(*d.rcs_dbsm) : "-";
      std::printf("%-20lld %6d %-7s %6u %4d %9.2f %11.2f %14.2f %8s\n",
                  static_cast<long long>(Nanoseconds(cycle.time)), cycle.sensor_id,
                  RadarDetectionKindName(d.kind), cycle.counter, d.id, d.range_m,
                  d.azimuth_rad * kDegPerRad, d.range_rate_mps, rcs.c_str());
    }
  }
  std::fprintf(stderr, "%s\n", Summary(log, result.stats).c_str());
  return result.stats.detections > 0 ? cli::kExitOk : cli::kExitNegative;
}

}  // namespace linecal::tools

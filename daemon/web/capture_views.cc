#include "daemon/web/capture_views.h"

#include <filesystem>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "station/pipeline/cycle_views.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

const char* ContentTypeOf(const std::string& path) {
  const std::string ext = fs::path(path).extension().string();
  if (ext == ".png") return "image/png";
  if (ext == ".json") return "application/json";
  if (ext == ".log" || ext == ".csv") return "text/plain; charset=utf-8";
  return "application/octet-stream";
}

// A non-negative decimal index below `size`, else InvalidArgument naming `what`.
absl::StatusOr<size_t> ParseIndex(const std::string& text, size_t size, const char* what) {
  size_t index = 0;
  if (!absl::SimpleAtoi(text, &index) || index >= size) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, " = ", QuoteInput(text), ": must be in [0, ", size, ")"));
  }
  return index;
}

}  // namespace

absl::StatusOr<nlohmann::json> CaptureViews::Files(int64_t cycle_id) {
  absl::StatusOr<Capture> capture = core_->CycleCapture(cycle_id);
  const std::string id = std::to_string(cycle_id);
  // Running, not kept or unreadable: the page says why there is nothing to show.
  if (absl::IsFailedPrecondition(capture.status())) {
    return nlohmann::json{
        {"cycle_id", id}, {"kept", false}, {"reason", capture.status().message()}};
  }
  if (!capture.ok()) return capture.status();
  nlohmann::json files = nlohmann::json::array();
  const std::vector<CaptureFileEntry> list = CaptureFileList(*capture);
  for (size_t i = 0; i < list.size(); ++i) {
    std::error_code ec;
    const std::uintmax_t bytes = fs::file_size(fs::path(capture->dir) / list[i].path, ec);
    files.push_back({{"index", i},
                     {"path", list[i].path},
                     {"sensor", list[i].sensor},
                     {"role", list[i].role},
                     {"bytes", ec ? 0 : bytes}});
  }
  return nlohmann::json{{"cycle_id", id}, {"kept", true}, {"files", std::move(files)}};
}

absl::StatusOr<CaptureFileToSend> CaptureViews::File(int64_t cycle_id, const std::string& index) {
  absl::StatusOr<Capture> capture = core_->CycleCapture(cycle_id);
  if (!capture.ok()) return capture.status();
  const std::vector<CaptureFileEntry> list = CaptureFileList(*capture);
  absl::StatusOr<size_t> i = ParseIndex(index, list.size(), "file");
  if (!i.ok()) return i.status();
  // ReadCapture checked every path of the list inside the capture, links resolved.
  CaptureFileToSend out;
  out.path = (fs::path(capture->dir) / list[*i].path).string();
  std::error_code ec;
  out.bytes = fs::file_size(out.path, ec);
  if (ec) return absl::NotFoundError(absl::StrCat("file ", *i, ": ", ec.message()));
  out.content_type = ContentTypeOf(list[*i].path);
  out.download_name = absl::StrCat("cycle-", cycle_id, "-", list[*i].path);
  // A replayed capture comes from outside: only these characters go into the header's
  // quoted file name, so that no quote or line break of a path ends up there.
  for (char& c : out.download_name) {
    if (!absl::ascii_isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '-') c = '_';
  }
  return out;
}

absl::StatusOr<CaptureArchiveToSend> CaptureViews::Archive(int64_t cycle_id) {
  absl::StatusOr<Capture> capture = core_->CycleCapture(cycle_id);
  // Nothing to download is a missing resource here, not a state of the page to explain.
  if (absl::IsFailedPrecondition(capture.status()) &&
      absl::StartsWith(capture.status().message(), "capture_not_kept")) {
    return absl::NotFoundError(capture.status().message());
  }
  if (!capture.ok()) return capture.status();
  const std::string top = absl::StrCat("cycle-", cycle_id);
  absl::StatusOr<std::vector<ArchiveMember>> members = CaptureArchiveMembers(*capture, top);
  if (!members.ok()) return members.status();
  return CaptureArchiveToSend{*std::move(members), absl::StrCat(top, "-capture.tar")};
}

absl::StatusOr<std::string> CaptureViews::View(int64_t cycle_id, const std::string& sensor,
                                               const std::string& frame) {
  int frame_index = 0;
  if (!frame.empty() && (!absl::SimpleAtoi(frame, &frame_index) || frame_index < 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("frame = ", QuoteInput(frame), ": must be a frame index (0, 1, ...)"));
  }
  const std::string key = absl::StrCat(cycle_id, "/", frame_index, "/", sensor);
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto it = cache_.begin(); it != cache_.end(); ++it) {
    if (it->first != key) continue;
    cache_.splice(cache_.begin(), cache_, it);
    return cache_.front().second;
  }
  absl::StatusOr<StoredCycle> cycle = core_->GetCycle(cycle_id);
  if (!cycle.ok()) return cycle.status();
  absl::StatusOr<Capture> capture = core_->CycleCapture(cycle_id);
  if (!capture.ok()) return capture.status();
  std::vector<double> T_car_sensor;
  for (const StoredSensorResult& r : cycle->sensors) {
    if (r.sensor == sensor) T_car_sensor = r.T_car_sensor;
  }
  if (!capture->manifest.FindSensor(sensor)) {
    return absl::NotFoundError(
        absl::StrCat("sensor: ", QuoteInput(sensor), " is not in cycle ", cycle_id, "'s capture"));
  }
  absl::StatusOr<nlohmann::json> view = SensorViewJson(*capture, sensor, frame_index, T_car_sensor);
  if (!view.ok()) return view.status();
  (*view)["cycle_id"] = std::to_string(cycle_id);
  if (view->contains("file")) {
    const std::vector<CaptureFileEntry> list = CaptureFileList(*capture);
    for (size_t i = 0; i < list.size(); ++i) {
      if (list[i].sensor == sensor && list[i].path == (*view)["file"]) (*view)["image"] = i;
    }
  }
  cache_.emplace_front(key, view->dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
  if (cache_.size() > kViewCacheSize) cache_.pop_back();
  return cache_.front().second;
}

}  // namespace linecal

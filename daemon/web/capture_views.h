#pragma once
// The cycle page's recorded data (docs/console.md, "Cycle views"): the files of a cycle's
// kept capture, for download and as the camera frames under the overlays, and each sensor's
// view (station/pipeline/cycle_views.h), over StationCore::CycleCapture. A client names a cycle
// by id, a sensor by name and a file by its index in CaptureFileList, never by a path, so
// nothing outside the cycle's capture (checked inside the data root) can be asked for.
// Views are computed one at a time: each is a frame's detection or a LiDAR or radar fit, and
// two at once would only slow a running cycle more. The last kViewCacheSize are kept, since
// a capture does not change once its cycle ended.
// Thread safety: every method may be called from any thread.

#include <cstdint>
#include <list>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>

#include "absl/status/statusor.h"
#include "daemon/core/station_core.h"
#include "daemon/web/capture_archive.h"

namespace linecal {

// Views kept: a cycle page of the reference car asks for 10, so three pages' worth.
inline constexpr size_t kViewCacheSize = 32;

// A cycle's whole capture to send as one tar archive (capture_archive.h).
struct CaptureArchiveToSend {
  std::vector<ArchiveMember> members;  // under the folder cycle-<id>/
  std::string download_name;           // cycle-<id>-capture.tar
};

// A file of a capture to send: where it is, its size and how the browser should take it.
struct CaptureFileToSend {
  std::string path;  // on disk, inside the capture
  std::uint64_t bytes = 0;
  std::string content_type;   // image/png, application/json, text/plain, application/octet-stream
  std::string download_name;  // cycle-<id>-<path>, every byte but [A-Za-z0-9.-] as '_'
};

class CaptureViews {
 public:
  explicit CaptureViews(StationCore* core) : core_(core) {}

  // {cycle_id, kept: true, files: [{index, path, sensor, role, bytes}]}, or {cycle_id, kept:
  // false, reason} while the cycle runs or when its capture was not kept or does not read
  // (CycleCapture's FailedPrecondition message; an answer, not an error: most cycles keep
  // none). NotFound for an unknown cycle. Cost: ReadCapture's plus a stat per file.
  absl::StatusOr<nlohmann::json> Files(int64_t cycle_id);
  // File `index` (decimal, of Files' list). InvalidArgument for an index that is not one;
  // errors of CycleCapture.
  absl::StatusOr<CaptureFileToSend> File(int64_t cycle_id, const std::string& index);
  // The capture's files for the archive (CaptureArchiveMembers under cycle-<id>/). NotFound
  // for an unknown cycle and for one that kept no capture ("capture_not_kept: ..."); the
  // other errors of CycleCapture (FailedPrecondition while it runs or when it does not read).
  absl::StatusOr<CaptureArchiveToSend> Archive(int64_t cycle_id);
  // SensorViewJson of `sensor` with the cycle's solved mounting, as JSON text, plus "image":
  // the index of a camera's frame in Files' list. `frame` is "" (0) or a decimal index.
  // Errors of CycleCapture and SensorViewJson; InvalidArgument for a malformed frame.
  absl::StatusOr<std::string> View(int64_t cycle_id, const std::string& sensor,
                                   const std::string& frame);

 private:
  StationCore* core_;
  std::mutex mutex_;  // held while a view is computed, and for the cache
  std::list<std::pair<std::string, std::string>> cache_;  // key -> view, most recent first
};

}  // namespace linecal

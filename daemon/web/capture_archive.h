#pragma once
// A cycle's kept capture as one download (docs/console.md, "Cycle views"): a tar archive of
// the capture's folder, written with libarchive (Debian's libarchive-dev) as it is sent, so
// that a capture of hundreds of MB is never whole in memory.

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "station/capture/capture.h"

namespace linecal {

// One file of an archive: where it is read and its name in the archive.
struct ArchiveMember {
  std::string disk_path;
  std::string name;  // relative, '/'-separated
};

// The files of `capture`'s folder under `top` ("cycle-7/manifest.json"): first the capture's
// own list (station/pipeline/cycle_views.h CaptureFileList: paths ReadCapture checked inside
// the capture, links resolved), then every other regular file below the folder in name order
// (a simulated cycle's ground_truth.json), found without following links, so nothing outside
// the folder is taken whatever a replayed capture holds. Cost: a walk of the folder.
absl::StatusOr<std::vector<ArchiveMember>> CaptureArchiveMembers(const Capture& capture,
                                                                 const std::string& top);

// Writes `members` as a POSIX tar archive (ustar; a pax header only for a name too long for
// ustar), each file's bytes read as written, through `write`, which returns false when the
// client went away. Regular-file entries with mode 0644, the files' modification times, no
// owner names. Cancelled when `write` returned false; NotFound / Internal naming the member
// when a file cannot be read (the archive written so far is then cut short).
absl::Status WriteTarArchive(const std::vector<ArchiveMember>& members,
                             const std::function<bool(std::string_view)>& write);

}  // namespace linecal

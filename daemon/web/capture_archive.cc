#include "daemon/web/capture_archive.h"

#include <archive.h>
#include <archive_entry.h>
#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <memory>
#include <set>

#include "absl/strings/str_cat.h"
#include "station/pipeline/cycle_views.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

// Pieces a file is read and handed to the archive in.
constexpr size_t kPieceBytes = 1 << 16;

struct ArchiveDeleter {
  void operator()(archive* a) const { archive_write_free(a); }
};
struct EntryDeleter {
  void operator()(archive_entry* e) const { archive_entry_free(e); }
};

// The client's side of libarchive's output: `write` and whether it refused a piece.
struct Output {
  const std::function<bool(std::string_view)>* write;
  bool refused = false;
};

la_ssize_t WriteOut(archive*, void* data, const void* buffer, size_t length) {
  auto* out = static_cast<Output*>(data);
  if (!(*out->write)(std::string_view(static_cast<const char*>(buffer), length))) {
    out->refused = true;
    return -1;
  }
  return static_cast<la_ssize_t>(length);
}

// The error of a failed libarchive call: Cancelled when the client went away.
absl::Status ArchiveError(archive* a, const Output& out, const std::string& what) {
  if (out.refused) return absl::CancelledError("the client went away");
  const char* message = archive_error_string(a);
  return absl::InternalError(absl::StrCat(what, ": ", message ? message : "archive error"));
}

// One member: its header, then its bytes in pieces. Needs an open archive.
absl::Status WriteMember(archive* a, const Output& out, const ArchiveMember& m) {
  struct stat st {};
  if (::stat(m.disk_path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) {
    return absl::NotFoundError(absl::StrCat(m.name, ": not a readable file"));
  }
  std::ifstream in(m.disk_path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(m.name, ": cannot open it"));
  std::unique_ptr<archive_entry, EntryDeleter> entry(archive_entry_new());
  archive_entry_set_pathname(entry.get(), m.name.c_str());
  archive_entry_set_size(entry.get(), st.st_size);
  archive_entry_set_filetype(entry.get(), AE_IFREG);
  archive_entry_set_perm(entry.get(), 0644);
  archive_entry_set_mtime(entry.get(), st.st_mtim.tv_sec, st.st_mtim.tv_nsec);
  // ARCHIVE_WARN: a name that does not convert to the header's character set, kept as is.
  if (archive_write_header(a, entry.get()) < ARCHIVE_WARN) return ArchiveError(a, out, m.name);
  std::vector<char> piece(kPieceBytes);
  std::int64_t left = st.st_size;
  while (left > 0) {
    in.read(piece.data(), static_cast<std::streamsize>(std::min<std::int64_t>(left, kPieceBytes)));
    const std::streamsize got = in.gcount();
    if (got <= 0) return absl::InternalError(absl::StrCat(m.name, ": shorter than its size"));
    if (archive_write_data(a, piece.data(), static_cast<size_t>(got)) < 0)
      return ArchiveError(a, out, m.name);
    left -= got;
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::vector<ArchiveMember>> CaptureArchiveMembers(const Capture& capture,
                                                                 const std::string& top) {
  std::vector<ArchiveMember> members;
  std::set<std::string> listed;
  for (const CaptureFileEntry& f : CaptureFileList(capture)) {
    members.push_back({(fs::path(capture.dir) / f.path).string(), absl::StrCat(top, "/", f.path)});
    listed.insert(fs::path(f.path).lexically_normal().generic_string());
  }
  std::vector<std::string> others;
  std::error_code ec;
  // Neither linked folders nor linked files are followed: only what is in the folder itself.
  for (fs::recursive_directory_iterator it(capture.dir, ec), end; !ec && it != end;
       it.increment(ec)) {
    std::error_code type_ec;
    if (it->symlink_status(type_ec).type() != fs::file_type::regular) continue;
    const std::string name = it->path().lexically_relative(capture.dir).generic_string();
    if (!listed.contains(name)) others.push_back(name);
  }
  if (ec) {
    return absl::InternalError(
        absl::StrCat("capture: cannot list ", capture.dir, ": ", ec.message()));
  }
  std::sort(others.begin(), others.end());
  for (const std::string& name : others) {
    members.push_back({(fs::path(capture.dir) / name).string(), absl::StrCat(top, "/", name)});
  }
  return members;
}

absl::Status WriteTarArchive(const std::vector<ArchiveMember>& members,
                             const std::function<bool(std::string_view)>& write) {
  std::unique_ptr<archive, ArchiveDeleter> a(archive_write_new());
  if (!a) return absl::ResourceExhaustedError("archive: out of memory");
  Output out{&write};
  // pax restricted: plain ustar headers, which every tar reads, and a pax extended header
  // only for a member that ustar cannot describe (a name over 100 bytes).
  if (archive_write_set_format_pax_restricted(a.get()) != ARCHIVE_OK ||
      archive_write_open(a.get(), &out, nullptr, WriteOut, nullptr) != ARCHIVE_OK) {
    return ArchiveError(a.get(), out, "archive");
  }
  for (const ArchiveMember& m : members) {
    if (absl::Status s = WriteMember(a.get(), out, m); !s.ok()) return s;
  }
  if (archive_write_close(a.get()) != ARCHIVE_OK) return ArchiveError(a.get(), out, "archive");
  return absl::OkStatus();
}

}  // namespace linecal

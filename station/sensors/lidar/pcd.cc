// The one translation unit that includes PCL (its headers take seconds to compile).
#include "station/sensors/lidar/pcd.h"

#include <pcl/PCLPointCloud2.h>
#include <pcl/console/print.h>
#include <pcl/io/pcd_io.h>

#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <optional>
#include <string>
#include <system_error>
#include <tuple>
#include <utility>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

namespace linecal {
namespace {

// A PCD header is a few hundred bytes; past this it is not one.
constexpr std::size_t kMaxHeaderBytes = 64 * 1024;
// LZF (binary_compressed) expands a back reference of at most 264 bytes from 3 bytes, so no
// valid file decompresses to more than ~88 times its size; 100 leaves a margin.
constexpr std::uint64_t kMaxCompressionRatio = 100;
// An ASCII value takes at least one character and one separator.
constexpr std::uint64_t kMinAsciiBytesPerValue = 2;
// PCL addresses cloud data with 32-bit offsets.
constexpr std::uint64_t kMaxDataBytes = std::numeric_limits<std::int32_t>::max();

// A PCD header, as far as ReadPcd needs it.
struct PcdHeader {
  struct Field {
    std::string name;
    std::uint8_t datatype = 0;  // pcl::PCLPointField::PointFieldTypes
    std::uint64_t count = 1;
    std::uint64_t size = 4;
  };
  std::vector<Field> fields;
  std::uint64_t width = 0;
  std::uint64_t height = 1;
  std::uint64_t points = 0;
  std::uint64_t point_bytes = 0;
  std::string data;             // "ascii", "binary" or "binary_compressed"
  std::size_t data_offset = 0;  // where the body starts in the file
  std::uint64_t values_per_point = 0;
};

std::uint8_t PclType(char type, std::uint64_t size) {
  using F = pcl::PCLPointField;
  switch (type) {
    case 'I':
      return size == 1 ? F::INT8 : size == 2 ? F::INT16 : size == 4 ? F::INT32 : F::INT64;
    case 'U':
      return size == 1 ? F::UINT8 : size == 2 ? F::UINT16 : size == 4 ? F::UINT32 : F::UINT64;
    case 'F':
      return size == 4 ? F::FLOAT32 : size == 8 ? F::FLOAT64 : 0;
  }
  return 0;
}

// "path: not a readable PCD file (what)".
absl::Status NotPcd(const std::filesystem::path& path, absl::string_view what) {
  return absl::InvalidArgumentError(
      absl::StrCat(path.string(), ": not a readable PCD file (", what, ")"));
}

// The per-field lists of a header as written (names and types view the header's text), and
// whether it had a POINTS entry.
struct PcdFieldLists {
  std::vector<absl::string_view> names, types;
  std::vector<std::uint64_t> sizes, counts;
  bool have_points = false;
};

// The tokens as unsigned decimal numbers; false if one is not.
bool ParseNumbers(const std::vector<absl::string_view>& tok, std::vector<std::uint64_t>* out) {
  out->clear();
  for (absl::string_view t : tok) {
    std::uint64_t v = 0;
    if (!absl::SimpleAtoi(t, &v)) return false;
    out->push_back(v);
  }
  return true;
}

// The tokens as one unsigned decimal number; false unless they are exactly that.
bool ParseSingle(const std::vector<absl::string_view>& tok, std::uint64_t* out) {
  std::vector<std::uint64_t> one;
  if (!ParseNumbers(tok, &one) || one.size() != 1) return false;
  *out = one[0];
  return true;
}

// Stores the values `tok` of header entry `key` (one of the prescribed ones; the body starts
// at `pos` if it is DATA) in *h and *lists; NotPcd naming the entry if they are not what it
// takes.
absl::Status ParseEntry(const std::filesystem::path& path, absl::string_view key,
                        const std::vector<absl::string_view>& tok, std::size_t pos, PcdHeader* h,
                        PcdFieldLists* lists) {
  if (key == "FIELDS") {
    lists->names = tok;
  } else if (key == "SIZE") {
    if (!ParseNumbers(tok, &lists->sizes)) return NotPcd(path, "SIZE");
  } else if (key == "TYPE") {
    lists->types = tok;
  } else if (key == "COUNT") {
    if (!ParseNumbers(tok, &lists->counts)) return NotPcd(path, "COUNT");
  } else if (key == "WIDTH") {
    if (!ParseSingle(tok, &h->width)) return NotPcd(path, "WIDTH");
  } else if (key == "HEIGHT") {
    if (!ParseSingle(tok, &h->height)) return NotPcd(path, "HEIGHT");
  } else if (key == "POINTS") {
    if (!ParseSingle(tok, &h->points)) return NotPcd(path, "POINTS");
    lists->have_points = true;
  } else if (key == "VIEWPOINT") {
    if (tok.size() != 7) return NotPcd(path, "VIEWPOINT needs 7 values");
  } else if (key == "DATA") {
    if (tok.size() != 1) return NotPcd(path, "DATA");
    h->data = std::string(tok[0]);
    h->data_offset = pos;
  }
  return absl::OkStatus();
}

// Reads the header's entries from `text` (the file's first bytes), in the order the format
// prescribes, up to and including DATA (h->data_offset: where the body starts). NotPcd for an
// unknown entry, one out of order, a malformed value or no DATA line.
absl::Status ParseEntries(const std::filesystem::path& path, const std::string& text, PcdHeader* h,
                          PcdFieldLists* lists) {
  // The entries in their prescribed order (COLUMNS is FIELDS in PCD v0.6).
  static constexpr absl::string_view kOrder[] = {"VERSION", "FIELDS", "SIZE",   "TYPE",
                                                 "COUNT",   "WIDTH",  "HEIGHT", "VIEWPOINT",
                                                 "POINTS",  "DATA"};
  int last_entry = -1;
  std::size_t pos = 0;
  while (pos < text.size() && h->data.empty()) {
    const std::size_t eol = text.find('\n', pos);
    if (eol == std::string::npos) break;
    const absl::string_view line(text.data() + pos, eol - pos);
    pos = eol + 1;
    std::vector<absl::string_view> tok =
        absl::StrSplit(line, absl::ByAnyChar(" \t\r"), absl::SkipEmpty());
    if (tok.empty() || tok[0][0] == '#') continue;
    const absl::string_view key = tok[0] == "COLUMNS" ? "FIELDS" : tok[0];
    tok.erase(tok.begin());
    int entry = 0;
    while (entry < static_cast<int>(std::size(kOrder)) && kOrder[entry] != key) ++entry;
    if (entry == static_cast<int>(std::size(kOrder))) {
      return NotPcd(path, absl::StrCat("unknown header entry ", Snippet({key.data(), key.size()})));
    }
    if (entry <= last_entry) {
      return NotPcd(path, absl::StrCat("header entry ", key, " out of order"));
    }
    last_entry = entry;
    if (absl::Status s = ParseEntry(path, key, tok, pos, h, lists); !s.ok()) return s;
  }
  if (h->data.empty()) return NotPcd(path, "no DATA line in the header");
  return absl::OkStatus();
}

// The fields from the lists (COUNT 1 each if absent) into h->fields, h->values_per_point and
// h->point_bytes; NotPcd when the lists differ in length or a field's size, type or count is
// not one PCL reads.
absl::Status SetFields(const std::filesystem::path& path, PcdFieldLists lists, PcdHeader* h) {
  if (lists.names.empty() || lists.sizes.size() != lists.names.size() ||
      lists.types.size() != lists.names.size()) {
    return NotPcd(path, "FIELDS, SIZE and TYPE differ in length");
  }
  if (lists.counts.empty()) lists.counts.assign(lists.names.size(), 1);
  if (lists.counts.size() != lists.names.size()) {
    return NotPcd(path, "FIELDS and COUNT differ in length");
  }
  // The limits keep every product below 2^64: a point of at most 2^20 values of 8 bytes.
  constexpr std::uint64_t kMaxValuesPerPoint = 1 << 20;
  for (std::size_t i = 0; i < lists.names.size(); ++i) {
    PcdHeader::Field f;
    f.name = std::string(lists.names[i]);
    f.size = lists.sizes[i];
    f.count = lists.counts[i];
    f.datatype = lists.types[i].size() == 1 ? PclType(lists.types[i][0], f.size) : 0;
    if ((f.size != 1 && f.size != 2 && f.size != 4 && f.size != 8) || f.datatype == 0) {
      const std::string_view type(lists.types[i].data(), lists.types[i].size());
      return NotPcd(path, absl::StrCat("SIZE ", f.size, " TYPE ", Snippet(type), " of field ",
                                       Snippet(f.name)));
    }
    if (f.count == 0 || f.count > kMaxValuesPerPoint) return NotPcd(path, "COUNT");
    h->values_per_point += f.count;
    h->point_bytes += f.count * f.size;
    h->fields.push_back(std::move(f));
  }
  if (h->values_per_point > kMaxValuesPerPoint) return NotPcd(path, "too many values per point");
  return absl::OkStatus();
}

// Checks the point count against WIDTH x HEIGHT (it is that without POINTS), the budget, and
// that the file's `body_bytes` after the header can hold the points in h->data's encoding.
absl::Status CheckPointCount(const std::filesystem::path& path, bool have_points,
                             std::uint64_t body_bytes, const InputBudget& budget, PcdHeader* h) {
  if (!have_points) h->points = h->width * h->height;
  if (h->width > kMaxDataBytes || h->height > kMaxDataBytes || h->points != h->width * h->height) {
    return NotPcd(path, absl::StrCat("POINTS ", h->points, " is not WIDTH ", h->width, " x HEIGHT ",
                                     h->height));
  }
  // The budget before the body is looked at: the header's claims decide what is allocated.
  if (h->points > static_cast<std::uint64_t>(budget.max_scan_points)) {
    return OverBudget(path.string(),
                      static_cast<std::int64_t>(std::min<std::uint64_t>(
                          h->points, std::numeric_limits<std::int64_t>::max())),
                      "points", budget.max_scan_points, "max_scan_points");
  }
  const std::uint64_t data_bytes = h->points * h->point_bytes;
  if (data_bytes > static_cast<std::uint64_t>(budget.max_file_bytes)) {
    return OverBudget(absl::StrCat(path.string(), ": decoded point data"),
                      static_cast<std::int64_t>(data_bytes), "bytes", budget.max_file_bytes,
                      "max_file_bytes");
  }
  std::uint64_t limit = 0;
  if (h->data == "binary") {
    limit = body_bytes;
  } else if (h->data == "binary_compressed") {
    limit = body_bytes * kMaxCompressionRatio;
  } else {
    limit = body_bytes / kMinAsciiBytesPerValue * h->point_bytes / h->values_per_point;
  }
  if (data_bytes > limit || data_bytes > kMaxDataBytes) {
    return NotPcd(path,
                  absl::StrCat(h->points, " points of ", h->point_bytes,
                               " bytes do not fit the file's ", body_bytes, " bytes of data"));
  }
  return absl::OkStatus();
}

// Parses and checks a header. PCL's own header parser is not used: it sizes its buffers from
// POINTS × point size before it looks at the data, and it stops at the first line it does
// not know and then reads the file from a wrong offset (a crash the fuzzer found). Here the
// entries must come in the order the PCD format prescribes, unknown ones are refused, and the
// body must be able to hold what the header announces.
absl::StatusOr<PcdHeader> ParseHeader(const std::filesystem::path& path,
                                      const InputBudget& budget) {
  std::error_code ec;
  const std::uint64_t file_size = std::filesystem::file_size(path, ec);
  if (ec) return absl::InvalidArgumentError(absl::StrCat(path.string(), ": ", ec.message()));
  if (absl::Status s = CheckFileBytes(path, budget); !s.ok()) return s;
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot open ", path.string()));
  std::string text(std::min<std::uint64_t>(file_size, kMaxHeaderBytes), '\0');
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<std::size_t>(in.gcount()));

  PcdHeader h;
  PcdFieldLists lists;
  if (absl::Status s = ParseEntries(path, text, &h, &lists); !s.ok()) return s;
  if (h.data != "ascii" && h.data != "binary" && h.data != "binary_compressed") {
    return NotPcd(path, absl::StrCat("DATA ", Snippet(h.data)));
  }
  const bool have_points = lists.have_points;
  if (absl::Status s = SetFields(path, std::move(lists), &h); !s.ok()) return s;
  const std::uint64_t body = file_size - std::min<std::uint64_t>(file_size, h.data_offset);
  if (absl::Status s = CheckPointCount(path, have_points, body, budget, &h); !s.ok()) return s;
  return h;
}

bool IsIntegerType(std::uint8_t datatype) {
  return datatype != pcl::PCLPointField::FLOAT32 && datatype != pcl::PCLPointField::FLOAT64;
}

// One value of a field: integer types exactly, floating-point types as double.
struct Number {
  bool integer = false;
  std::int64_t i = 0;
  double d = 0.0;
  double AsDouble() const { return integer ? static_cast<double>(i) : d; }
};

Number LoadNumber(const std::uint8_t* p, std::uint8_t datatype) {
  auto load = [p]<typename T>(T) {
    T v;
    std::memcpy(&v, p, sizeof(T));
    return v;
  };
  Number n;
  n.integer = IsIntegerType(datatype);
  switch (datatype) {
    case pcl::PCLPointField::INT8:
      n.i = load(std::int8_t{});
      break;
    case pcl::PCLPointField::UINT8:
      n.i = load(std::uint8_t{});
      break;
    case pcl::PCLPointField::INT16:
      n.i = load(std::int16_t{});
      break;
    case pcl::PCLPointField::UINT16:
      n.i = load(std::uint16_t{});
      break;
    case pcl::PCLPointField::INT32:
      n.i = load(std::int32_t{});
      break;
    case pcl::PCLPointField::UINT32:
      n.i = load(std::uint32_t{});
      break;
    case pcl::PCLPointField::INT64:
      n.i = load(std::int64_t{});
      break;
    case pcl::PCLPointField::UINT64:
      // Beyond int64 no time or ring is meaningful: saturate.
      n.i = static_cast<std::int64_t>(
          std::min<std::uint64_t>(load(std::uint64_t{}), std::numeric_limits<std::int64_t>::max()));
      break;
    case pcl::PCLPointField::FLOAT32:
      n.d = load(float{});
      break;
    case pcl::PCLPointField::FLOAT64:
      n.d = load(double{});
      break;
  }
  return n;
}

// An ASCII value: integer fields are read exactly (PCL's own ASCII reader goes through
// double, which would round ns times since the epoch by up to 128 ns).
std::optional<Number> ParseNumber(absl::string_view token, std::uint8_t datatype) {
  Number n;
  const char* end = token.data() + token.size();
  if (IsIntegerType(datatype)) {
    const auto [p, ec] = std::from_chars(token.data(), end, n.i);
    if (ec == std::errc() && p == end) {
      n.integer = true;
      return n;
    }
  }
  if (absl::EqualsIgnoreCase(token, "nan")) {
    n.d = std::numeric_limits<double>::quiet_NaN();
    return n;
  }
  const auto [p, ec] = std::from_chars(token.data(), end, n.d);
  if (ec != std::errc() || p != end) return std::nullopt;
  return n;
}

// A time value as ns: integer fields hold ns, floating-point fields seconds.
std::int64_t TimeNs(const Number& n) {
  if (n.integer) return n.i;
  const double ns = n.d * 1e9;
  // Saturate what an int64 cannot hold (NaN becomes 0) instead of converting out of range.
  constexpr double kLimit = 9.2e18;
  if (std::isnan(ns)) return 0;
  if (ns >= kLimit) return std::numeric_limits<std::int64_t>::max();
  if (ns <= -kLimit) return std::numeric_limits<std::int64_t>::min();
  return std::llround(ns);
}

// Where the fields LidarPoint needs are in a point: byte offsets (binary) or value indices
// (ASCII), with their types.
struct FieldMap {
  struct Slot {
    bool present = false;
    std::uint64_t at = 0;
    std::uint8_t datatype = 0;
  };
  Slot x, y, z, intensity, ring, time;
};

void SilencePcl() {
  // PCL prints its own errors to stderr; ReadPcd and WritePcd report through their status.
  pcl::console::setVerbosityLevel(pcl::console::L_ALWAYS);
}

// Builds the map from (name, datatype, count, location) of every field in file order.
absl::StatusOr<FieldMap> MapFields(
    const std::filesystem::path& path,
    const std::vector<std::tuple<std::string, std::uint8_t, std::uint64_t, std::uint64_t>>&
        fields) {
  FieldMap m;
  const std::pair<const char*, FieldMap::Slot*> wanted[] = {
      {"x", &m.x},       {"y", &m.y},      {"z", &m.z}, {"intensity", &m.intensity},
      {"ring", &m.ring}, {"time", &m.time}};
  for (const auto& [name, datatype, count, at] : fields) {
    for (const auto& [wanted_name, slot] : wanted) {
      if (name != wanted_name || slot->present) continue;
      if (count != 1) {
        return absl::InvalidArgumentError(
            absl::StrCat(path.string(), ": field ", name, " is not one number per point"));
      }
      *slot = {true, at, datatype};
    }
  }
  if (!m.x.present || !m.y.present || !m.z.present) {
    return absl::InvalidArgumentError(absl::StrCat(path.string(), ": no x, y and z fields"));
  }
  if (m.ring.present && !IsIntegerType(m.ring.datatype)) {
    return absl::InvalidArgumentError(
        absl::StrCat(path.string(), ": field ring is not an integer"));
  }
  return m;
}

// Appends one point from its field values; `get` returns the value of a slot.
template <typename Get>
absl::Status AddPoint(const std::filesystem::path& path, std::uint64_t index, const FieldMap& m,
                      const Get& get, PcdCloud* out) {
  LidarPoint pt;
  pt.x = static_cast<float>(get(m.x).AsDouble());
  pt.y = static_cast<float>(get(m.y).AsDouble());
  pt.z = static_cast<float>(get(m.z).AsDouble());
  if (!std::isfinite(pt.x) || !std::isfinite(pt.y) || !std::isfinite(pt.z)) {
    ++out->non_finite_dropped;
    return absl::OkStatus();
  }
  if (m.intensity.present) pt.intensity = static_cast<float>(get(m.intensity).AsDouble());
  if (m.ring.present) {
    const Number ring = get(m.ring);
    if (!ring.integer || ring.i < 0 || ring.i > std::numeric_limits<std::uint16_t>::max()) {
      return absl::InvalidArgumentError(absl::StrCat(path.string(), ": point ", index, ": ring ",
                                                     ring.AsDouble(), " is not in 0..65535"));
    }
    pt.ring = static_cast<std::uint16_t>(ring.i);
  }
  if (m.time.present) pt.time_ns = TimeNs(get(m.time));
  out->points.push_back(pt);
  return absl::OkStatus();
}

absl::StatusOr<PcdCloud> ReadAscii(const std::filesystem::path& path, const PcdHeader& h) {
  std::vector<std::tuple<std::string, std::uint8_t, std::uint64_t, std::uint64_t>> fields;
  std::uint64_t index = 0;
  for (const PcdHeader::Field& f : h.fields) {
    fields.emplace_back(f.name, f.datatype, f.count, index);
    index += f.count;
  }
  absl::StatusOr<FieldMap> m = MapFields(path, fields);
  if (!m.ok()) return m.status();
  std::ifstream in(path, std::ios::binary);
  in.seekg(static_cast<std::streamoff>(h.data_offset));
  PcdCloud out;
  out.has_intensity = m->intensity.present;
  out.has_ring = m->ring.present;
  out.has_time = m->time.present;
  out.points.reserve(h.points);
  std::string line;
  std::uint64_t point = 0;
  while (point < h.points && std::getline(in, line)) {
    const std::vector<absl::string_view> tok =
        absl::StrSplit(line, absl::ByAnyChar(" \t\r"), absl::SkipEmpty());
    if (tok.empty()) continue;
    if (tok.size() != h.values_per_point) {
      return absl::InvalidArgumentError(absl::StrCat(path.string(), ": point ", point, " has ",
                                                     tok.size(), " values, expected ",
                                                     h.values_per_point));
    }
    absl::Status bad_value;
    auto get = [&](const FieldMap::Slot& s) {
      const std::optional<Number> n = ParseNumber(tok[s.at], s.datatype);
      if (!n) {
        bad_value = absl::InvalidArgumentError(
            absl::StrCat(path.string(), ": point ", point, ": ",
                         Snippet({tok[s.at].data(), tok[s.at].size()}), " is not a number"));
        return Number{};
      }
      return *n;
    };
    if (absl::Status s = AddPoint(path, point, *m, get, &out); !s.ok()) return s;
    if (!bad_value.ok()) return bad_value;
    ++point;
  }
  if (point < h.points) {
    return absl::InvalidArgumentError(
        absl::StrCat(path.string(), ": ", point, " of ", h.points, " points"));
  }
  return out;
}

// The body through PCL's decoder (a copy for binary, LZF and de-interleaving for
// binary_compressed), on a cloud laid out from the checked header. PCL trusts the sizes in a
// compressed body, so they are checked against the file first.
absl::StatusOr<PcdCloud> ReadBinary(const std::filesystem::path& path, const PcdHeader& h) {
  std::ifstream in(path, std::ios::binary);
  std::vector<std::uint8_t> file((std::istreambuf_iterator<char>(in)),
                                 std::istreambuf_iterator<char>());
  auto bad = [&](const std::string& what) {
    return absl::InvalidArgumentError(absl::StrCat(path.string(), ": ", what));
  };
  pcl::PCLPointCloud2 cloud;
  std::uint32_t offset = 0;
  for (const PcdHeader::Field& f : h.fields) {
    pcl::PCLPointField pf;
    pf.name = f.name;
    pf.offset = offset;
    pf.datatype = f.datatype;
    pf.count = static_cast<std::uint32_t>(f.count);
    cloud.fields.push_back(pf);
    offset += static_cast<std::uint32_t>(f.count * f.size);
  }
  // ParseHeader bounded all of these by kMaxDataBytes.
  cloud.point_step = offset;
  cloud.width = static_cast<std::uint32_t>(h.width);
  cloud.height = static_cast<std::uint32_t>(h.height);
  cloud.row_step = cloud.point_step * cloud.width;
  const std::uint64_t data_bytes = h.points * h.point_bytes;
  cloud.data.resize(data_bytes);
  const bool compressed = h.data == "binary_compressed";
  const std::uint64_t body = file.size() - std::min<std::uint64_t>(file.size(), h.data_offset);
  if (compressed) {
    // A u32 compressed size, a u32 uncompressed size, then the LZF stream.
    constexpr std::uint64_t kSizesBytes = 8;
    if (body < kSizesBytes) return bad("binary_compressed body shorter than its sizes");
    std::uint32_t sizes[2];
    std::memcpy(sizes, file.data() + h.data_offset, sizeof(sizes));
    if (sizes[0] > body - kSizesBytes) {
      return bad(absl::StrCat("compressed size ", sizes[0], " exceeds the file"));
    }
    if (sizes[1] != data_bytes) {
      return bad(absl::StrCat("uncompressed size ", sizes[1], " is not ", data_bytes));
    }
  } else if (body < data_bytes) {
    return bad("data shorter than the header says");
  }
  if (h.points > 0) {
    SilencePcl();
    int result = -1;
    try {
      result =
          pcl::PCDReader().readBodyBinary(file.data(), cloud, pcl::PCDReader::PCD_V7, compressed,
                                          static_cast<unsigned int>(h.data_offset));
    } catch (const std::exception& e) {
      return bad(e.what());
    }
    if (result < 0 || cloud.data.size() != data_bytes) return bad("corrupt point data");
  }
  const std::uint64_t n = h.points;
  std::vector<std::tuple<std::string, std::uint8_t, std::uint64_t, std::uint64_t>> fields;
  for (const pcl::PCLPointField& f : cloud.fields) {
    fields.emplace_back(f.name, f.datatype, f.count, f.offset);
  }
  absl::StatusOr<FieldMap> m = MapFields(path, fields);
  if (!m.ok()) return m.status();
  PcdCloud out;
  out.has_intensity = m->intensity.present;
  out.has_ring = m->ring.present;
  out.has_time = m->time.present;
  out.points.reserve(n);
  for (std::uint64_t i = 0; i < n; ++i) {
    const std::uint8_t* p = cloud.data.data() + i * cloud.point_step;
    auto get = [p](const FieldMap::Slot& s) { return LoadNumber(p + s.at, s.datatype); };
    if (absl::Status s = AddPoint(path, i, *m, get, &out); !s.ok()) return s;
  }
  return out;
}

}  // namespace

absl::StatusOr<PcdCloud> ReadPcd(const std::filesystem::path& path) {
  return ReadPcd(path, InputBudget::Unlimited());
}

absl::StatusOr<PcdCloud> ReadPcd(const std::filesystem::path& path, const InputBudget& budget) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    return absl::NotFoundError(absl::StrCat("cannot read ", path.string()));
  }
  const absl::StatusOr<PcdHeader> header = ParseHeader(path, budget);
  if (!header.ok()) return header.status();
  return header->data == "ascii" ? ReadAscii(path, *header) : ReadBinary(path, *header);
}

absl::Status WritePcd(const std::filesystem::path& path, std::span<const LidarPoint> points,
                      PcdEncoding encoding) {
  SilencePcl();
  pcl::PCLPointCloud2 cloud;
  auto add = [&](const char* name, std::uint32_t offset, std::uint8_t type) {
    pcl::PCLPointField f;
    f.name = name;
    f.offset = offset;
    f.datatype = type;
    f.count = 1;
    cloud.fields.push_back(f);
  };
  // Packed without padding: 3 × 4 + 4 + 2 + 8 bytes.
  add("x", 0, pcl::PCLPointField::FLOAT32);
  add("y", 4, pcl::PCLPointField::FLOAT32);
  add("z", 8, pcl::PCLPointField::FLOAT32);
  add("intensity", 12, pcl::PCLPointField::FLOAT32);
  add("ring", 16, pcl::PCLPointField::UINT16);
  add("time", 18, pcl::PCLPointField::INT64);
  cloud.point_step = 26;
  cloud.width = static_cast<std::uint32_t>(points.size());
  cloud.height = 1;
  cloud.row_step = cloud.point_step * cloud.width;
  cloud.is_dense = true;
  cloud.data.resize(static_cast<std::size_t>(cloud.row_step));
  for (std::size_t i = 0; i < points.size(); ++i) {
    std::uint8_t* p = cloud.data.data() + i * cloud.point_step;
    const LidarPoint& q = points[i];
    std::memcpy(p + 0, &q.x, 4);
    std::memcpy(p + 4, &q.y, 4);
    std::memcpy(p + 8, &q.z, 4);
    std::memcpy(p + 12, &q.intensity, 4);
    std::memcpy(p + 16, &q.ring, 2);
    std::memcpy(p + 18, &q.time_ns, 8);
  }

  const Eigen::Vector4f origin = Eigen::Vector4f::Zero();
  const Eigen::Quaternionf orientation = Eigen::Quaternionf::Identity();
  pcl::PCDWriter writer;
  int result = -1;
  try {
    if (points.empty()) {
      // PCL's writers refuse empty clouds; a rotation without returns is still a scan.
      std::ofstream out(path, std::ios::binary | std::ios::trunc);
      const std::string header = encoding == PcdEncoding::kAscii
                                     ? writer.generateHeaderASCII(cloud, origin, orientation)
                                     : writer.generateHeaderBinary(cloud, origin, orientation);
      out << header << "DATA " << (encoding == PcdEncoding::kAscii ? "ascii" : "binary") << "\n";
      result = out ? 0 : -1;
    } else if (encoding == PcdEncoding::kAscii) {
      // 9 significant digits make every float round-trip exactly.
      constexpr int kFloatDigits = 9;
      result = writer.writeASCII(path.string(), cloud, origin, orientation, kFloatDigits);
    } else if (encoding == PcdEncoding::kBinary) {
      result = writer.writeBinary(path.string(), cloud, origin, orientation);
    } else {
      result = writer.writeBinaryCompressed(path.string(), cloud, origin, orientation);
    }
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat("cannot write ", path.string(), ": ", e.what()));
  }
  if (result < 0) return absl::InternalError(absl::StrCat("cannot write ", path.string()));
  return absl::OkStatus();
}

}  // namespace linecal

#include "station/io/json_reader.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

const char* TypeName(const nlohmann::json& j) { return j.type_name(); }

std::string Shorten(const nlohmann::json& j) {
  std::string s = j.dump();
  // Long values (whole objects) would drown the message; 40 characters identify the value.
  constexpr size_t kMaxShown = 40;
  if (s.size() > kMaxShown) s = s.substr(0, kMaxShown) + "...";
  return s;
}

}  // namespace

JsonField::JsonField(const nlohmann::json* node, std::shared_ptr<const std::string> source,
                     std::string path)
    : node_(node), source_(std::move(source)), path_(std::move(path)) {}

std::string JsonField::ChildPath(const std::string& key) const {
  return path_.empty() ? key : absl::StrCat(path_, ".", key);
}

absl::Status JsonField::Error(const std::string& key, const std::string& message) const {
  return absl::InvalidArgumentError(absl::StrCat(*source_, ": ", ChildPath(key), ": ", message));
}

absl::Status JsonField::Error(const std::string& message) const {
  return absl::InvalidArgumentError(
      absl::StrCat(*source_, ": ", path_.empty() ? "(top level)" : path_, ": ", message));
}

bool JsonField::Has(const std::string& key) const {
  return node_->is_object() && node_->contains(key);
}

absl::StatusOr<JsonField> JsonField::Object(const std::string& key) const {
  if (!Has(key)) return Error(key, "missing");
  const nlohmann::json& v = (*node_)[key];
  if (!v.is_object()) return Error(key, absl::StrCat("expected an object, got ", TypeName(v)));
  return JsonField(&v, source_, ChildPath(key));
}

absl::StatusOr<std::vector<JsonField>> JsonField::Array(const std::string& key) const {
  if (!Has(key)) return Error(key, "missing");
  const nlohmann::json& v = (*node_)[key];
  if (!v.is_array()) return Error(key, absl::StrCat("expected an array, got ", TypeName(v)));
  std::vector<JsonField> out;
  out.reserve(v.size());
  for (size_t i = 0; i < v.size(); ++i) {
    out.emplace_back(&v[i], source_, absl::StrCat(ChildPath(key), "[", i, "]"));
  }
  return out;
}

absl::StatusOr<std::string> JsonField::String(const std::string& key) const {
  if (!Has(key)) return Error(key, "missing");
  const nlohmann::json& v = (*node_)[key];
  if (!v.is_string()) return Error(key, absl::StrCat("expected a string, got ", Shorten(v)));
  return v.get<std::string>();
}

absl::StatusOr<double> JsonField::Number(const std::string& key) const {
  if (!Has(key)) return Error(key, "missing");
  const nlohmann::json& v = (*node_)[key];
  if (!v.is_number()) return Error(key, absl::StrCat("expected a number, got ", Shorten(v)));
  const double d = v.get<double>();
  if (!std::isfinite(d)) return Error(key, "must be finite");
  return d;
}

absl::StatusOr<std::int64_t> JsonField::Integer(const std::string& key) const {
  if (!Has(key)) return Error(key, "missing");
  const nlohmann::json& v = (*node_)[key];
  if (!v.is_number_integer()) {
    return Error(key, absl::StrCat("expected a whole number, got ", Shorten(v)));
  }
  return v.get<std::int64_t>();
}

absl::StatusOr<bool> JsonField::Bool(const std::string& key) const {
  if (!Has(key)) return Error(key, "missing");
  const nlohmann::json& v = (*node_)[key];
  if (!v.is_boolean()) return Error(key, absl::StrCat("expected true or false, got ", Shorten(v)));
  return v.get<bool>();
}

absl::StatusOr<std::vector<double>> JsonField::Numbers(const std::string& key, size_t n) const {
  if (!Has(key)) return Error(key, "missing");
  const nlohmann::json& v = (*node_)[key];
  if (!v.is_array())
    return Error(key, absl::StrCat("expected an array of numbers, got ", Shorten(v)));
  if (n != 0 && v.size() != n) {
    return Error(key, absl::StrCat("expected ", n, " numbers, got ", v.size()));
  }
  std::vector<double> out;
  out.reserve(v.size());
  for (size_t i = 0; i < v.size(); ++i) {
    if (!v[i].is_number() || !std::isfinite(v[i].get<double>())) {
      return Error(absl::StrCat(key, "[", i, "]"),
                   absl::StrCat("expected a finite number, got ", Shorten(v[i])));
    }
    out.push_back(v[i].get<double>());
  }
  return out;
}

absl::StatusOr<std::string> JsonField::StringOr(const std::string& key,
                                                const std::string& fallback) const {
  return Has(key) ? String(key) : fallback;
}
absl::StatusOr<double> JsonField::NumberOr(const std::string& key, double fallback) const {
  return Has(key) ? Number(key) : fallback;
}
absl::StatusOr<std::int64_t> JsonField::IntegerOr(const std::string& key,
                                                  std::int64_t fallback) const {
  return Has(key) ? Integer(key) : fallback;
}
absl::StatusOr<bool> JsonField::BoolOr(const std::string& key, bool fallback) const {
  return Has(key) ? Bool(key) : fallback;
}

absl::StatusOr<double> JsonField::AsNumber() const {
  if (!node_->is_number() || !std::isfinite(node_->get<double>())) {
    return Error(absl::StrCat("expected a finite number, got ", Shorten(*node_)));
  }
  return node_->get<double>();
}

absl::StatusOr<std::string> JsonField::AsString() const {
  if (!node_->is_string()) return Error(absl::StrCat("expected a string, got ", Shorten(*node_)));
  return node_->get<std::string>();
}

absl::Status JsonField::AllowOnlyKeys(std::initializer_list<const char*> allowed) const {
  if (!node_->is_object()) return Error("expected an object");
  for (const auto& [key, value] : node_->items()) {
    bool known = false;
    for (const char* a : allowed) known = known || key == a;
    if (!known) {
      std::string list;
      for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
      return Error(key, absl::StrCat("unknown field (known: ", list, ")"));
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<std::string> ReadTextFile(const std::string& path) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return absl::NotFoundError(absl::StrCat(path, ": cannot read: ", ec.message()));
  constexpr std::uintmax_t kMaxTextFile = 64u << 20;
  if (size > kMaxTextFile)
    return absl::InvalidArgumentError(absl::StrCat(path, ": too large (", size, " bytes)"));
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open: ", std::strerror(errno)));
  std::ostringstream text;
  text << in.rdbuf();
  if (!in.good() && !in.eof()) return absl::DataLossError(absl::StrCat(path, ": read error"));
  return text.str();
}

absl::StatusOr<JsonDocument> JsonDocument::FromFile(const std::string& path) {
  absl::StatusOr<std::string> text = ReadTextFile(path);
  if (!text.ok()) return text.status();
  return FromText(*text, path);
}

absl::StatusOr<JsonDocument> JsonDocument::FromText(const std::string& text,
                                                    const std::string& source) {
  JsonDocument doc;
  doc.source_ = std::make_shared<const std::string>(source);
  // The non-throwing parse: request and file data must never reach an exception.
  nlohmann::json tree = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (tree.is_discarded()) {
    // Locate the syntax error with the SAX parser's byte position, as a line and column.
    struct Locator : nlohmann::json_sax<nlohmann::json> {
      size_t position = 0;
      bool null() override { return true; }
      bool boolean(bool) override { return true; }
      bool number_integer(number_integer_t) override { return true; }
      bool number_unsigned(number_unsigned_t) override { return true; }
      bool number_float(number_float_t, const string_t&) override { return true; }
      bool string(string_t&) override { return true; }
      bool binary(binary_t&) override { return true; }
      bool start_object(std::size_t) override { return true; }
      bool key(string_t&) override { return true; }
      bool end_object() override { return true; }
      bool start_array(std::size_t) override { return true; }
      bool end_array() override { return true; }
      bool parse_error(std::size_t pos, const std::string&,
                       const nlohmann::detail::exception&) override {
        position = pos;
        return false;
      }
    } locator;
    nlohmann::json::sax_parse(text, &locator, nlohmann::json::input_format_t::json, false);
    size_t line = 1, column = 1;
    for (size_t i = 0; i + 1 < locator.position && i < text.size(); ++i) {
      if (text[i] == '\n') {
        ++line;
        column = 1;
      } else {
        ++column;
      }
    }
    return absl::InvalidArgumentError(
        absl::StrCat(source, ":", line, ":", column, ": not valid JSON"));
  }
  doc.tree_ = std::make_unique<nlohmann::json>(std::move(tree));
  return doc;
}

absl::StatusOr<JsonField> JsonDocument::Root() const {
  JsonField root(tree_.get(), source_, "");
  if (!tree_->is_object()) return root.Error("expected a JSON object");
  return root;
}

std::string JsonFileText(const nlohmann::json& j) { return j.dump(2) + "\n"; }

absl::Status WriteJsonFile(const std::string& path, const nlohmann::json& j) {
  const std::string tmp = path + ".tmp";
  const std::string text = JsonFileText(j);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0)
    return absl::InternalError(absl::StrCat(tmp, ": cannot create: ", std::strerror(errno)));
  size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = errno;
      ::close(fd);
      return absl::InternalError(absl::StrCat(tmp, ": write failed: ", std::strerror(err)));
    }
    done += static_cast<size_t>(n);
  }
  const bool synced = ::fsync(fd) == 0;
  const int sync_errno = errno;
  if (::close(fd) != 0 || !synced) {
    return absl::InternalError(
        absl::StrCat(tmp, ": sync failed: ", std::strerror(synced ? errno : sync_errno)));
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    return absl::InternalError(absl::StrCat(path, ": rename failed: ", std::strerror(errno)));
  }
  return absl::OkStatus();
}

}  // namespace linecal

#pragma once
// Reading JSON documents (station layouts, car models, capture manifests, configs) with errors
// that name the file, the field's path and the bad value:
//   "deploy/cars/reference.json: sensors[2].intrinsics.fx: must be > 0, got -5"
//
// JsonField is a cheap, non-owning cursor (a pointer to a node of a document the caller keeps
// alive, plus its path). Every accessor is O(key lookup) and returns absl::InvalidArgumentError
// on a missing field or a wrong type; numbers must be finite.

#include <cstdint>
#include <initializer_list>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace linecal {

class JsonField {
 public:
  // `source` names the document in messages (usually its file path); `path` is this node's
  // path from the root ("" for the root).
  JsonField(const nlohmann::json* node, std::shared_ptr<const std::string> source,
            std::string path);

  const nlohmann::json& node() const { return *node_; }
  const std::string& path() const { return path_; }
  const std::string& source() const { return *source_; }

  bool Has(const std::string& key) const;

  absl::StatusOr<JsonField> Object(const std::string& key) const;
  absl::StatusOr<std::vector<JsonField>> Array(const std::string& key) const;
  absl::StatusOr<std::string> String(const std::string& key) const;
  absl::StatusOr<double> Number(const std::string& key) const;
  absl::StatusOr<std::int64_t> Integer(const std::string& key) const;
  absl::StatusOr<bool> Bool(const std::string& key) const;
  // A numeric array of exactly `n` finite numbers (n = 0: any length).
  absl::StatusOr<std::vector<double>> Numbers(const std::string& key, size_t n = 0) const;

  // The same with a default when the key is absent (a present key of the wrong type is still an
  // error).
  absl::StatusOr<std::string> StringOr(const std::string& key, const std::string& fallback) const;
  absl::StatusOr<double> NumberOr(const std::string& key, double fallback) const;
  absl::StatusOr<std::int64_t> IntegerOr(const std::string& key, std::int64_t fallback) const;
  absl::StatusOr<bool> BoolOr(const std::string& key, bool fallback) const;

  // This node as a number / string (for array elements).
  absl::StatusOr<double> AsNumber() const;
  absl::StatusOr<std::string> AsString() const;

  // Fails on the first key not in `allowed`, so that a misspelt optional field is reported
  // instead of silently ignored.
  absl::Status AllowOnlyKeys(std::initializer_list<const char*> allowed) const;

  // "source: path.key: message" as an InvalidArgument status.
  absl::Status Error(const std::string& key, const std::string& message) const;
  // "source: path: message" (about this node itself).
  absl::Status Error(const std::string& message) const;

  // The path of a child key, e.g. "sensors[2]" + "fx" -> "sensors[2].fx".
  std::string ChildPath(const std::string& key) const;

 private:
  const nlohmann::json* node_;
  std::shared_ptr<const std::string> source_;
  std::string path_;
};

// A parsed JSON document that owns its tree; root() must not outlive it.
class JsonDocument {
 public:
  // Reads and parses a file. Errors name the file (and the line and column for syntax errors).
  static absl::StatusOr<JsonDocument> FromFile(const std::string& path);
  // Parses text; `source` names it in messages.
  static absl::StatusOr<JsonDocument> FromText(const std::string& text, const std::string& source);

  // The root, which must be an object.
  absl::StatusOr<JsonField> Root() const;

 private:
  JsonDocument() = default;
  std::unique_ptr<nlohmann::json> tree_;
  std::shared_ptr<const std::string> source_;
};

// The whole file as text. Errors name the file. Files over 64 MiB are refused: no document
// linecal reads comes near that, and the limit keeps a wrong path from eating memory.
absl::StatusOr<std::string> ReadTextFile(const std::string& path);

// Writes `j` to `path` atomically (a temporary file in the same directory, fsync, rename), so
// a crash never leaves a half-written document. Indented for people to read.
absl::Status WriteJsonFile(const std::string& path, const nlohmann::json& j);

// The text WriteJsonFile writes for `j` (indented by two, one final newline), for a document
// that is served instead of written with the same bytes.
std::string JsonFileText(const nlohmann::json& j);

}  // namespace linecal

#include "station/io/input_budget.h"

#include <limits>
#include <system_error>
#include <utility>

#include "absl/strings/str_cat.h"

namespace linecal {

InputBudget InputBudget::Unlimited() {
  constexpr std::int64_t kNone = std::numeric_limits<std::int64_t>::max();
  return {kNone, kNone, kNone, kNone, kNone};
}

absl::Status InputBudget::Validate() const {
  const std::pair<const char*, std::int64_t> limits[] = {
      {"max_file_bytes", max_file_bytes},
      {"max_image_pixels", max_image_pixels},
      {"max_scan_points", max_scan_points},
      {"max_can_lines", max_can_lines},
      {"max_manifest_frames", max_manifest_frames}};
  for (const auto& [key, value] : limits) {
    if (value < 1) {
      return absl::InvalidArgumentError(
          absl::StrCat("input_budget.", key, ": must be >= 1, got ", value));
    }
  }
  return absl::OkStatus();
}

std::string OverBudgetText(std::int64_t value, std::string_view what, std::int64_t limit,
                           std::string_view key) {
  return absl::StrCat(value, " ", std::string(what), " exceed the budget of ", limit,
                      " (input_budget.", std::string(key), ")");
}

absl::Status OverBudget(std::string_view file, std::int64_t value, std::string_view what,
                        std::int64_t limit, std::string_view key) {
  return absl::InvalidArgumentError(
      absl::StrCat(std::string(file), ": ", OverBudgetText(value, what, limit, key)));
}

absl::Status CheckFileBytes(const std::filesystem::path& path, const InputBudget& budget) {
  std::error_code ec;
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec) return absl::OkStatus();
  if (size > static_cast<std::uintmax_t>(budget.max_file_bytes)) {
    return OverBudget(path.string(), static_cast<std::int64_t>(size), "bytes",
                      budget.max_file_bytes, "max_file_bytes");
  }
  return absl::OkStatus();
}

std::string Snippet(std::string_view text, std::size_t max_chars) {
  std::string out = "'";
  for (char c : text.substr(0, max_chars)) out += (c >= 0x20 && c < 0x7F) ? c : '?';
  if (text.size() > max_chars) out += "...";
  return out + "'";
}

}  // namespace linecal

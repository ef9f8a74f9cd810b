#pragma once
// The one verdict of a sensor or a cycle (docs/interfaces.md), from the solvers through the
// pipeline and the store to the APIs (the gRPC mapping is daemon/service's):
//   pass   measured within tolerance and trustworthy
//   fail   measured, out of tolerance or not trustworthy
//   error  could not be measured (sensor silent, board not found, ...)
// "No verdict yet" (a running cycle, an event without one) is std::nullopt where it occurs.

#include <optional>
#include <string_view>

namespace linecal {

enum class Verdict { kPass, kFail, kError };

// "pass", "fail", "error": the words of results JSON, the store and the console. Pure.
// Inline (header-only): every library that holds a verdict names it.
constexpr const char* VerdictName(Verdict verdict) {
  switch (verdict) {
    case Verdict::kPass:
      return "pass";
    case Verdict::kFail:
      return "fail";
    case Verdict::kError:
      return "error";
  }
  return "error";
}

// The inverse of VerdictName; nullopt for any other word (the empty one too). Pure.
constexpr std::optional<Verdict> ParseVerdict(std::string_view name) {
  for (Verdict v : {Verdict::kPass, Verdict::kFail, Verdict::kError}) {
    if (name == VerdictName(v)) return v;
  }
  return std::nullopt;
}

}  // namespace linecal

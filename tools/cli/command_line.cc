#include "tools/cli/command_line.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

namespace linecal::cli {

CommandLine::CommandLine(std::string usage, std::string summary, std::vector<OptionSpec> options)
    : usage_(std::move(usage)), summary_(std::move(summary)), options_(std::move(options)) {}

const OptionSpec* CommandLine::Find(const std::string& name) const {
  for (const OptionSpec& o : options_) {
    if (o.name == name) return &o;
  }
  return nullptr;
}

absl::Status CommandLine::Parse(const std::vector<std::string>& args) {
  std::vector<const OptionSpec*> positionals;
  for (const OptionSpec& o : options_) {
    if (o.positional) positionals.push_back(&o);
  }
  size_t next_positional = 0;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& arg = args[i];
    if (arg == "--help" || arg == "-h") {
      help_requested_ = true;
      return absl::OkStatus();
    }
    if (arg.rfind("--", 0) != 0) {
      if (next_positional == positionals.size()) {
        return absl::InvalidArgumentError(absl::StrCat("unexpected argument '", arg, "'"));
      }
      values_[positionals[next_positional++]->name].push_back(arg);
      continue;
    }
    std::string name = arg.substr(2);
    std::optional<std::string> inline_value;
    if (const size_t eq = name.find('='); eq != std::string::npos) {
      inline_value = name.substr(eq + 1);
      name = name.substr(0, eq);
    }
    const OptionSpec* spec = Find(name);
    if (spec == nullptr || spec->positional) {
      return absl::InvalidArgumentError(absl::StrCat("unknown option --", name));
    }
    std::string value;
    if (spec->metavar.empty()) {
      if (inline_value) {
        return absl::InvalidArgumentError(absl::StrCat("--", name, " takes no value"));
      }
    } else if (inline_value) {
      value = *inline_value;
    } else {
      if (i + 1 >= args.size()) {
        return absl::InvalidArgumentError(
            absl::StrCat("--", name, " needs a value (", spec->metavar, ")"));
      }
      value = args[++i];
    }
    auto& slot = values_[name];
    if (!spec->repeated && !slot.empty()) {
      return absl::InvalidArgumentError(absl::StrCat("--", name, " given twice"));
    }
    slot.push_back(std::move(value));
  }
  for (const OptionSpec& o : options_) {
    if (o.required && !Has(o.name)) {
      return absl::InvalidArgumentError(absl::StrCat("missing ", o.positional ? "" : "--", o.name));
    }
  }
  return absl::OkStatus();
}

std::string CommandLine::Help() const {
  std::ostringstream out;
  out << "usage: " << usage_ << "\n\n" << summary_ << "\n\noptions:\n";
  for (const OptionSpec& o : options_) {
    std::string left =
        o.positional ? "  " + o.name : "  --" + o.name + (o.metavar.empty() ? "" : " " + o.metavar);
    out << left;
    // Align help text in a column; 28 fits the longest option names in use.
    constexpr size_t kHelpColumn = 28;
    out << std::string(left.size() < kHelpColumn ? kHelpColumn - left.size() : 1, ' ') << o.help;
    if (o.required) out << " (required)";
    if (o.repeated) out << " (repeatable)";
    out << "\n";
  }
  out << "  --help                    this text\n";
  return out.str();
}

bool CommandLine::Has(const std::string& name) const { return values_.count(name) > 0; }

std::string CommandLine::Get(const std::string& name, const std::string& fallback) const {
  const auto it = values_.find(name);
  return it == values_.end() ? fallback : it->second.front();
}

std::vector<std::string> CommandLine::GetAll(const std::string& name) const {
  const auto it = values_.find(name);
  return it == values_.end() ? std::vector<std::string>{} : it->second;
}

absl::StatusOr<double> CommandLine::GetDouble(const std::string& name, double fallback) const {
  if (!Has(name)) return fallback;
  const std::string s = Get(name);
  double v = 0;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size() || !std::isfinite(v)) {
    return absl::InvalidArgumentError(absl::StrCat("--", name, ": '", s, "' is not a number"));
  }
  return v;
}

absl::StatusOr<std::vector<double>> ParseNumberList(const std::string& text,
                                                    const std::string& what, size_t count) {
  std::vector<double> out;
  for (const absl::string_view part : absl::StrSplit(text, ',')) {
    double v = 0;
    const auto [end, ec] = std::from_chars(part.data(), part.data() + part.size(), v);
    if (part.empty() || ec != std::errc() || end != part.data() + part.size() ||
        !std::isfinite(v)) {
      return absl::InvalidArgumentError(absl::StrCat(what, ": '", part, "' is not a number"));
    }
    out.push_back(v);
  }
  if (count > 0 && out.size() != count) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, ": ", count, " comma-separated numbers needed, got ", out.size()));
  }
  return out;
}

absl::StatusOr<int> CommandLine::GetInt(const std::string& name, int fallback) const {
  if (!Has(name)) return fallback;
  const std::string s = Get(name);
  int v = 0;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size()) {
    return absl::InvalidArgumentError(
        absl::StrCat("--", name, ": '", s, "' is not a whole number"));
  }
  return v;
}

}  // namespace linecal::cli

namespace linecal::cli {

std::optional<int> ParseOrExit(CommandLine& cl, const std::string& command,
                               const std::vector<std::string>& args) {
  if (const absl::Status s = cl.Parse(args); !s.ok()) {
    return BadInput(command, std::string(s.message()));
  }
  if (cl.help_requested()) {
    std::fputs(cl.Help().c_str(), stdout);
    return kExitOk;
  }
  return std::nullopt;
}

int BadInput(const std::string& command, const std::string& message) {
  std::fprintf(stderr, "linecal %s: %s\n", command.c_str(), message.c_str());
  return kExitBadInput;
}

}  // namespace linecal::cli

#pragma once
// Statistics shared by the `linecal eval ...` programs: percentiles and the checks of a
// reported 1-sigma against the spread of the errors it describes (acceptance.md).

#include <algorithm>
#include <cmath>
#include <span>
#include <vector>

namespace linecal::tools {

// The two-sided 95% quantile of the standard normal distribution.
inline constexpr double kZ95 = 1.959964;

// The q-quantile (0..1) of v, linear between order statistics; 0 for an empty v. O(n log n).
inline double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(pos));
  const size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (pos - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

struct ErrorSigmaStats {
  int n = 0;
  double p95_abs_error = 0;
  double rms_error = 0;
  double rms_sigma = 0;
  double error_over_sigma = 0;  // RMS error / RMS reported sigma: 1 when the sigma is right
  double coverage95 = 0;        // share of |error| <= 1.96 sigma: 0.95 when it is right
};

// errors[i] (estimate - truth) with their reported 1-sigma sigmas[i]; same length. O(n log n).
inline ErrorSigmaStats SummariseErrors(std::span<const double> errors, std::span<const double> sigmas) {
  ErrorSigmaStats s;
  s.n = static_cast<int>(errors.size());
  if (errors.empty()) return s;
  std::vector<double> abs_errors;
  double sum_e2 = 0, sum_s2 = 0;
  int covered = 0;
  for (size_t i = 0; i < errors.size(); ++i) {
    abs_errors.push_back(std::abs(errors[i]));
    sum_e2 += errors[i] * errors[i];
    sum_s2 += sigmas[i] * sigmas[i];
    covered += std::abs(errors[i]) <= kZ95 * sigmas[i];
  }
  const double n = static_cast<double>(errors.size());
  s.p95_abs_error = Percentile(std::move(abs_errors), 0.95);
  s.rms_error = std::sqrt(sum_e2 / n);
  s.rms_sigma = std::sqrt(sum_s2 / n);
  s.error_over_sigma = s.rms_sigma > 0 ? s.rms_error / s.rms_sigma : 0;
  s.coverage95 = covered / n;
  return s;
}

}  // namespace linecal::tools

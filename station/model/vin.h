#pragma once
// Vehicle identification numbers (ISO 3779).

#include <string>

#include "absl/status/status.h"

namespace linecal {

// OK when `vin` has 17 characters from 0-9 and A-Z without I, O and Q (ISO 3779). With
// `check_digit`, position 9 must also be the North American check digit (49 CFR 565; other
// markets do not use it, so it is switchable). Errors say what is wrong and where
// ("character 5 'O' is not allowed (I, O, Q never appear in a VIN)"). O(17).
absl::Status ValidateVin(const std::string& vin, bool check_digit);

// The check digit ('0'..'9' or 'X') of a VIN made of allowed characters.
char VinCheckDigit(const std::string& vin);

}  // namespace linecal

#include "station/model/vin.h"

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

// ISO 3779 / 49 CFR 565 transliteration of letters to values; I, O, Q have none.
int VinValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  switch (c) {
    case 'A':
    case 'J':
      return 1;
    case 'B':
    case 'K':
    case 'S':
      return 2;
    case 'C':
    case 'L':
    case 'T':
      return 3;
    case 'D':
    case 'M':
    case 'U':
      return 4;
    case 'E':
    case 'N':
    case 'V':
      return 5;
    case 'F':
    case 'W':
      return 6;
    case 'G':
    case 'P':
    case 'X':
      return 7;
    case 'H':
    case 'Y':
      return 8;
    case 'R':
    case 'Z':
      return 9;
    default:
      return -1;
  }
}

// Position weights of 49 CFR 565.15; position 9 (the check digit itself) weighs 0.
constexpr int kWeights[17] = {8, 7, 6, 5, 4, 3, 2, 10, 0, 9, 8, 7, 6, 5, 4, 3, 2};
constexpr size_t kVinLength = 17;

}  // namespace

char VinCheckDigit(const std::string& vin) {
  int sum = 0;
  for (size_t i = 0; i < kVinLength && i < vin.size(); ++i) sum += VinValue(vin[i]) * kWeights[i];
  const int r = sum % 11;
  return r == 10 ? 'X' : static_cast<char>('0' + r);
}

absl::Status ValidateVin(const std::string& vin, bool check_digit) {
  if (vin.size() != kVinLength) {
    return absl::InvalidArgumentError(absl::StrCat("must have 17 characters, has ", vin.size()));
  }
  for (size_t i = 0; i < vin.size(); ++i) {
    const char c = vin[i];
    if (c == 'I' || c == 'O' || c == 'Q') {
      return absl::InvalidArgumentError(
          absl::StrCat("character ", i + 1, " '", std::string(1, c),
                       "' is not allowed (I, O, Q never appear in a VIN)"));
    }
    if (VinValue(c) < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("character ", i + 1, " is not an upper-case letter or digit (0x",
                       absl::Hex(static_cast<unsigned char>(c)), ")"));
    }
  }
  if (check_digit && vin[8] != VinCheckDigit(vin)) {
    return absl::InvalidArgumentError(absl::StrCat("check digit (character 9) is '",
                                                   std::string(1, vin[8]), "', expected '",
                                                   std::string(1, VinCheckDigit(vin)), "'"));
  }
  return absl::OkStatus();
}

}  // namespace linecal

#pragma once
// Crafted input files for the input-budget tests (issue 21): small files whose headers claim
// huge sizes, written byte by byte so that no library decides what they contain.

#include <cstdint>
#include <string>

namespace linecal::testing_support {

// The CRC-32 of PNG chunks (ISO 3309, as in the PNG specification's annex).
inline std::uint32_t PngCrc32(const std::string& bytes) {
  std::uint32_t crc = 0xFFFFFFFFu;
  for (unsigned char b : bytes) {
    crc ^= b;
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return crc ^ 0xFFFFFFFFu;
}

inline std::string Be32(std::uint32_t v) {
  return {static_cast<char>(v >> 24), static_cast<char>(v >> 16), static_cast<char>(v >> 8),
          static_cast<char>(v)};
}

inline std::string PngChunk(const std::string& type, const std::string& data) {
  return Be32(static_cast<std::uint32_t>(data.size())) + type + data + Be32(PngCrc32(type + data));
}

// A 74-byte PNG claiming 16384 x 16384 RGB, 16 bits a sample (1.6 GB decoded, 268435456
// pixels): signature, IHDR, a 17-byte IDAT (the start of a zlib stream), IEND.
inline std::string HugeClaimPng() {
  const std::string signature = "\x89PNG\r\n\x1a\n";
  constexpr std::uint32_t kSide = 16384;
  const std::string ihdr = Be32(kSide) + Be32(kSide) + std::string("\x10\x02\x00\x00\x00", 5);
  const std::string idat("\x78\x01\x00\x00\x80\xff\x7f\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00",
                         17);
  return signature + PngChunk("IHDR", ihdr) + PngChunk("IDAT", idat) + PngChunk("IEND", "");
}

}  // namespace linecal::testing_support

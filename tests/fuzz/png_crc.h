// libpng rejects a chunk whose CRC does not match, so random mutations of a PNG almost never
// reach its decoder. The PNG targets mutate with libFuzzer's own mutator, then recompute the
// CRC of every chunk, as libpng's own fuzzer gets by switching the check off.
#pragma once

#include <zlib.h>

#include <cstddef>
#include <cstdint>
#include <cstring>

namespace carvemap::fuzz {

// Recomputes the CRC of each chunk of the PNG in [data, data + size) that lies wholly inside.
inline void FixPngCrcs(uint8_t* data, size_t size) {
  static const uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (size < 8 || std::memcmp(data, kSignature, 8) != 0) return;
  size_t pos = 8;
  while (pos + 12 <= size) {
    const uint32_t length = uint32_t{data[pos]} << 24 | uint32_t{data[pos + 1]} << 16 |
                            uint32_t{data[pos + 2]} << 8 | data[pos + 3];
    if (length > size - pos - 12) return;
    const uint32_t crc = static_cast<uint32_t>(crc32(0, data + pos + 4, length + 4));
    uint8_t* out = data + pos + 8 + length;
    out[0] = static_cast<uint8_t>(crc >> 24);
    out[1] = static_cast<uint8_t>(crc >> 16);
    out[2] = static_cast<uint8_t>(crc >> 8);
    out[3] = static_cast<uint8_t>(crc);
    pos += 12 + length;
  }
}

}  // namespace carvemap::fuzz

extern "C" size_t LLVMFuzzerMutate(uint8_t* data, size_t size, size_t max_size);

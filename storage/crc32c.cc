#include "storage/crc32c.h"

#include <cstring>

namespace carvemap {
namespace {

// The table, for CPUs without SSE4.2.
struct Crc32cTable {
  uint32_t t[256];
  constexpr Crc32cTable() : t() {
    for (uint32_t i = 0; i < 256; ++i) {
      uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? (c >> 1) ^ 0x82f63b78u : c >> 1;
      t[i] = c;
    }
  }
};
constexpr Crc32cTable kCrcTable;

#if defined(__x86_64__)
// SSE4.2's crc32 instruction computes this very checksum: a worker reads every byte of its
// inputs through it, and the table costs a few ns per byte.
__attribute__((target("sse4.2"))) uint32_t Crc32cHardware(uint32_t c, std::string_view data) {
  const char* p = data.data();
  size_t n = data.size();
  uint64_t c64 = c;
  for (; n >= 8; n -= 8, p += 8) {
    uint64_t v;
    std::memcpy(&v, p, 8);
    c64 = __builtin_ia32_crc32di(c64, v);
  }
  c = uint32_t(c64);
  for (; n > 0; --n, ++p) c = __builtin_ia32_crc32qi(c, static_cast<unsigned char>(*p));
  return c;
}
const bool kHasSse42 = __builtin_cpu_supports("sse4.2");
#endif

}  // namespace

uint32_t Crc32cExtend(uint32_t crc, std::string_view data) {
  uint32_t c = ~crc;
#if defined(__x86_64__)
  if (kHasSse42) return ~Crc32cHardware(c, data);
#endif
  for (unsigned char b : data) c = kCrcTable.t[(c ^ b) & 0xff] ^ (c >> 8);
  return ~c;
}

uint32_t Crc32c(std::string_view data) { return Crc32cExtend(0, data); }

}  // namespace carvemap

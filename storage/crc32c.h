// CRC-32C (Castagnoli): the checksum of the files carvemap writes for itself (partial sums and
// the regions of a re-carve pass). Plain (unmasked), initial value 0xffffffff and final inversion, as leveldb's
// crc32c::Value and iSCSI; "123456789" checksums to 0xe3069283.
#pragma once

#include <cstdint>
#include <string_view>

namespace carvemap {

[[nodiscard]] uint32_t Crc32c(std::string_view data);
// Extends `crc` (of earlier bytes; 0 for none) with `data`: Crc32cExtend(Crc32c(a), b) is
// Crc32c(a + b).
[[nodiscard]] uint32_t Crc32cExtend(uint32_t crc, std::string_view data);

}  // namespace carvemap

// Internal to the importers: the compressed blocks that bag formats carry (ROS 1 chunks: bz2 or
// lz4; MCAP chunks: zstd or lz4), each decompressed whole into a buffer of the size its
// container states. Debian's libbz2, liblz4 and libzstd do the work.
#pragma once

#include <cstdint>
#include <span>

#include "absl/status/status.h"

namespace carvemap::import_internal {

// Each fills `out` exactly or says why not ("does not decompress to its N bytes (…)"); the
// caller names the file and the record.
absl::Status DecompressBz2(std::span<const uint8_t> in, std::span<uint8_t> out);
// LZ4's frame format (what MCAP and ROS 1's roslz4 write).
absl::Status DecompressLz4Frame(std::span<const uint8_t> in, std::span<uint8_t> out);
absl::Status DecompressZstd(std::span<const uint8_t> in, std::span<uint8_t> out);

}  // namespace carvemap::import_internal

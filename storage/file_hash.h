// SHA-256 of a file, for TileInfo (carve.proto), FetchArtifact's last chunk and uploads.
#ifndef CARVEMAP_STORAGE_FILE_HASH_H_
#define CARVEMAP_STORAGE_FILE_HASH_H_

#include <string>

#include "absl/status/statusor.h"

namespace carvemap {

// Lower-case hex. NOT_FOUND / INTERNAL naming the file when it cannot be read.
absl::StatusOr<std::string> Sha256HexOfFile(const std::string& path);
// Lower-case hex SHA-256 of `bytes`.
std::string Sha256Hex(const std::string& bytes);

}  // namespace carvemap

#endif  // CARVEMAP_STORAGE_FILE_HASH_H_

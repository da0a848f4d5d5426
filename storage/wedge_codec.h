// Wedge records (storage/WEDGE_FORMAT.md): the bytes of the coordinator's chunk spill files and
// of the wedge payload sent to workers. Little-endian, float32, byte-exact: the same wedges
// always give the same bytes, and decoding then encoding gives the input back.
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/geometry/carving_types.h"

namespace carvemap {

inline constexpr size_t kRayRecordBytes = 72;  // 18 float32
// 1 byte num_rays, then num_rays ray records: 73 bytes for a single ray, 289 for four.
[[nodiscard]] constexpr size_t WedgeRecordBytes(int num_rays) {
  return 1 + kRayRecordBytes * static_cast<size_t>(num_rays);
}

// OK iff num_rays is in [1, 4] and every value of its rays is finite.
[[nodiscard]] absl::Status ValidateWedge(const Wedge& wedge);

// Appends the wedge's record to `out`. REQUIRES: ValidateWedge(wedge).ok() (a num_rays outside
// [1, 4] is not representable; non-finite values would be written and rejected on decode).
void AppendWedgeRecord(const Wedge& wedge, std::string& out);
[[nodiscard]] std::string EncodeWedges(std::span<const Wedge> wedges);

// The wedges of a concatenation of records, in order. Rays beyond num_rays are zero. Errors:
// DataLoss naming the record and byte offset for a truncated record, a num_rays outside [1, 4]
// or a non-finite value.
[[nodiscard]] absl::StatusOr<std::vector<Wedge>> DecodeWedges(std::string_view bytes);

}  // namespace carvemap

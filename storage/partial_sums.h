// Partial sums: what carving one time slice of a scan leaves for each 2 m chunk it touched,
// before the chunk's slices are added up and simplified (§4.3.2) into its tile. Eq 4.8 keeps
// a leaf as sums (LeafStats), so a chunk's tile is the sum of its slices' sums.
// One file per slice: storage/PARTIAL_FORMAT.md. Nothing here knows about carving.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/chunk_region.h"
#include "geometry/octree_keys.h"
#include "storage/tile_store.h"

namespace carvemap {

// One chunk's part of a file: its finest leaves' sums (a chunk may have several sections in
// one file, in file order, when the writer flushed its sums more than once).
struct PartialSection {
  ChunkKey chunk = ChunkKey::Zero();
  uint64_t wedges = 0;  // wedges carved into these sums (for the tile's num_wedges)
  uint64_t leaves = 0;
  uint64_t offset = 0;        // of its first stored byte in the file
  uint64_t stored_bytes = 0;  // its bytes in the file (compressed from version 2)
  uint32_t crc = 0;           // CRC-32C of its stored bytes
};

struct PartialSumsIndex {
  uint32_t version = 0;
  int chunk_depth = 0;
  uint32_t slice = 0;
  std::vector<PartialSection> sections;  // in file order
};

// Writes a file through "<path>.<random>.tmp": sections as they come, the index last, then
// fsync and a rename, so a file under its final name is complete. Not thread-safe.
class PartialSumsWriter {
 public:
  static absl::StatusOr<std::unique_ptr<PartialSumsWriter>> Create(const std::string& path,
                                                                  int chunk_depth,
                                                                  uint32_t slice);
  ~PartialSumsWriter();  // removes the .tmp file of an unfinished writer
  PartialSumsWriter(const PartialSumsWriter&) = delete;
  PartialSumsWriter& operator=(const PartialSumsWriter&) = delete;

  // `leaves`: finest leaves (depth = chunk_depth) of `chunk`, any order, distinct; they are
  // written sorted by local coordinates (z, y, x). InvalidArgument for another depth or a
  // local coordinate outside the chunk; I/O errors name the file.
  absl::Status AddSection(const ChunkKey& chunk, uint64_t wedges,
                          std::span<const TileLeaf> leaves);
  // The index and trailer, fsync, rename. Returns the file's size.
  absl::StatusOr<uint64_t> Finish();

 private:
  struct Impl;
  explicit PartialSumsWriter(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Reads and checks the header, trailer and index (sizes, checksums). NotFound for a missing
// file; DataLoss naming the file for a truncated or corrupt one.
[[nodiscard]] absl::StatusOr<PartialSumsIndex> ReadPartialIndex(const std::string& path);
// Appends the section's leaves to `out` (depth chunk_depth), after checking its checksum
// (DataLoss naming the file and chunk otherwise).
[[nodiscard]] absl::Status ReadPartialSection(const std::string& path, const PartialSumsIndex& index,
                                              const PartialSection& section,
                                              std::vector<TileLeaf>& out);

// §5.6.1's re-carving pass: the chunks to carve again and each one's region, in one file that
// every slice of the pass reads (storage/PARTIAL_FORMAT.md "Regions"). The writer takes the
// regions encoded, as the coordinator receives them, and writes them in ChunkKeyLess order
// (InvalidArgument naming a chunk listed twice or a region that does not decode). Written
// through "<path>.<random>.tmp" and renamed; I/O errors name the file. The reader keeps them
// encoded (each region's bits checked against its depth; a slice decodes those it reaches):
// NotFound for a missing file, DataLoss naming the file for a damaged one.
[[nodiscard]] absl::Status WriteRegionsFile(const std::string& path,
                                            std::span<const RecarveChunk> regions);
[[nodiscard]] absl::StatusOr<RecarveRegionMap> ReadRegionsFile(const std::string& path);

}  // namespace carvemap

// A chunk's tile from its slices' partial sums (docs/DESIGN.md §5): eq 4.8's sums of every slice
// that carved into the chunk (worker/slice_carver.h) added up in slice order, the leaves no slice
// observed dropped (they held only scan points), §4.3.2's simplification, one tile. The sums
// are the whole scan's carve of the chunk up to floating-point rounding (the order of the
// additions follows the slices), and the same bytes whatever worker combines them.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "geometry/octree_keys.h"
#include "storage/partial_sums.h"

namespace carvemap {

struct CarveChunkResult {
  std::string tile_path;
  uint64_t tile_bytes = 0;
  uint64_t wedges = 0, leaves = 0;
  double elapsed_s = 0;
};

// One slice's partial sums file and its index (ReadPartialIndex).
struct PartialSource {
  std::string path;
  PartialSumsIndex index;
};

// Where each chunk's sections are: (source, section) pairs in source order, then file order.
using SectionsByChunk =
    std::map<ChunkKey, std::vector<std::pair<size_t, size_t>>, ChunkKeyLess>;
[[nodiscard]] SectionsByChunk GroupSections(const std::vector<PartialSource>& sources);

struct CombineChunkRequest {
  std::string job_id;
  ChunkKey chunk = ChunkKey::Zero();
  OctreeGrid grid;                             // every source's chunk depth
  const std::vector<PartialSource>* sources = nullptr;
  std::vector<std::pair<size_t, size_t>> sections;  // this chunk's, from GroupSections
  std::string tiles_dir;                       // the tile is written here (atomically)
};

// Errors name the chunk (and the file, for damaged sums); a source of another chunk depth is
// InvalidArgument. CarveChunkResult::wedges is the sum of the sections' wedges.
absl::StatusOr<CarveChunkResult> CombineChunkToTile(const CombineChunkRequest& request);

}  // namespace carvemap

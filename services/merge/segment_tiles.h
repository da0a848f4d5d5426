// The merge shell around segment_chunk.h (docs/DESIGN.md §6 stages 6–7): every tile of a job
// segmented against the extruded floor plans, chunk by chunk through the TileSet's bounded cache,
// into two tile directories that the existing stages then mesh (building: planar mesh; objects:
// dense mesh). Out of core: a few decoded neighbourhoods per thread in, two tiles out each, at a
// time.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "services/merge/dense_mesh.h"
#include "services/merge/tile_set.h"
#include "services/segment/segment_chunk.h"

namespace carvemap {

struct SegmentTilesResult {
  uint64_t chunks = 0;
  uint64_t building_tiles = 0;
  uint64_t object_tiles = 0;            // chunks with at least one object cell
  std::vector<ChunkKey> object_chunks;  // those chunks, in the TileSet's order
  uint64_t object_cells = 0;            // finest cells
  uint64_t unobserved_object_cells = 0;
  uint64_t trimmed_cells = 0;
};

// Writes building tiles to `building_dir` and object tiles to `objects_dir` (both created;
// tiles replace any there). An empty `building_dir` writes no building tiles (the finer
// re-carving of §5.6.1 wants the objects only). `only_in` (that pass): each chunk's objects
// only inside its region (SegmentChunk), decoded by the thread that segments the chunk; a
// chunk not in the map has none. Only chunks with a tile are segmented: object volume in a
// chunk that no wedge reached is not found. Errors: TileSet::Get's, SegmentChunk's, WriteTile's
// (naming the file), Unavailable naming a directory that cannot be created, Cancelled. The
// chunks are segmented on `threads` threads and written in order on the calling thread: the
// tiles do not depend on the thread count.
[[nodiscard]] absl::StatusOr<SegmentTilesResult> SegmentTiles(
    TileSet& tiles, const PlanVolume& plan, const SegmentOptions& options,
    const std::string& building_dir, const std::string& objects_dir,
    const ChunkProgressFn& progress, int threads, const RecarveRegionMap* only_in = nullptr);

}  // namespace carvemap

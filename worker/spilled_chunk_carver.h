// Carves every chunk of an ingest in this process with a pool of threads: what `carvemap carve`
// and the accuracy test run, and the baseline the distributed workers are compared against.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "coordinator/chunk_spill.h"
#include "services/geometry/chunk_region.h"
#include "services/geometry/octree_keys.h"
#include "worker/chunk_octree.h"

namespace carvemap {

struct SpilledChunkCarveOptions {
  OctreeGrid grid;
  std::string job_id;     // recorded in every tile
  std::string tiles_dir;  // must exist
  int threads = 1;
  CarveEvaluation evaluation = CarveEvaluation::kFast;  // worker/chunk_octree.h
  // §5.6.1's second pass: a chunk listed here is carved only inside its region.
  std::map<ChunkKey, ChunkRegion, ChunkKeyLess> regions;
};

struct SpilledChunkCarveProgress {
  size_t chunks_done = 0, chunks_total = 0;
  // Wedge-chunk pairs carved so far and in all: a chunk's cost is roughly its wedge count.
  uint64_t pairs_done = 0, pairs_total = 0;
};

struct SpilledChunkCarveTotals {
  std::vector<std::string> tile_paths;  // in the order of the chunks given
  uint64_t tile_bytes = 0, leaves = 0, leaf_updates = 0;
};

// Carves `chunks` (each from its spill file) into tiles, biggest chunks first. Stops at the
// first error and returns it; tiles written before then stay (each is complete: atomic
// writes), so callers discard the directory. `progress` is called from this thread about every
// 250 ms and at the end.
absl::StatusOr<SpilledChunkCarveTotals> CarveSpilledChunks(
    const std::vector<SpilledChunk>& chunks, const SpilledChunkCarveOptions& options,
    const std::function<void(const SpilledChunkCarveProgress&)>& progress = {});

// The spill files of `chunks` under `spill_dir` (an ingest's, kept for §5.6.1's re-carving of
// the object chunks at a finer grid). NotFound naming the file of a chunk the ingest did not
// spill. wedge_count is 0: the spill is not read here, so the carving order is the given one.
absl::StatusOr<std::vector<SpilledChunk>> FindSpilledChunks(const std::string& spill_dir,
                                                            const std::vector<ChunkKey>& chunks);

}  // namespace carvemap

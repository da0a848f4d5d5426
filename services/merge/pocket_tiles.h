// The merge shell around fill_pockets.h: a job's tiles with their thin unobserved pockets filled
// as free, into a directory the merge's stages then read in place of the job's own (the job's
// tiles, and octree.bt from them, keep the pockets unobserved). Out of core as segment_tiles.h:
// a few decoded neighbourhoods per thread.
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "services/merge/dense_mesh.h"
#include "services/merge/tile_set.h"
#include "services/segment/fill_pockets.h"

namespace carvemap {

struct PocketTilesResult {
  uint64_t chunks = 0;
  uint64_t filled_tiles = 0;  // chunks with at least one cell filled, written anew
  uint64_t filled_cells = 0;  // finest cells
};

// Writes every chunk of `tiles` (read from `tiles_dir`) into `out_dir` (created): a chunk with
// pockets as a new tile, any other as a hard link to its tile in `tiles_dir` (a copy where the
// file system has no hard links). Holds every chunk's candidate cells at once but for the
// tainted pockets inside one chunk (29 bytes each with their sets: a pocket may span chunks),
// then reads the chunks with filled cells a second time. Errors: TileSet::Get's,
// PocketCandidates', KeepFillablePocketCells', WriteTile's (naming the file), Unavailable naming
// a directory or file that cannot be created, Cancelled. The chunks are filled on `threads` threads and written
// in order on the calling thread: the tiles do not depend on the thread count.
[[nodiscard]] absl::StatusOr<PocketTilesResult> FillPocketTiles(
    TileSet& tiles, const std::string& tiles_dir, const std::string& out_dir,
    const PocketFillOptions& options, const ChunkProgressFn& progress, int threads);

}  // namespace carvemap

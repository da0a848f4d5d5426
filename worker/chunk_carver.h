// The worker's unit of work (DESIGN §5): the wedges of one 2 m chunk ➜ chunk octree (eq 4.8)
// ➜ simplified (§4.3.2) ➜ one tile. Deterministic: the same request gives the same tile bytes
// whichever worker runs it and however often.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/geometry/chunk_region.h"
#include "services/geometry/octree_keys.h"
#include "worker/chunk_octree.h"

namespace carvemap {

struct CarveChunkRequest {
  std::string job_id;
  ChunkKey chunk = ChunkKey::Zero();
  OctreeGrid grid;                 // resolution 2 m / 2^k
  std::string_view wedge_payload;  // wedge payload (storage/WEDGE_FORMAT.md), in spill order
  std::string tiles_dir;           // the tile is written here (atomically)
  double sigmas = 3.0;             // must match the ingest's
  // Carve only inside this part of the chunk (§5.6.1's second pass); null: the whole chunk.
  const ChunkRegion* region = nullptr;
  CarveEvaluation evaluation = CarveEvaluation::kFast;  // chunk_octree.h
  // If set, called with the wedges carved since its last call while the chunk is carved
  // (ChunkOctree::SetProgress); the calls add up to CarveChunkResult::wedges.
  std::function<void(uint64_t wedges)> progress;
};

struct CarveChunkResult {
  std::string tile_path;
  uint64_t tile_bytes = 0;
  uint64_t wedges = 0, leaf_updates = 0, leaves = 0;
  uint64_t leaf_touches = 0;  // (leaf, wedge) pairs the wedge hulls touched
  double elapsed_s = 0;
};

// Thread-compatible; tile writing serialises on HDF5 internally (storage/tile_store.h).
absl::StatusOr<CarveChunkResult> CarveChunkToTile(const CarveChunkRequest& request);

}  // namespace carvemap

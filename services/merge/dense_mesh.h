// The dense mesh (docs/DESIGN.md §7 mesh/dense.ply) and the boundary faces (docs/DESIGN.md §6 stage
// 1) of a whole tiles directory, out of core: chunk by chunk, each from the tiles of its
// neighbourhood fetched through the TileSet's bounded cache, then a small global step (the vertex
// weld, or concatenation of faces). No logging and no files written here; the merge shell does
// that.
//
// Chunks are computed on `threads` threads (the tiles are read on the caller's); the output is
// the same whatever their number.
//
// Memory: the cache budget plus a batch of four neighbourhoods per thread (at most 27 decoded
// tiles each, held while their chunk is processed) plus the output (the dense mesh welded as
// the chunks come, ChunkMeshWelder, with the chunk meshes of the last two x-columns).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <functional>
#include <vector>

#include "absl/status/statusor.h"
#include "services/merge/tile_set.h"
#include "services/mesh/boundary_faces.h"
#include "storage/ply_io.h"

namespace carvemap {

// Called after each chunk with (chunks done, chunks in total); returning false cancels the
// run, which then returns Cancelled.
using ChunkProgressFn = std::function<bool(uint64_t done, uint64_t total)>;

struct DenseMeshResult {
  TriangleMesh mesh;         // watertight; counter-clockwise seen from the interior
  // Per vertex: 1 when it lies on a surface between interior and observed exterior space
  // (evidence of scan points), 0 when it closes the carved volume against unobserved space.
  std::vector<uint8_t> vertex_observed;
  uint64_t chunks = 0;       // chunks meshed (tiles and their +1 neighbours)
  uint64_t polygons = 0;     // corner polygons before triangulation
  uint64_t centre_vertices = 0;
};

// The tiles of `chunk`'s 3×3×3 neighbourhood through the cache (only the slots with all offsets
// ≤ 0 when `low_only`); `hold` keeps them alive while the chunk is processed, whatever the
// cache evicts. Errors: TileSet::Get's.
[[nodiscard]] absl::StatusOr<ChunkNeighbourhood> FetchNeighbourhood(
    TileSet& tiles, const ChunkKey& chunk, bool low_only,
    std::array<std::shared_ptr<const TileData>, 27>& hold);

// Dual contouring (services/mesh/dual_contouring.h) of every tile of `tiles`. Errors: those of
// TileSet::Get (NotFound, DataLoss, InvalidArgument naming the file), of the per-chunk stage,
// or Cancelled.
[[nodiscard]] absl::StatusOr<DenseMeshResult> BuildDenseMesh(
    TileSet& tiles, const ChunkProgressFn& progress = nullptr, int threads = 1);

// All boundary faces of `tiles` (services/mesh/boundary_faces.h): the chunks' faces in
// ChunkKeyLess order of their interior leaf's chunk, each chunk's in its deterministic order.
[[nodiscard]] absl::StatusOr<std::vector<BoundaryFace>> CollectBoundaryFaces(
    TileSet& tiles, const ChunkProgressFn& progress = nullptr, int threads = 1);

}  // namespace carvemap

#include "services/merge/dense_mesh.h"

#include <array>
#include <memory>

#include "services/mesh/dual_contouring.h"

namespace carvemap {

// dense_mesh.h: the tiles of `chunk`'s neighbourhood (only slots with all offsets ≤ 0 when
// `low_only`). `hold` keeps them alive while the chunk is processed, whatever the cache evicts.
absl::StatusOr<ChunkNeighbourhood> FetchNeighbourhood(
    TileSet& tiles, const ChunkKey& chunk, bool low_only,
    std::array<std::shared_ptr<const TileData>, 27>& hold) {
  ChunkNeighbourhood hood;
  hood.grid = tiles.grid();
  hood.chunk = chunk;
  for (int dz = -1; dz <= 1; ++dz) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const int s = ChunkNeighbourhood::Index(dx, dy, dz);
        hold[s].reset();
        const ChunkKey c = chunk + ChunkKey(dx, dy, dz);
        if ((low_only && (dx > 0 || dy > 0 || dz > 0)) || !tiles.Contains(c)) continue;
        absl::StatusOr<std::shared_ptr<const TileData>> tile = tiles.Get(c);
        if (!tile.ok()) return tile.status();
        hold[s] = *std::move(tile);
        hood.tiles[s] = hold[s].get();
      }
    }
  }
  return hood;
}

absl::StatusOr<DenseMeshResult> BuildDenseMesh(TileSet& tiles, const ChunkProgressFn& progress) {
  const std::vector<ChunkKey> chunks = DenseMeshChunks(tiles.chunks());
  std::vector<ChunkMesh> meshes;
  DenseMeshResult result;
  std::array<std::shared_ptr<const TileData>, 27> hold;
  for (size_t i = 0; i < chunks.size(); ++i) {
    absl::StatusOr<ChunkNeighbourhood> hood = FetchNeighbourhood(tiles, chunks[i], /*low_only=*/true, hold);
    if (!hood.ok()) return hood.status();
    absl::StatusOr<ChunkMesh> mesh = DualContourChunk(*hood);
    if (!mesh.ok()) return mesh.status();
    result.polygons += mesh->polygons;
    result.centre_vertices += mesh->centre_vertices;
    if (!mesh->triangles.empty()) meshes.push_back(*std::move(mesh));
    if (progress && !progress(i + 1, chunks.size())) {
      return absl::CancelledError("dense_mesh: cancelled");
    }
  }
  result.chunks = chunks.size();
  result.mesh = WeldChunkMeshes(meshes, &result.vertex_observed);
  return result;
}

absl::StatusOr<std::vector<BoundaryFace>> CollectBoundaryFaces(TileSet& tiles,
                                                               const ChunkProgressFn& progress) {
  std::vector<BoundaryFace> faces;
  std::array<std::shared_ptr<const TileData>, 27> hold;
  const std::vector<ChunkKey>& chunks = tiles.chunks();
  for (size_t i = 0; i < chunks.size(); ++i) {
    absl::StatusOr<ChunkNeighbourhood> hood = FetchNeighbourhood(tiles, chunks[i], /*low_only=*/false, hold);
    if (!hood.ok()) return hood.status();
    absl::StatusOr<std::vector<BoundaryFace>> f = ChunkBoundaryFaces(*hood);
    if (!f.ok()) return f.status();
    faces.insert(faces.end(), f->begin(), f->end());
    if (progress && !progress(i + 1, chunks.size())) {
      return absl::CancelledError("boundary_faces: cancelled");
    }
  }
  return faces;
}

}  // namespace carvemap

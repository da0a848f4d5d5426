#include "services/merge/dense_mesh.h"

#include <algorithm>
#include <array>
#include <memory>
#include <vector>

#include "absl/strings/str_cat.h"
#include "services/merge/for_each_chunk.h"
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

absl::StatusOr<DenseMeshResult> BuildDenseMesh(TileSet& tiles, const ChunkProgressFn& progress,
                                               int threads) {
  const std::vector<ChunkKey> chunks = DenseMeshChunks(tiles.chunks());
  // The chunks come in ChunkKeyLess order, so they are welded as they come.
  ChunkMeshWelder welder(tiles.grid().leaves_per_side());
  DenseMeshResult result;
  absl::Status s = ForEachChunk<ChunkMesh>(
      tiles, chunks, /*low_only=*/true, threads,
      [](const ChunkNeighbourhood& hood) { return DualContourChunk(hood); },
      [&](ChunkMesh&& mesh) -> absl::Status {
        result.polygons += mesh.polygons;
        result.centre_vertices += mesh.centre_vertices;
        if (mesh.triangles.empty()) return absl::OkStatus();
        return welder.Add(std::move(mesh));
      },
      progress, "dense_mesh");
  if (!s.ok()) return s;
  result.chunks = chunks.size();
  absl::StatusOr<TriangleMesh> mesh = welder.Finish(&result.vertex_observed);
  if (!mesh.ok()) return mesh.status();
  result.mesh = *std::move(mesh);
  return result;
}

absl::StatusOr<std::vector<BoundaryFace>> CollectBoundaryFaces(TileSet& tiles,
                                                               const ChunkProgressFn& progress,
                                                               int threads) {
  std::vector<BoundaryFace> faces;
  absl::Status s = ForEachChunk<std::vector<BoundaryFace>>(
      tiles, tiles.chunks(), /*low_only=*/false, threads,
      [](const ChunkNeighbourhood& hood) { return ChunkBoundaryFaces(hood); },
      [&](std::vector<BoundaryFace>&& f) { faces.insert(faces.end(), f.begin(), f.end()); },
      progress, "boundary_faces");
  if (!s.ok()) return s;
  // Grown by doubling, the vector can hold twice its faces; the later stages keep it whole.
  faces.shrink_to_fit();
  return faces;
}

}  // namespace carvemap

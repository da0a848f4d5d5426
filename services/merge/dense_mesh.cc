#include "services/merge/dense_mesh.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <memory>
#include <optional>
#include <span>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
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

namespace {

// Runs `compute` on every chunk's neighbourhood and hands the results to `take` in chunk order.
// The tiles are read on the calling thread (HDF5 is not thread-safe, storage/tile_store.h), a
// batch of a few chunks per thread at a time; `compute` runs on `threads` threads. The results
// do not depend on the thread count.
template <typename Result, typename Compute, typename Take>
absl::Status ForEachChunk(TileSet& tiles, std::span<const ChunkKey> chunks, bool low_only,
                          int threads, const Compute& compute, const Take& take,
                          const ChunkProgressFn& progress, const char* stage) {
  threads = std::max(1, threads);
  const size_t batch = threads == 1 ? 1 : 4 * size_t(threads);
  std::vector<std::array<std::shared_ptr<const TileData>, 27>> hold(batch);
  std::vector<ChunkNeighbourhood> hoods(batch);
  std::vector<std::optional<absl::StatusOr<Result>>> results(batch);
  for (size_t first = 0; first < chunks.size(); first += batch) {
    const size_t n = std::min(batch, chunks.size() - first);
    for (size_t k = 0; k < n; ++k) {
      absl::StatusOr<ChunkNeighbourhood> hood =
          FetchNeighbourhood(tiles, chunks[first + k], low_only, hold[k]);
      if (!hood.ok()) return hood.status();
      hoods[k] = *hood;
    }
    std::atomic<size_t> next{0};
    const auto work = [&] {
      for (size_t k; (k = next.fetch_add(1)) < n;) results[k].emplace(compute(hoods[k]));
    };
    {
      std::vector<std::jthread> pool;
      for (size_t t = 1; t < std::min(size_t(threads), n); ++t) pool.emplace_back(work);
      work();
    }
    for (size_t k = 0; k < n; ++k) {
      absl::StatusOr<Result>& r = *results[k];
      if (!r.ok()) return r.status();
      take(*std::move(r));
      results[k].reset();
      if (progress && !progress(first + k + 1, chunks.size())) {
        return absl::CancelledError(absl::StrCat(stage, ": cancelled"));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<DenseMeshResult> BuildDenseMesh(TileSet& tiles, const ChunkProgressFn& progress,
                                               int threads) {
  const std::vector<ChunkKey> chunks = DenseMeshChunks(tiles.chunks());
  std::vector<ChunkMesh> meshes;
  DenseMeshResult result;
  absl::Status s = ForEachChunk<ChunkMesh>(
      tiles, chunks, /*low_only=*/true, threads,
      [](const ChunkNeighbourhood& hood) { return DualContourChunk(hood); },
      [&](ChunkMesh&& mesh) {
        result.polygons += mesh.polygons;
        result.centre_vertices += mesh.centre_vertices;
        if (!mesh.triangles.empty()) meshes.push_back(std::move(mesh));
      },
      progress, "dense_mesh");
  if (!s.ok()) return s;
  result.chunks = chunks.size();
  result.mesh = WeldChunkMeshes(meshes, &result.vertex_observed);
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
  return faces;
}

}  // namespace carvemap

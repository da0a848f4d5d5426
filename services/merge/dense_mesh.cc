#include "services/merge/dense_mesh.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <deque>
#include <limits>
#include <memory>
#include <optional>
#include <vector>

#include "absl/container/flat_hash_map.h"
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

namespace {

// Dual contouring of `chunks` (ChunkKeyLess order), each chunk's mesh handed to `welder` as it
// comes; the chunks' polygon counts added to `polygons` and `centre_vertices`.
absl::Status ContourAndWeld(TileSet& tiles, std::span<const ChunkKey> chunks,
                            ChunkMeshWelder& welder, const ChunkProgressFn& progress, int threads,
                            uint64_t& polygons, uint64_t& centre_vertices) {
  return ForEachChunk<ChunkMesh>(
      tiles, chunks, /*low_only=*/true, threads,
      [](const ChunkNeighbourhood& hood) { return DualContourChunk(hood); },
      [&](ChunkMesh&& mesh) -> absl::Status {
        polygons += mesh.polygons;
        centre_vertices += mesh.centre_vertices;
        if (mesh.triangles.empty()) return absl::OkStatus();
        return welder.Add(std::move(mesh));
      },
      progress, "dense_mesh");
}

}  // namespace

absl::StatusOr<DenseMeshResult> BuildDenseMesh(TileSet& tiles, const ChunkProgressFn& progress,
                                               int threads) {
  const std::vector<ChunkKey> chunks = DenseMeshChunks(tiles.chunks());
  // The chunks come in ChunkKeyLess order, so they are welded as they come.
  ChunkMeshWelder welder(tiles.grid().leaves_per_side());
  DenseMeshResult result;
  if (absl::Status s = ContourAndWeld(tiles, chunks, welder, progress, threads, result.polygons,
                                      result.centre_vertices);
      !s.ok()) {
    return s;
  }
  result.chunks = chunks.size();
  absl::StatusOr<TriangleMesh> mesh = welder.Finish(&result.vertex_observed);
  if (!mesh.ok()) return mesh.status();
  result.mesh = *std::move(mesh);
  return result;
}

void ColumnSelfIntersections::AddVertices(std::span<const Eigen::Vector3f> v) {
  vertices_.insert(vertices_.end(), v.begin(), v.end());
}

void ColumnSelfIntersections::AddTriangles(const ChunkKey& chunk,
                                           std::span<const Eigen::Vector3i> triangles) {
  if (triangles.empty()) return;
  if (columns_.empty() || columns_.back().x != chunk.x()) {
    // The columns before this one are complete: count those whose next column is.
    while (columns_.size() >= next_ + 2) CountNext();
    columns_.push_back(Column{chunk.x(), {}, std::numeric_limits<int>::max()});
  }
  Column& c = columns_.back();
  for (const Eigen::Vector3i& t : triangles) c.min_index = std::min(c.min_index, t.minCoeff());
  c.triangles.insert(c.triangles.end(), triangles.begin(), triangles.end());
}

SelfIntersections ColumnSelfIntersections::Finish() {
  while (next_ < columns_.size()) CountNext();
  return total_;
}

// Counts columns_[next_]'s window with the columns beside it (columns_[next_ − 1], kept from
// the last count, and columns_[next_ + 1], complete or the last), then drops what no later
// window needs.
void ColumnSelfIntersections::CountNext() {
  const auto t0 = std::chrono::steady_clock::now();
  const size_t i = next_;
  const bool first = !counted_any_, last = i + 1 >= columns_.size();
  const double lo =
      first ? -std::numeric_limits<double>::infinity() : columns_[i].x * column_width_m_;
  const double hi =
      last ? std::numeric_limits<double>::infinity() : columns_[i + 1].x * column_width_m_;
  TriangleMesh window;
  absl::flat_hash_map<int, int> local;
  for (size_t k = (i > 0 ? i - 1 : 0); k <= std::min(i + 1, columns_.size() - 1); ++k) {
    for (const Eigen::Vector3i& t : columns_[k].triangles) {
      float x0 = INFINITY, x1 = -INFINITY;
      for (int j = 0; j < 3; ++j) {
        const float x = vertices_[size_t(t[j]) - base_].x();
        x0 = std::min(x0, x);
        x1 = std::max(x1, x);
      }
      if (double(x1) < lo || double(x0) >= hi) continue;
      Eigen::Vector3i lt;
      for (int j = 0; j < 3; ++j) {
        auto [it, added] = local.try_emplace(t[j], int(window.vertices.size()));
        if (added) window.vertices.push_back(vertices_[size_t(t[j]) - base_]);
        lt[j] = it->second;
      }
      window.triangles.push_back(lt);
    }
  }
  // A window is one slab's worth or less: cut into one slab per thread, so that the count,
  // which the slabs do not change, is not left to one core.
  const size_t per_slab =
      std::clamp<size_t>(window.triangles.size() / size_t(std::max(threads_, 1)) + 1,
                         size_t{1} << 14, kSelfIntersectionTrianglesPerSlab);
  const SelfIntersections s = CountSelfIntersections(window, threads_, per_slab, lo, hi);
  seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  total_.pairs += s.pairs;
  total_.unchecked += s.unchecked;
  counted_any_ = true;
  if (i > 0) {
    columns_.pop_front();  // the column before: no later window reaches it
  } else {
    next_ = 1;
  }
  // Vertices below every remaining column's triangles are not needed again (a later column's
  // keys, hence indices, are larger).
  int needed = std::numeric_limits<int>::max();
  for (const Column& c : columns_) needed = std::min(needed, c.min_index);
  if (needed == std::numeric_limits<int>::max()) needed = int(base_ + vertices_.size());
  if (size_t(needed) > base_) {
    const size_t drop = std::min(size_t(needed) - base_, vertices_.size());
    vertices_.erase(vertices_.begin(), vertices_.begin() + std::ptrdiff_t(drop));
    base_ += drop;
  }
}

absl::StatusOr<DenseMeshStreamResult> StreamDenseMesh(TileSet& tiles, const DenseMeshSink& sink,
                                                      const ChunkProgressFn& progress, int threads,
                                                      bool count_self_intersections) {
  const std::vector<ChunkKey> chunks = DenseMeshChunks(tiles.chunks());
  DenseMeshStreamResult result;
  std::optional<ColumnSelfIntersections> checks;
  if (count_self_intersections) checks.emplace(kChunkSizeM, threads);
  ChunkMeshWelder::Sink weld_sink;
  weld_sink.vertices = [&](std::span<const Eigen::Vector3f> v, std::span<const uint8_t>) {
    result.vertices += v.size();
    if (checks) checks->AddVertices(v);
    return sink.vertices(v);
  };
  weld_sink.triangles = [&](const ChunkKey& chunk, std::span<const Eigen::Vector3i> t) {
    result.triangles += t.size();
    if (checks) checks->AddTriangles(chunk, t);
    return sink.triangles(chunk, t);
  };
  ChunkMeshWelder welder(tiles.grid().leaves_per_side(), std::move(weld_sink));
  if (absl::Status s = ContourAndWeld(tiles, chunks, welder, progress, threads, result.polygons,
                                      result.centre_vertices);
      !s.ok()) {
    return s;
  }
  result.chunks = chunks.size();
  if (absl::StatusOr<TriangleMesh> rest = welder.Finish(); !rest.ok()) return rest.status();
  if (checks) {
    result.self_intersections = checks->Finish();
    result.self_intersection_seconds = checks->seconds();
  }
  return result;
}

absl::Status CollectBoundaryFacesInto(TileSet& tiles, const BoundaryFaceSink& sink,
                                      const ChunkProgressFn& progress, int threads) {
  return ForEachChunk<std::vector<BoundaryFace>>(
      tiles, tiles.chunks(), /*low_only=*/false, threads,
      [](const ChunkNeighbourhood& hood) { return ChunkBoundaryFaces(hood); },
      [&](std::vector<BoundaryFace>&& f) { return sink(std::move(f)); }, progress,
      "boundary_faces");
}

absl::StatusOr<std::vector<BoundaryFace>> CollectBoundaryFaces(TileSet& tiles,
                                                               const ChunkProgressFn& progress,
                                                               int threads) {
  std::vector<BoundaryFace> faces;
  absl::Status s = CollectBoundaryFacesInto(
      tiles,
      [&](std::vector<BoundaryFace>&& f) {
        faces.insert(faces.end(), f.begin(), f.end());
        return absl::OkStatus();
      },
      progress, threads);
  if (!s.ok()) return s;
  // Grown by doubling, the vector can hold twice its faces; its callers keep it whole.
  faces.shrink_to_fit();
  return faces;
}

}  // namespace carvemap

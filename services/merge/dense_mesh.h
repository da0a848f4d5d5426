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
#include <deque>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "services/merge/tile_set.h"
#include "services/mesh/boundary_faces.h"
#include "services/mesh/self_intersections.h"
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

// Where StreamDenseMesh puts the mesh: vertices in their final order (each call continues the
// last's indices), triangles in their final order, a chunk's at a time (chunks in ChunkKeyLess
// order), indexing the vertices given so far. An error stops the stream and is returned.
struct DenseMeshSink {
  std::function<absl::Status(std::span<const Eigen::Vector3f>)> vertices;
  std::function<absl::Status(const ChunkKey& chunk, std::span<const Eigen::Vector3i>)> triangles;
};

struct DenseMeshStreamResult {
  uint64_t chunks = 0, polygons = 0, centre_vertices = 0;
  uint64_t vertices = 0, triangles = 0;
  SelfIntersections self_intersections;  // CountSelfIntersections' counts of the whole mesh
  double self_intersection_seconds = 0;  // of the stream's time, spent counting them
};

// The self-intersections of a mesh that comes chunk column by chunk column (ChunkKeyLess
// order: x first), counted a window at a time: once the column after a column is complete,
// the pairs whose x* lies from that column's first x to the next column's
// (CountSelfIntersections' windows) are counted among the triangles of it and of the columns
// beside it that reach into that range. A triangle must lie within one column's width of its
// chunk's cells (a dense mesh's lie within a cell or two), so that no other column reaches
// it. Memory: three columns' triangles and their vertices.
class ColumnSelfIntersections {
 public:
  ColumnSelfIntersections(double column_width_m, int threads)
      : column_width_m_(column_width_m), threads_(threads) {}
  // Vertices in index order, each before a triangle names it.
  void AddVertices(std::span<const Eigen::Vector3f> v);
  // A chunk's triangles (global vertex indices), chunks in ChunkKeyLess order.
  void AddTriangles(const ChunkKey& chunk, std::span<const Eigen::Vector3i> triangles);
  // Counts the columns left; the whole mesh's counts.
  SelfIntersections Finish();
  [[nodiscard]] double seconds() const { return seconds_; }

 private:
  struct Column {
    int x = 0;
    std::vector<Eigen::Vector3i> triangles;  // global vertex indices
    int min_index = 0;
  };
  void CountNext();

  double column_width_m_;
  int threads_;
  std::deque<Eigen::Vector3f> vertices_;  // global indices from base_
  size_t base_ = 0;
  std::deque<Column> columns_;
  size_t next_ = 0;  // the column to count next: 0 before the first count, then 1
  bool counted_any_ = false;
  SelfIntersections total_;
  double seconds_ = 0;
};

// BuildDenseMesh's mesh, given to `sink` as it is welded instead of held: memory for a few
// x-columns of chunks, whatever the building's size. Its self-intersections are counted on the
// way, a window at a time: each chunk column's range along x with the triangles of the
// columns beside it that reach into it (CountSelfIntersections' windows), on `threads`
// threads, unless `count_self_intersections` is false (its counts are then zero). Errors:
// BuildDenseMesh's and the sink's.
[[nodiscard]] absl::StatusOr<DenseMeshStreamResult> StreamDenseMesh(
    TileSet& tiles, const DenseMeshSink& sink, const ChunkProgressFn& progress = nullptr,
    int threads = 1, bool count_self_intersections = true);

// All boundary faces of `tiles` (services/mesh/boundary_faces.h): the chunks' faces in
// ChunkKeyLess order of their interior leaf's chunk, each chunk's in its deterministic order.
[[nodiscard]] absl::StatusOr<std::vector<BoundaryFace>> CollectBoundaryFaces(
    TileSet& tiles, const ChunkProgressFn& progress = nullptr, int threads = 1);

// CollectBoundaryFaces, each chunk's faces given to `sink` as they come (in the same order)
// instead of held. The sink's error stops the walk and is returned.
using BoundaryFaceSink = std::function<absl::Status(std::vector<BoundaryFace>&&)>;
[[nodiscard]] absl::Status CollectBoundaryFacesInto(TileSet& tiles, const BoundaryFaceSink& sink,
                                                    const ChunkProgressFn& progress = nullptr,
                                                    int threads = 1);

}  // namespace carvemap

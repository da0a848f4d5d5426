// Dense meshing of the octree's boundary (§4.3.3 "Dense octree meshing", Fig 4.9;
// docs/DESIGN.md §6 stage 8, §7 mesh/dense.ply): a watertight, consistently oriented triangle mesh
// of the surface between interior (p > 0.5) and exterior leaves.
//
// The method is the dissertation's variant of dual contouring: "mapping each boundary face of the
// octree to a vertex in the mesh and each corner of the octree into a face". Labels live at
// cell centres, so the primal surface is made of the square faces between interior and
// exterior cells, and the mesh is its dual:
//   - topology on the finest grid: every leaf is resampled to finest cells (only labels, and
//     only for the chunk plus a one-cell halo; cost (2^k + 1)³ × 4 bytes per chunk, 8.6 MB at
//     k = 7), so coarse leaves next to fine ones need no special cases;
//   - one vertex per finest boundary face, at its Fig 4.9 isosurface point (IsosurfaceOffsetM
//     from the p of the two leaves holding its cells, taken at those cells, clamped to ±0.45
//     of the finest resolution so a vertex stays between the two cells' centres);
//   - one polygon per (grid corner × connected sheet of faces around it), triangulated.
// Ambiguities (two interior cells touching only along an edge or at a corner) are resolved by
// one rule: at a grid edge with four boundary faces, the two faces of the same interior cell
// are joined (interior cells are 6-connected, exterior space 18/26-connected). Faces around a
// corner then split into disjoint cycles, one polygon each, so every mesh edge is shared by
// exactly two triangles and vertex links are single cycles: manifold and watertight by
// construction, with no vertex splitting heuristics. Unobserved space and chunks without tiles
// are exterior (§4.3.2), so every interior region is closed.
//
// Compared with Ju et al.'s cell-vertex DC (one vertex per cell with a QEF): vertices sit on
// the isosurface points themselves (no QEF needed: each vertex has exactly one sample), sharp
// corners are bevelled by at most ~one cell, and ambiguous configurations stay manifold.
//
// Out of core: a chunk meshes the grid corners it owns (the corners whose floor-chunk is the
// chunk) from its tile and the seven lower neighbours' (slots with dx, dy, dz ≤ 0); vertices
// are keyed by global finest-cell coordinates, so ChunkMeshWelder joins the chunks exactly.
#pragma once

#include <array>
#include <cstdint>
#include <deque>
#include <functional>
#include <optional>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "services/mesh/boundary_faces.h"
#include "storage/ply_io.h"

namespace carvemap {

// Global id of a mesh vertex. tag 0..2: the finest boundary face perpendicular to axis `tag`
// between cells `cell` and cell + e_tag; tag ≥ 3: the centre vertex of polygon (tag − 3) at
// grid corner `cell` (the min corner of finest cell `cell`). Ordered lexicographically
// (x, y, z, tag), which fixes the welded vertex order.
struct MeshVertexKey {
  std::array<int32_t, 4> v{};  // x, y, z, tag
  friend bool operator<(const MeshVertexKey& a, const MeshVertexKey& b) { return a.v < b.v; }
  friend bool operator==(const MeshVertexKey& a, const MeshVertexKey& b) { return a.v == b.v; }
};

// The part of the dense mesh owned by one chunk. A vertex key may also appear in other chunks'
// meshes (faces on chunk borders), always with the same position.
struct ChunkMesh {
  ChunkKey chunk = ChunkKey::Zero();
  std::vector<MeshVertexKey> vertex_keys;
  std::vector<Eigen::Vector3d> vertex_positions;  // m, world; parallel to vertex_keys
  // Parallel to vertex_keys: 1 when the vertex's exterior side is observed space (a surface
  // the scans saw, p ≤ 0.5 from points), 0 when it borders unobserved space (the edge of the
  // carved volume, closed by §4.3.2's rule). Centre vertices: 1 iff all their polygon's are.
  std::vector<uint8_t> vertex_observed;
  // Indices into vertex_keys; counter-clockwise seen from the interior (free space), i.e.
  // normals point into the interior.
  std::vector<Eigen::Vector3i> triangles;
  uint64_t polygons = 0;        // corner polygons (before triangulation)
  uint64_t centre_vertices = 0; // polygons triangulated around an added centre vertex
};

// Meshes the grid corners owned by `hood.chunk`. Reads only the tiles in slots with
// dx, dy, dz ≤ 0 (others may be null). Errors: those of NeighbourhoodIndex::Build.
[[nodiscard]] absl::StatusOr<ChunkMesh> DualContourChunk(const ChunkNeighbourhood& hood);

// Joins chunk meshes by vertex key as they come, one at a time in ChunkKeyLess order (x
// first): vertices sorted by key (of a key several chunks give, the first chunk's copy),
// triangles in chunk order. The result is watertight when the chunks cover every chunk that
// owns a corner of an interior cell (DenseMeshChunks). Memory: the welded mesh (none with a
// Sink) and a few x-columns of chunks, not every chunk mesh and a sorted copy of all their
// keys (about three times the welded mesh on a large building). A chunk owns the grid
// corners in its cell range, so its vertex keys lie within a few cells below it along x: once
// the chunks reach column X, every key more than kMargin cells below X's first cell is final,
// and is welded (sorted, given its index); a chunk's triangles are welded once all their keys
// are.
class ChunkMeshWelder {
 public:
  // Where the welded mesh goes when it is not to be held: vertices in their final order (each
  // call's continue the last's indices), then each chunk's triangles, in chunk order, indexing
  // the vertices given so far. A sink's error stops the weld and is returned.
  struct Sink {
    std::function<absl::Status(std::span<const Eigen::Vector3f> vertices,
                               std::span<const uint8_t> observed)>
        vertices;
    std::function<absl::Status(const ChunkKey& chunk, std::span<const Eigen::Vector3i> triangles)>
        triangles;
  };

  // `chunk_cells`: finest cells along a chunk's side (OctreeGrid's 1 << chunk_depth). With a
  // sink (both functions set), the mesh goes to it and Finish returns an empty one.
  explicit ChunkMeshWelder(int chunk_cells, Sink sink = {});

  // Takes the next chunk. InvalidArgument when it comes before the previous one in
  // ChunkKeyLess order; Internal when one of its keys lies below the welded front (a key that
  // a chunk was assumed not to have).
  [[nodiscard]] absl::Status Add(ChunkMesh chunk);

  // Welds what is left and returns the mesh; `vertex_observed`, when given, receives
  // ChunkMesh::vertex_observed per vertex. The welder is empty afterwards.
  [[nodiscard]] absl::StatusOr<TriangleMesh> Finish(
      std::vector<uint8_t>* vertex_observed = nullptr);

  // Cells along x below a chunk's first cell that its vertex keys may reach (a face's lower
  // cell next to a corner on the chunk's low side is one cell below; the rest is slack).
  static constexpr int64_t kMargin = 4;

 private:
  struct PendingVertex {
    MeshVertexKey key;
    Eigen::Vector3f position;
    uint8_t observed = 0;
  };
  struct PendingChunk {
    ChunkKey chunk;
    int32_t min_key_x = 0, max_key_x = 0;
    std::vector<MeshVertexKey> keys;
    std::vector<Eigen::Vector3i> triangles;  // indices into keys
  };
  // Welds every pending vertex whose key's x is below `front`, then every chunk whose keys
  // are all welded, in order.
  absl::Status Advance(int64_t front);

  int chunk_cells_;
  Sink sink_;
  int num_vertices_ = 0;
  int64_t front_;  // every key with x below it is welded
  std::optional<ChunkKey> last_;
  std::vector<PendingVertex> pending_;  // in the order the chunks gave them
  std::deque<PendingChunk> chunks_;
  std::vector<std::pair<MeshVertexKey, int>> welded_;  // the welded keys still needed, sorted
  TriangleMesh mesh_;
  std::vector<uint8_t> observed_;
};

// The chunks whose corners may touch an interior cell of a tile in `tile_chunks`: each tile's
// chunk and its +1 neighbours ({0, 1}³), sorted by ChunkKeyLess, unique.
[[nodiscard]] std::vector<ChunkKey> DenseMeshChunks(std::span<const ChunkKey> tile_chunks);

}  // namespace carvemap

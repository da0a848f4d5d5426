// Boundary faces of the merged octree (seed §4.3.2, §4.3.3, Fig 4.9; DESIGN §6 stage 1): the
// faces between an interior leaf (p > 0.5) and an exterior leaf (p ≤ 0.5, or unobserved) that
// abut, of any sizes, across chunk borders.
//
// Out of core: faces are found one chunk at a time from that chunk's tile and its 26
// neighbours' (a ChunkNeighbourhood), so a merge holds a bounded number of decoded tiles. Every
// face is reported by exactly one chunk: the chunk holding its interior leaf.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "services/geometry/carving_types.h"
#include "services/geometry/octree_keys.h"
#include "storage/tile_store.h"

namespace carvemap {

// A leaf of the merged octree, in global finest-cell coordinates: the leaf covers finest cells
// [min_cell, min_cell + 2^(k − depth)) on each axis (k = grid.chunk_depth). An unobserved
// region (no tile row) is reported as the maximal unobserved node: stored = false, stats empty.
struct OctreeLeafRef {
  LeafKey min_cell = LeafKey::Zero();
  int depth = 0;  // 0 = a whole 2 m chunk, k = a finest leaf
  bool stored = false;
  LeafStats stats;
};

// One boundary face. Its geometry is the square shared by the two leaves, i.e. a face of the
// smaller one (a big leaf next to small ones has one face per small neighbour).
struct BoundaryFace {
  OctreeLeafRef interior;
  OctreeLeafRef exterior;
  int axis = 0;               // 0, 1, 2: the face is perpendicular to x, y or z
  // Unit normal along `axis` pointing from the exterior leaf into the interior leaf (into free
  // space: a floor's faces point up, a ceiling's down).
  Eigen::Vector3f normal = Eigen::Vector3f::UnitZ();
  Eigen::Vector3d center;     // centre of the shared square, on the leaves' common plane, m
  double size_m = 0;          // side of the shared square, m
  // Fig 4.9: the point on the line through `center` along `axis` where p, linearly
  // interpolated between the two leaves' centres (projected on that line), is 0.5. Lies between
  // the two leaf centres; equals `center` moved along the axis.
  Eigen::Vector3d isosurface;
  [[nodiscard]] double area_m2() const { return size_m * size_m; }
};

// A chunk's tile and its 26 neighbours' (nullptr: no tile there, all unobserved). Index of
// neighbour (dx, dy, dz) ∈ {−1, 0, 1}³: (dx + 1) + 3 (dy + 1) + 9 (dz + 1); 13 is the chunk
// itself. Tiles are not owned.
struct ChunkNeighbourhood {
  OctreeGrid grid;
  ChunkKey chunk = ChunkKey::Zero();
  std::array<const TileData*, 27> tiles{};
  [[nodiscard]] static int Index(int dx, int dy, int dz) {
    return (dx + 1) + 3 * (dy + 1) + 9 * (dz + 1);
  }
};

// The boundary faces whose interior leaf lies in `hood.chunk`, in a deterministic order
// (sorted by axis, then the face's min corner, then size). Errors: InvalidArgument when a tile
// is of another grid or chunk than its slot says, or its leaves overlap or leave the chunk.
[[nodiscard]] absl::StatusOr<std::vector<BoundaryFace>> ChunkBoundaryFaces(
    const ChunkNeighbourhood& hood);

}  // namespace carvemap

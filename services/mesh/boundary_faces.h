// Boundary faces of the merged octree (§4.3.2, §4.3.3, Fig 4.9; docs/DESIGN.md §6 stage 1): the
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
#include "geometry/carving_types.h"
#include "geometry/octree_keys.h"
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
// Kept small (48 bytes): the merge holds every face of the building at once while it
// fits the planar regions and meshes them (millions of faces for a large building), so a face
// keeps only what those stages read, not the two leaves it lies between.
struct BoundaryFace {
  Eigen::Vector3d center;  // centre of the shared square, on the leaves' common plane, m
  double size_m = 0;       // side of the shared square, m
  // Fig 4.9: the coordinate along `axis` of the point on the line through `center` where p,
  // linearly interpolated between the finest cells on either side of the face
  // (IsosurfaceOffsetM: each leaf's p taken at its cell beside the face), is 0.5, clamped to
  // within kIsosurfaceLimitFraction × the grid resolution: strictly between those two cells'
  // centres. isosurface() is the point.
  double isosurface_m = 0;
  // The exterior leaf's Σ w (eq 4.8) when it is stored and observed, else 0.
  float exterior_weight = 0;
  int8_t axis = 0;  // 0, 1, 2: the face is perpendicular to x, y or z
  // The sign of normal() along `axis`: +1 when the interior leaf is on the face's +axis side.
  int8_t sign = 1;
  // The exterior leaf is stored and observed (a ray reached it): a surface the scanners saw,
  // not one that closes the carved volume against unobserved space (no tile row, or no ray).
  bool exterior_observed = false;

  [[nodiscard]] double area_m2() const { return size_m * size_m; }
  // Unit normal along `axis` pointing from the exterior leaf into the interior leaf (into free
  // space: a floor's faces point up, a ceiling's down).
  [[nodiscard]] Eigen::Vector3f normal() const {
    Eigen::Vector3f n = Eigen::Vector3f::Zero();
    n[axis] = sign;
    return n;
  }
  [[nodiscard]] Eigen::Vector3d isosurface() const {
    Eigen::Vector3d p = center;
    p[axis] = isosurface_m;
    return p;
  }
};
static_assert(sizeof(BoundaryFace) <= 48, "the merge holds millions of these at once");

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

// The isosurface rule (Fig 4.9) shared by the faces above and the dense mesh. Returns the
// signed distance, m, from the face plane to the isosurface, positive towards the exterior
// leaf: p is linear from `p_interior` at the centre of the finest cell behind the plane
// (cell_m / 2 behind it) to `p_exterior` at the centre of the finest cell in front, and the
// result is where it crosses 0.5. Fig 4.9 interpolates between the two leaves' centres; we
// take each leaf's p at the finest cell beside the face whatever the leaf's size, because a
// simplified leaf's p is the mean over its whole volume (§4.3.2 merges the children's sums),
// not a value at its centre. Interpolating from the centres of the big leaves that cover a
// floor and the solid below it moved office2's floor faces up 4.4 cm on average at 6.25 cm;
// from the finest cells, −0.2 cm (docs/BENCHMARKS.md, "Dense vs planar
// meshes").
// Clamped to [−limit_m, +limit_m]. Why the clamp: an unobserved or p = 0.5 exterior puts the
// crossing exactly on the exterior cell's centre, with no evidence there; a barely interior
// leaf (p → 0.5⁺) puts it on the interior cell's centre, where the six faces of a lone cell
// would collapse to one point. Callers pass limit_m = kIsosurfaceLimitFraction × cell_m, so
// the surface stays strictly between the two cells' centres and faces never collapse.
// REQUIRES: p_interior > 0.5 ≥ p_exterior.
inline constexpr double kIsosurfaceLimitFraction = 0.45;
[[nodiscard]] double IsosurfaceOffsetM(double p_interior, double p_exterior, double cell_m,
                                       double limit_m);

// Leaf lookups in a ChunkNeighbourhood (global finest-cell coordinates), shared by the
// boundary faces and the dense mesh. Borrows the tiles of `hood`, which must outlive it.
// Not thread-safe for writes; const lookups may run concurrently.
class NeighbourhoodIndex {
 public:
  // Validates every tile against its slot (grid, chunk key, leaf depths and coordinates,
  // overlaps): InvalidArgument naming the chunk and the slot.
  static absl::StatusOr<NeighbourhoodIndex> Build(const ChunkNeighbourhood& hood);

  [[nodiscard]] const ChunkNeighbourhood& hood() const { return *hood_; }
  // Slot of the chunk holding `cell`, or −1 outside the 3×3×3 chunks.
  [[nodiscard]] int SlotOf(const LeafKey& cell) const;
  // The stored leaf covering `cell`, or nullptr (unobserved; also outside the 27 chunks).
  [[nodiscard]] const TileLeaf* StoredAt(const LeafKey& cell) const;
  // True when some stored leaf intersects the node of `depth` whose first cell is `min_cell`.
  // REQUIRES: the node is aligned to its depth and inside the 27 chunks.
  [[nodiscard]] bool AnyStoredIn(const LeafKey& min_cell, int depth) const;
  // The leaf covering `cell`: the stored one, or the maximal unobserved node of its chunk.
  [[nodiscard]] OctreeLeafRef LeafAt(const LeafKey& cell) const;

 private:
  struct TileIndex {
    const TileData* tile = nullptr;
    std::vector<uint64_t> first;  // first finest Morton cell of each leaf, ascending
    std::vector<uint64_t> end;    // one past its last cell
    std::vector<uint32_t> row;    // the leaf's index in tile->leaves
  };
  // Index into slots_[s].first of the leaf containing Morton cell `code`, or −1.
  [[nodiscard]] int64_t Find(int slot, uint64_t code) const;

  const ChunkNeighbourhood* hood_ = nullptr;
  std::array<TileIndex, 27> slots_;
};

}  // namespace carvemap

#include "services/mesh/boundary_faces.h"

#include <algorithm>
#include <cassert>
#include <numeric>
#include <tuple>

#include "absl/strings/str_format.h"

namespace carvemap {
namespace {

// Morton code of the first finest cell of a node, and its number of finest cells.
uint64_t FirstCell(const ChunkNode& node, int k) {
  return MortonCode(node.local) << (3 * (k - node.depth));
}
uint64_t CellSpan(int depth, int k) { return uint64_t{1} << (3 * (k - depth)); }

std::string ChunkName(const ChunkKey& c) {
  return absl::StrFormat("(%d, %d, %d)", c.x(), c.y(), c.z());
}

// Floor division by a power of two for negative numbers too.
int FloorDiv(int a, int n) { return a >= 0 ? a / n : -((-a + n - 1) / n); }

}  // namespace

double IsosurfaceOffsetM(double p_interior, double p_exterior, double cell_m, double limit_m) {
  // Fig 4.9: p(x) linear between (−h, p_i) and (+h, p_e), h = cell_m / 2; p(x) = 0.5 at
  // x = −h + 2h t.
  const double denom = p_interior - p_exterior;
  const double t = denom > 0 ? (p_interior - 0.5) / denom : 0.5;
  const double h = 0.5 * cell_m;
  return std::clamp(-h + 2 * h * t, -limit_m, limit_m);
}

absl::StatusOr<NeighbourhoodIndex> NeighbourhoodIndex::Build(const ChunkNeighbourhood& hood) {
  NeighbourhoodIndex index;
  index.hood_ = &hood;
  const int k = hood.grid.chunk_depth;
  if (k < kMinChunkDepth || k > kMaxChunkDepth) {
    return absl::InvalidArgumentError(
        absl::StrFormat("boundary_faces chunk %s: chunk depth %d outside [%d, %d]",
                        ChunkName(hood.chunk), k, kMinChunkDepth, kMaxChunkDepth));
  }
  for (int dz = -1; dz <= 1; ++dz) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const int s = ChunkNeighbourhood::Index(dx, dy, dz);
        const TileData* tile = hood.tiles[s];
        if (tile == nullptr) continue;
        const ChunkKey want = hood.chunk + ChunkKey(dx, dy, dz);
        auto error = [&](const std::string& what) {
          return absl::InvalidArgumentError(absl::StrFormat(
              "boundary_faces chunk %s: tile in slot (%d, %d, %d) (chunk %s): %s",
              ChunkName(hood.chunk), dx, dy, dz, ChunkName(want), what));
        };
        if (tile->chunk != want) return error("tile is of chunk " + ChunkName(tile->chunk));
        if (tile->grid.chunk_depth != k) {
          return error(absl::StrFormat("chunk depth %d, expected %d", tile->grid.chunk_depth, k));
        }
        TileIndex& ti = index.slots_[s];
        ti.tile = tile;
        const size_t n = tile->leaves.size();
        ti.row.resize(n);
        std::iota(ti.row.begin(), ti.row.end(), 0u);
        std::vector<uint64_t> first(n);
        for (size_t i = 0; i < n; ++i) {
          const ChunkNode& node = tile->leaves[i].node;
          if (node.depth < 0 || node.depth > k) {
            return error(absl::StrFormat("leaf %d: depth %d outside [0, %d]", i, node.depth, k));
          }
          const int side = 1 << node.depth;
          if ((node.local.array() < 0).any() || (node.local.array() >= side).any()) {
            return error(absl::StrFormat("leaf %d: local (%d, %d, %d) outside the chunk", i,
                                         node.local.x(), node.local.y(), node.local.z()));
          }
          first[i] = FirstCell(node, k);
        }
        // Tiles from ReadTile are already in canonical order; sort only when needed.
        if (!std::is_sorted(first.begin(), first.end())) {
          std::stable_sort(ti.row.begin(), ti.row.end(),
                           [&](uint32_t a, uint32_t b) { return first[a] < first[b]; });
        }
        ti.first.resize(n);
        ti.end.resize(n);
        for (size_t i = 0; i < n; ++i) {
          const uint32_t r = ti.row[i];
          ti.first[i] = first[r];
          ti.end[i] = first[r] + CellSpan(tile->leaves[r].node.depth, k);
          if (i > 0 && ti.first[i] < ti.end[i - 1]) {
            return error(absl::StrFormat("leaves %d and %d overlap", ti.row[i - 1], r));
          }
        }
      }
    }
  }
  return index;
}

int NeighbourhoodIndex::SlotOf(const LeafKey& cell) const {
  const int n = hood_->grid.leaves_per_side();
  int s = 0;
  for (int a = 2; a >= 0; --a) {
    const int d = FloorDiv(cell[a], n) - hood_->chunk[a];
    if (d < -1 || d > 1) return -1;
    s = s * 3 + (d + 1);
  }
  return s;
}

int64_t NeighbourhoodIndex::Find(int slot, uint64_t code) const {
  const TileIndex& ti = slots_[slot];
  auto it = std::upper_bound(ti.first.begin(), ti.first.end(), code);
  if (it == ti.first.begin()) return -1;
  const int64_t i = (it - ti.first.begin()) - 1;
  return code < ti.end[i] ? i : -1;
}

const TileLeaf* NeighbourhoodIndex::StoredAt(const LeafKey& cell) const {
  const int s = SlotOf(cell);
  if (s < 0 || slots_[s].tile == nullptr) return nullptr;
  const int n = hood_->grid.leaves_per_side();
  const ChunkKey chunk(FloorDiv(cell.x(), n), FloorDiv(cell.y(), n), FloorDiv(cell.z(), n));
  const int64_t i = Find(s, MortonCode(cell - chunk * n));
  return i < 0 ? nullptr : &slots_[s].tile->leaves[slots_[s].row[i]];
}

bool NeighbourhoodIndex::AnyStoredIn(const LeafKey& min_cell, int depth) const {
  const int s = SlotOf(min_cell);
  if (s < 0 || slots_[s].tile == nullptr) return false;
  const int k = hood_->grid.chunk_depth;
  const int n = hood_->grid.leaves_per_side();
  const ChunkKey chunk(FloorDiv(min_cell.x(), n), FloorDiv(min_cell.y(), n),
                       FloorDiv(min_cell.z(), n));
  const uint64_t a = MortonCode(min_cell - chunk * n);  // aligned: the node's first cell
  const uint64_t b = a + CellSpan(depth, k);
  const TileIndex& ti = slots_[s];
  // The last leaf starting before b intersects [a, b) iff it ends after a (leaves disjoint).
  auto it = std::lower_bound(ti.first.begin(), ti.first.end(), b);
  if (it == ti.first.begin()) return false;
  return ti.end[(it - ti.first.begin()) - 1] > a;
}

OctreeLeafRef NeighbourhoodIndex::LeafAt(const LeafKey& cell) const {
  const int k = hood_->grid.chunk_depth;
  OctreeLeafRef ref;
  if (const TileLeaf* leaf = StoredAt(cell)) {
    ref.stored = true;
    ref.stats = leaf->stats;
    ref.depth = leaf->node.depth;
    const int shift = k - leaf->node.depth;
    ref.min_cell = LeafKey(cell.x() >> shift << shift, cell.y() >> shift << shift,
                           cell.z() >> shift << shift);
    return ref;
  }
  // §4.3.2 keeps unobserved space apart from observed siblings, so the maximal unobserved
  // node is the coarsest node around `cell` that no stored leaf touches (at most the chunk).
  for (int d = 0; d <= k; ++d) {
    const int shift = k - d;
    const LeafKey m(cell.x() >> shift << shift, cell.y() >> shift << shift,
                    cell.z() >> shift << shift);
    if (!AnyStoredIn(m, d)) {
      ref.min_cell = m;
      ref.depth = d;
      return ref;
    }
  }
  ref.min_cell = cell;  // unreachable: the cell itself is unobserved
  ref.depth = k;
  return ref;
}

namespace {

struct FaceBuilder {
  const NeighbourhoodIndex& index;
  const OctreeGrid grid;
  const OctreeLeafRef& interior;
  int axis;
  int sign;  // +1: the exterior lies towards +axis
  // Faces with their integer sort key (axis, min corner in finest cells, size in cells).
  std::vector<std::pair<std::array<int, 5>, BoundaryFace>>& out;

  // Visits the node (min_cell, depth) adjacent to the interior leaf across its face: one
  // neighbour leaf when a leaf contains the node or it is wholly unobserved, else its four
  // children that touch the face.
  void Visit(const LeafKey& min_cell, int depth) {
    const int k = grid.chunk_depth;
    const TileLeaf* stored = index.StoredAt(min_cell);
    if (stored != nullptr && stored->node.depth <= depth) {
      OctreeLeafRef ext = index.LeafAt(min_cell);
      if (!ext.stats.interior()) Emit(min_cell, depth, ext);
      return;
    }
    if (stored == nullptr && !index.AnyStoredIn(min_cell, depth)) {
      Emit(min_cell, depth, index.LeafAt(min_cell));  // unobserved: exterior
      return;
    }
    assert(depth < k);
    const int half = 1 << (k - depth - 1);
    const int u = (axis + 1) % 3, w = (axis + 2) % 3;
    for (int j = 0; j < 4; ++j) {
      LeafKey c = min_cell;
      if (sign < 0) c[axis] += half;  // the children on the interior leaf's side
      if (j & 1) c[u] += half;
      if (j & 2) c[w] += half;
      Visit(c, depth + 1);
    }
  }

  // `node` (min_cell, depth) is the part of the neighbour across the face; `ext` its leaf.
  void Emit(const LeafKey& min_cell, int depth, const OctreeLeafRef& ext) {
    const int k = grid.chunk_depth;
    const double res = grid.resolution_m();
    const int cells = 1 << (k - depth);
    BoundaryFace f;
    f.axis = static_cast<int8_t>(axis);
    f.sign = static_cast<int8_t>(-sign);
    f.size_m = cells * res;
    LeafKey corner = min_cell;  // min corner of the shared square, finest cells
    if (sign < 0) corner[axis] += cells;
    f.center = (corner.cast<double>() + Eigen::Vector3d::Constant(0.5 * cells)) * res;
    f.center[axis] = corner[axis] * res;
    const double x = IsosurfaceOffsetM(interior.stats.p(), ext.stats.p(), res,
                                       kIsosurfaceLimitFraction * res);
    f.isosurface_m = f.center[axis] + sign * x;
    if (ext.stored && ext.stats.observed()) {
      f.exterior_observed = true;
      f.exterior_weight = static_cast<float>(ext.stats.sum_w);
    }
    out.emplace_back(std::array<int, 5>{axis, corner.x(), corner.y(), corner.z(), cells},
                     std::move(f));
  }
};

}  // namespace

absl::StatusOr<std::vector<BoundaryFace>> ChunkBoundaryFaces(const ChunkNeighbourhood& hood) {
  absl::StatusOr<NeighbourhoodIndex> index = NeighbourhoodIndex::Build(hood);
  if (!index.ok()) return index.status();
  std::vector<std::pair<std::array<int, 5>, BoundaryFace>> faces;
  const TileData* own = hood.tiles[ChunkNeighbourhood::Index(0, 0, 0)];
  if (own == nullptr) return std::vector<BoundaryFace>{};
  const int k = hood.grid.chunk_depth;
  const LeafKey base = hood.chunk * hood.grid.leaves_per_side();
  for (const TileLeaf& leaf : own->leaves) {
    if (!leaf.stats.interior()) continue;
    OctreeLeafRef interior;
    interior.min_cell = base + leaf.node.local * (1 << (k - leaf.node.depth));
    interior.depth = leaf.node.depth;
    interior.stored = true;
    interior.stats = leaf.stats;
    const int cells = 1 << (k - leaf.node.depth);
    for (int axis = 0; axis < 3; ++axis) {
      for (int sign : {-1, 1}) {
        LeafKey n = interior.min_cell;
        n[axis] += sign * cells;  // the same-size node across the face
        FaceBuilder{*index, hood.grid, interior, axis, sign, faces}.Visit(n, leaf.node.depth);
      }
    }
  }
  std::sort(faces.begin(), faces.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<BoundaryFace> out;
  out.reserve(faces.size());
  for (auto& f : faces) out.push_back(std::move(f.second));
  return out;
}

}  // namespace carvemap

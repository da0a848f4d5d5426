// The finest leaves of one chunk that a wedge hull touches (§4.3.2: "the locations ... that
// are intersected by at least one scan wedge"), listed as runs of leaves along one axis.
//
// A leaf is touched iff HullIntersectsBox(hull, its box) (geometry/wedge_geometry.h),
// the test the coordinator bins wedges into chunks with. Runs make the listing cost about the
// number of rows a wedge crosses rather than the number of leaves, and let the carver evaluate
// a ray along a run with a fixed step (eq 4.7 is affine in the leaf index along a row up to the
// exp/erfc).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "geometry/chunk_region.h"
#include "geometry/octree_keys.h"
#include "geometry/wedge_geometry.h"

namespace carvemap {

// Leaves t ∈ [lo, hi] along `axis` of the row whose other two local coordinates are
// u (axis + 1 mod 3) and v (axis + 2 mod 3), packed in one integer so that sorting runs sorts
// them by row (v, then u), then by lo:
//   bits 30–39 v, 20–29 u, 10–19 lo, 0–9 hi   (local coordinates < 2^10: kMaxChunkDepth = 10).
using LeafRun = uint64_t;
[[nodiscard]] constexpr LeafRun MakeLeafRun(int u, int v, int lo, int hi) {
  return uint64_t(v) << 30 | uint64_t(u) << 20 | uint64_t(lo) << 10 | uint64_t(hi);
}
[[nodiscard]] constexpr uint32_t RunRow(LeafRun r) { return uint32_t(r >> 20); }  // v << 10 | u
[[nodiscard]] constexpr int RunV(LeafRun r) { return int(r >> 30); }
[[nodiscard]] constexpr int RunU(LeafRun r) { return int((r >> 20) & 1023); }
[[nodiscard]] constexpr int RunLo(LeafRun r) { return int((r >> 10) & 1023); }
[[nodiscard]] constexpr int RunHi(LeafRun r) { return int(r & 1023); }

// Appends to `out`, sorted (as integers), the runs along `axis` (0 x, 1 y, 2 z) of the finest leaves of
// `chunk` that `hull` touches and, when `region` is given, that lie in it. Returns the number of
// leaves appended. REQUIRES: hull.planes.size() <= 64. Deterministic.
//
// Method: in leaf indices the test is linear (each plane: a·t + b·u + c·v ≤ g), so a row's
// leaves are an interval, and the rows that hold any form a convex polygon in (u, v), the
// projection of those constraints (Fourier–Motzkin: each pair of a lower and an upper bound on
// t). Cost: a few operations per plane per row, nothing per leaf.
// Exactness: the leaf boxes are NodeBox's, and a run end whose margin to a plane is below
// 1 nm (where rounding could decide) is settled with HullIntersectsBox's own arithmetic; only a
// plane that nearly contains a whole row (margin < 1 nm at every leaf of it) could differ.
size_t RasterizeHull(const WedgeHull& hull, const OctreeGrid& grid, const ChunkKey& chunk,
                     int axis, const ChunkRegion* region, std::vector<LeafRun>& out);

}  // namespace carvemap

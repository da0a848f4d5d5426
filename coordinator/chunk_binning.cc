#include "coordinator/chunk_binning.h"

#include <array>
#include <algorithm>
#include <cmath>

namespace carvemap {
namespace {

// Half-open ranges of chunk indices [lo, hi) per axis.
struct Range {
  std::array<int, 3> lo, hi;
};

Eigen::AlignedBox3d RangeBox(const Range& r) {
  return Eigen::AlignedBox3d(
      Eigen::Vector3d(r.lo[0], r.lo[1], r.lo[2]) * kChunkSizeM,
      Eigen::Vector3d(r.hi[0], r.hi[1], r.hi[2]) * kChunkSizeM);
}

// Halving the longest axis: a range the hull misses is dropped with one test, and the test is
// monotone in the box, so the result equals testing every chunk of the range one by one.
void Descend(const WedgeHull& hull, const Range& r, std::vector<ChunkKey>& out) {
  if (!HullIntersectsBox(hull, RangeBox(r))) return;
  int axis = 0;
  int longest = 0;
  for (int a = 0; a < 3; ++a) {
    if (r.hi[a] - r.lo[a] > longest) {
      longest = r.hi[a] - r.lo[a];
      axis = a;
    }
  }
  if (longest == 1) {
    out.emplace_back(r.lo[0], r.lo[1], r.lo[2]);
    return;
  }
  const int mid = r.lo[axis] + longest / 2;
  Range a = r, b = r;
  a.hi[axis] = mid;
  b.lo[axis] = mid;
  Descend(hull, a, out);
  Descend(hull, b, out);
}

}  // namespace

std::vector<ChunkKey> ChunksOfWedge(const WedgeHull& hull) {
  std::vector<ChunkKey> out;
  if (hull.box.isEmpty() || !(hull.box.min().array().abs() < kMaxWorldCoordinateM).all() ||
      !(hull.box.max().array().abs() < kMaxWorldCoordinateM).all()) {
    return out;  // also rejects NaN; keeps chunk indices far from int overflow
  }
  const ChunkKey lo = ChunkOf(hull.box.min());
  const ChunkKey hi = ChunkOf(hull.box.max());
  Range r;
  for (int a = 0; a < 3; ++a) {
    r.lo[a] = lo[a];
    r.hi[a] = hi[a] + 1;
  }
  Descend(hull, r, out);
  std::sort(out.begin(), out.end(), ChunkKeyLess());
  return out;
}

std::vector<ChunkKey> ChunksOfWedge(const Wedge& wedge, double sigmas) {
  return ChunksOfWedge(MakeWedgeHull(wedge, sigmas));
}

}  // namespace carvemap

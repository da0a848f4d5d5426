#include "geometry/octree_keys.h"

#include <cmath>
#include <string>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

// Resolutions are powers of two times 2 m, so x / resolution and x / 2 m are exact scalings:
// LeafOf and ChunkOf agree (ChunkOf(x) == ChunkOfLeaf(LeafOf(x))) for every x.
int FloorToInt(double v) { return static_cast<int>(std::floor(v)); }

std::string AllowedResolutions() {
  std::string s;
  for (int k = kMinChunkDepth; k <= kMaxChunkDepth; ++k) {
    absl::StrAppend(&s, k == kMinChunkDepth ? "" : ", ", kChunkSizeM / (1 << k));
  }
  return s;
}

// Spreads the low 21 bits of v so that bit i lands on bit 3i.
uint64_t Spread3(uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffULL;
  v = (v | v << 16) & 0x1f0000ff0000ffULL;
  v = (v | v << 8) & 0x100f00f00f00f00fULL;
  v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
  v = (v | v << 2) & 0x1249249249249249ULL;
  return v;
}

uint64_t Compact3(uint64_t v) {
  v &= 0x1249249249249249ULL;
  v = (v ^ (v >> 2)) & 0x10c30c30c30c30c3ULL;
  v = (v ^ (v >> 4)) & 0x100f00f00f00f00fULL;
  v = (v ^ (v >> 8)) & 0x1f0000ff0000ffULL;
  v = (v ^ (v >> 16)) & 0x1f00000000ffffULL;
  v = (v ^ (v >> 32)) & 0x1fffff;
  return v;
}

}  // namespace

absl::StatusOr<OctreeGrid> OctreeGrid::FromResolution(double resolution_m) {
  if (std::isfinite(resolution_m) && resolution_m > 0) {
    const int k = static_cast<int>(std::lround(std::log2(kChunkSizeM / resolution_m)));
    if (k >= kMinChunkDepth && k <= kMaxChunkDepth) {
      const double exact = kChunkSizeM / (1 << k);
      if (std::abs(resolution_m - exact) <= 1e-9 * exact) return OctreeGrid{k};
    }
  }
  return absl::InvalidArgumentError(
      absl::StrCat("resolution ", resolution_m, " m is not 2 m / 2^k; allowed (m): ",
                   AllowedResolutions()));
}

ChunkKey ChunkOf(const Eigen::Vector3d& x_world) {
  return ChunkKey(FloorToInt(x_world.x() / kChunkSizeM), FloorToInt(x_world.y() / kChunkSizeM),
                  FloorToInt(x_world.z() / kChunkSizeM));
}

LeafKey LeafOf(const OctreeGrid& grid, const Eigen::Vector3d& x_world) {
  const double r = grid.resolution_m();
  return LeafKey(FloorToInt(x_world.x() / r), FloorToInt(x_world.y() / r),
                 FloorToInt(x_world.z() / r));
}

ChunkKey ChunkOfLeaf(const OctreeGrid& grid, const LeafKey& leaf) {
  // C++20 defines >> on negative values as arithmetic, i.e. floor division by 2^k.
  return ChunkKey(leaf.x() >> grid.chunk_depth, leaf.y() >> grid.chunk_depth,
                  leaf.z() >> grid.chunk_depth);
}

Eigen::AlignedBox3d ChunkBox(const ChunkKey& chunk) {
  const Eigen::Vector3d lo = chunk.cast<double>() * kChunkSizeM;
  return Eigen::AlignedBox3d(lo, lo + Eigen::Vector3d::Constant(kChunkSizeM));
}

Eigen::AlignedBox3d LeafBox(const OctreeGrid& grid, const LeafKey& leaf) {
  const double r = grid.resolution_m();
  return Eigen::AlignedBox3d(leaf.cast<double>() * r,
                             (leaf.cast<double>() + Eigen::Vector3d::Ones()) * r);
}

Eigen::Vector3d LeafCenter(const OctreeGrid& grid, const LeafKey& leaf) {
  return (leaf.cast<double>() + Eigen::Vector3d::Constant(0.5)) * grid.resolution_m();
}

uint64_t MortonCode(const Eigen::Vector3i& local) {
  return Spread3(static_cast<uint32_t>(local.x())) |
         Spread3(static_cast<uint32_t>(local.y())) << 1 |
         Spread3(static_cast<uint32_t>(local.z())) << 2;
}

Eigen::Vector3i MortonDecode(uint64_t code) {
  return Eigen::Vector3i(static_cast<int>(Compact3(code)), static_cast<int>(Compact3(code >> 1)),
                         static_cast<int>(Compact3(code >> 2)));
}

Eigen::AlignedBox3d NodeBox(const OctreeGrid& grid, const ChunkKey& chunk,
                            const ChunkNode& node) {
  const double size = kChunkSizeM / (1 << node.depth);
  const Eigen::Vector3d lo =
      chunk.cast<double>() * kChunkSizeM + node.local.cast<double>() * size;
  return Eigen::AlignedBox3d(lo, lo + Eigen::Vector3d::Constant(size));
}

}  // namespace carvemap

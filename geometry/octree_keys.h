// Octree addressing shared by coordinator, workers, tiles and merge (docs/DESIGN.md §5). Space is
// cut into 2 m chunks (§4.3.1: chunks are non-leaf nodes of one octree); each chunk is an octree of
// depth k, so the resolution is 2 m / 2^k (k = 5: 6.25 cm, 6: 3.125 cm, 7: 1.5625 cm,
// 8: 0.78 cm).
//
// Keys are signed integers: leaf key = floor(x / resolution), chunk key = floor(x / 2 m), so
// chunk c holds leaf keys [c·2^k, (c+1)·2^k) on each axis. With OctoMap's 16-level tree at the
// same resolution, OctoMap's key is our leaf key + 32768 and our chunks are its nodes at depth
// 16 − k (32768 is a multiple of 2^k), so .bt export needs no resampling.
#pragma once

#include <cstdint>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "absl/status/statusor.h"

namespace carvemap {

inline constexpr double kChunkSizeM = 2.0;
inline constexpr int kMinChunkDepth = 1;
inline constexpr int kMaxChunkDepth = 10;  // 1.95 mm leaves; Morton codes fit 30 bits

using ChunkKey = Eigen::Vector3i;  // floor(x / 2 m)
using LeafKey = Eigen::Vector3i;   // floor(x / resolution)

// Strict weak order on chunk keys: x, then y, then z. Partial-sum sections, tile sets and the lease
// table all list chunks in this order.
struct ChunkKeyLess {
  bool operator()(const ChunkKey& a, const ChunkKey& b) const {
    if (a.x() != b.x()) return a.x() < b.x();
    if (a.y() != b.y()) return a.y() < b.y();
    return a.z() < b.z();
  }
};

struct OctreeGrid {
  int chunk_depth = 5;  // k

  // The grid whose resolution is `resolution_m`, which must be 2 m / 2^k (within 1e-9 relative)
  // with k in [kMinChunkDepth, kMaxChunkDepth]; otherwise InvalidArgument naming the
  // resolutions that are allowed.
  static absl::StatusOr<OctreeGrid> FromResolution(double resolution_m);

  [[nodiscard]] double resolution_m() const { return kChunkSizeM / (1 << chunk_depth); }
  [[nodiscard]] int leaves_per_side() const { return 1 << chunk_depth; }
};

[[nodiscard]] ChunkKey ChunkOf(const Eigen::Vector3d& x_world);
[[nodiscard]] LeafKey LeafOf(const OctreeGrid& grid, const Eigen::Vector3d& x_world);
[[nodiscard]] ChunkKey ChunkOfLeaf(const OctreeGrid& grid, const LeafKey& leaf);  // floor division
[[nodiscard]] Eigen::AlignedBox3d ChunkBox(const ChunkKey& chunk);
[[nodiscard]] Eigen::AlignedBox3d LeafBox(const OctreeGrid& grid, const LeafKey& leaf);
[[nodiscard]] Eigen::Vector3d LeafCenter(const OctreeGrid& grid, const LeafKey& leaf);

// A node inside a chunk: depth d in [0, k] (0 = the chunk itself, k = a finest leaf) and
// local coordinates in [0, 2^d) per axis. Its code interleaves the bits of the local
// coordinates (x in bit 0, y in bit 1, z in bit 2 of each triple; Morton order), which orders
// nodes of one depth along a Z-curve; tiles store (code, depth) pairs.
struct ChunkNode {
  Eigen::Vector3i local = Eigen::Vector3i::Zero();
  int depth = 0;
};
[[nodiscard]] uint64_t MortonCode(const Eigen::Vector3i& local);
[[nodiscard]] Eigen::Vector3i MortonDecode(uint64_t code);
// World box of a node of `chunk`.
[[nodiscard]] Eigen::AlignedBox3d NodeBox(const OctreeGrid& grid, const ChunkKey& chunk,
                                          const ChunkNode& node);

}  // namespace carvemap

// The merged octree in OctoMap's two file formats (docs/DESIGN.md §7), so that octovis and
// OctoMap's tools and library open it:
//   octree.bt  "# Octomap OcTree binary file": each node free, occupied or unknown (the
//              labels of §4.3.2);
//   octree.ot  "# Octomap OcTree file": each node's occupancy as log-odds, from eq 4.8's p
//              (the full probabilities, for users who threshold or update the map themselves).
// Written out of core: chunks are OctoMap nodes at depth 16 − k (geometry/
// octree_keys.h), so the tree is streamed in OctoMap's depth-first child order one tile at a
// time; only the open path of ≤ 16 nodes and the current tile are held.
//
// Formats (as Debian's liboctomap 1.9 reads them): header lines "<first line>", "id OcTree",
// "size <nodes>", "res <m>", "data", then the nodes depth first from the root, each written
// before its children, children in child order (child index = x bit + 2·y bit + 4·z bit, the
// Morton order tiles use).
// - .bt (OccupancyOcTreeBase::readBinaryNode): every inner node as 2 bytes: byte 0 for
//   children 0–3, byte 1 for children 4–7, 2 bits per child i at bits 2(i mod 4) (low) and
//   2(i mod 4)+1 (high): low=1 high=0 free leaf, low=0 high=1 occupied leaf, 11 inner node
//   (its bytes follow later, after its earlier siblings' subtrees), 00 no child (unknown).
// - .ot (OcTreeBaseImpl::readNodesRecurs, OcTreeNode::readData): every node, leaf or inner, as
//   its log-odds (a 4-byte float in the machine's order, as OctoMap writes it) and one byte
//   whose bit i says child i follows; an inner node's value is the largest of its children's.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/carving_types.h"
#include "services/merge/tile_set.h"
#include "storage/tile_store.h"

namespace carvemap {

inline constexpr int kOctomapTreeDepth = 16;
inline constexpr int kOctomapKeyOffset = 32768;  // OctoMap key = our leaf key + this

// What a leaf becomes in octree.ot: OctoMap's log-odds of occupancy, log(q / (1 − q)) with
// q = 1 − p (p: eq 4.8's probability of open space), q clamped to [kOtMinProbability,
// 1 − kOtMinProbability] so that a leaf every ray agreed on stays finite (±13.8).
inline constexpr double kOtMinProbability = 1e-6;
[[nodiscard]] float OtLogOddsOf(const LeafStats& stats);

// What a leaf becomes in octree.bt. OctoMap's "occupied" is solid matter, our exterior; the
// carve map's interior (p > 0.5, open space) is OctoMap's "free". Unobserved space is unknown.
enum class BtLabel : uint8_t { kUnknown, kFree, kOccupied };
[[nodiscard]] BtLabel BtLabelOf(const LeafStats& stats);

struct OctomapFileStats {
  uint64_t num_nodes = 0;  // the header's size: every node, inner and leaf, root included
  uint64_t bytes = 0;      // file size
};
struct OctomapFilesStats {
  uint64_t num_tiles = 0;   // tiles read (each once)
  OctomapFileStats bt, ot;  // zero for a file not asked for
};

// Called once per tile, in the order written; a non-OK status (e.g. Cancelled) stops the
// write and is returned as is.
using TileVisitor = std::function<absl::Status(const TileData& tile)>;

// Writes `bt_path` (.bt) and `ot_path` (.ot), each through "<path>.partial" and a rename, from
// one read of every tile of `tiles`, calling `visit` on each; an empty path is not written.
// Sibling leaves that OctoMap's prune() would merge are merged (.bt: one label; .ot: one value).
// OutOfRange for a chunk beyond OctoMap's key space (|leaf key| > 32768, i.e. about ±2 km at
// 6.25 cm); tile errors as TileSet::Get; Unavailable naming the file for I/O errors. On any
// error neither file is left.
absl::StatusOr<OctomapFilesStats> WriteOctomapFiles(TileSet& tiles, const std::string& bt_path,
                                                    const std::string& ot_path,
                                                    const TileVisitor& visit = nullptr);

}  // namespace carvemap

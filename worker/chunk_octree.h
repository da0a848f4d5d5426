// The probabilistic octree of one 2 m chunk (§4.3.1–§4.3.2, docs/DESIGN.md §5): wedges are carved
// into its finest leaves (eq 4.8), then the tree is simplified bottom-up (§4.3.2) and its
// leaves go to a tile (storage/tile_store.h).
//
// Representation: only observed leaves are stored, per depth, keyed by Morton code. Every
// region no stored leaf covers is unobserved (p = 0.5, count 0, exterior; §4.3.2). That is the
// same tree the dissertation describes: its unobserved leaves are the maximal nodes holding no
// observed leaf, which the stored leaves determine. Memory is ∝ observed leaves (~50 B each).
//
// Thread-compatible: one ChunkOctree per chunk and thread; const methods may run concurrently.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/container/flat_hash_map.h"
#include "absl/status/status.h"
#include "geometry/carving_types.h"
#include "geometry/chunk_region.h"
#include "geometry/octree_keys.h"
#include "storage/tile_store.h"

namespace carvemap {

// §4.3.1: each ray of a wedge is extended this many σ past its point.
inline constexpr double kWedgeHullSigmas = 3.0;
// Ray contributions with w = f_⊥ below this are skipped (see CarveWedges; carve_map.h already
// returns w = 0 beyond f_⊥ < e^−39 ≈ 1e−17).
inline constexpr double kMinRayWeight = 1e-15;

class ChunkOctree {
 public:
  // REQUIRES: grid.chunk_depth in [kMinChunkDepth, kMaxChunkDepth].
  ChunkOctree(const OctreeGrid& grid, const ChunkKey& chunk);
  ChunkOctree(const ChunkOctree&) = delete;
  ChunkOctree& operator=(const ChunkOctree&) = delete;
  ChunkOctree(ChunkOctree&&) = default;
  ChunkOctree& operator=(ChunkOctree&&) = default;

  // Carves wedges (eq 4.8): a finest leaf L of this chunk is touched by a wedge when the wedge
  // hull (MakeWedgeHull, kWedgeHullSigmas) touches L's box. S(L), "the list of intersecting scan
  // rays", is the SET of rays of the wedges that touch L: a ray shared by several such wedges
  // (neighbouring wedges share edges: each ray of a line or grid sensor belongs to up to 4)
  // votes once, with its carve map value at the leaf centre, LeafStats::Add(p, w), skipping
  // w < kMinRayWeight. Rays are the entries of wedges.rays (the payload stores each ray once;
  // two equal entries would vote as two rays). The set is exact within one call (the worker
  // passes a chunk's whole payload); a ray given again in a later call votes again. A wedge that misses the chunk
  // changes nothing; rays shorter than 1 µm carve nothing. Votes are summed in a fixed order
  // that depends only on the input, so equal input gives bit-identical sums.
  // Each distinct ray whose point lies in an observed finest leaf of the chunk (and of the
  // region, if any) also adds 1 to that leaf's `points` (§4.2.3's point voxel set).
  // Errors (nothing changed): InvalidArgument for num_rays outside [1, 4], a ray index out of
  // range or a non-finite mean/covariance (naming the wedge or ray); FailedPrecondition after
  // Simplify().
  absl::Status CarveIndexed(const IndexedWedges& wedges);
  // The same for wedges that carry copies of their rays: rays are the same when their
  // RayModels are bit-identical, as copies of one ray in several wedge records are.
  absl::Status CarveWedges(std::span<const Wedge> wedges);
  absl::Status CarveWedge(const Wedge& wedge) { return CarveWedges({&wedge, 1}); }
  // Later carving touches only the leaves inside `region` (§5.6.1: a second, finer pass over
  // the nodes that hold objects); the rest of the chunk stays unobserved. Shared, not copied:
  // a decoded region's tables are up to ~1.2 MB at the finer pass's depth, and the carver that
  // decoded it counts it once in its memory budget.
  void RestrictTo(std::shared_ptr<const ChunkRegion> region) { region_ = std::move(region); }
  // For later carving (default kFast).
  void SetEvaluation(CarveEvaluation e) { evaluation_ = e; }
  // The carves into this tree are parts of the chunk's carve (time slices of the scan,
  // worker/slice_carver.h): a voting ray's scan point is counted in its finest leaf even when
  // no ray of these parts observed the leaf (another part may). The parts' finest leaves are
  // added up with AddFinest, and DropUnobserved then forgets the leaves no part observed.
  void SetPartial(bool partial) { partial_ = partial; }
  // Adds a part's sums of finest leaves (depth chunk_depth, any order) to the tree's, and its
  // wedge count to num_wedges(). InvalidArgument for a leaf of another depth or outside the
  // chunk; FailedPrecondition after Simplify().
  absl::Status AddFinest(std::span<const TileLeaf> leaves, uint64_t wedges);
  // Removes the finest leaves no ray observed (count 0: kept by a part for their points).
  void DropUnobserved();
  // The finest leaves as they are (before Simplify: a part's sums), in canonical tile order.
  [[nodiscard]] std::vector<TileLeaf> FinestLeaves() const;

  // §4.3.2, bottom-up: 8 sibling leaves merge into their parent (LeafStats::Merge, exact sums)
  // when all 8 are observed leaves with the same label (interior iff p > 0.5) and none holds a
  // scan point (LeafStats::points stay at the finest depth, where segmentation reads them). A
  // node with an unobserved child is never merged (its children are not all observed, nor all
  // unobserved); a node whose children are all unobserved is an unobserved leaf already
  // (stores nothing).
  // Repeats up to the chunk root. Labels of every point are unchanged. Idempotent.
  void Simplify();

  // The observed leaves in canonical tile order (SortTileLeaves): deterministic, whatever the
  // hash maps' iteration order.
  [[nodiscard]] std::vector<TileLeaf> Leaves() const;
  // The statistics of the leaf holding `x_world` (count 0, p 0.5 when unobserved or outside
  // the chunk), and the depth of that stored leaf (-1 when none).
  [[nodiscard]] LeafStats StatsAt(const Eigen::Vector3d& x_world, int* depth = nullptr) const;
  // The leaves as a tile; params.num_wedges/hull_sigmas/min_weight/simplified are filled in.
  [[nodiscard]] TileData ToTile(const std::string& job_id) const;

  [[nodiscard]] const OctreeGrid& grid() const { return grid_; }
  [[nodiscard]] const ChunkKey& chunk() const { return chunk_; }
  [[nodiscard]] size_t num_leaves() const;
  // Bytes the leaves' hash maps take: their slots at their capacity (a map has up to twice
  // the slots it fills after it grows) and a control byte per slot.
  [[nodiscard]] size_t memory_bytes() const;
  [[nodiscard]] bool simplified() const { return simplified_; }
  [[nodiscard]] uint64_t num_wedges() const { return num_wedges_; }  // carved, incl. misses
  [[nodiscard]] uint64_t num_leaf_updates() const { return num_leaf_updates_; }  // Add() calls
  // (leaf, wedge) pairs the wedge hulls touched.
  [[nodiscard]] uint64_t num_leaf_touches() const { return num_leaf_touches_; }

 private:
  using Level = absl::flat_hash_map<uint64_t, LeafStats>;  // Morton code at that depth → stats

  void CountPoints(const IndexedWedges& in);

  OctreeGrid grid_;
  ChunkKey chunk_;
  // levels_[d]: observed leaves at depth d. Carving fills levels_[k] only; Simplify moves
  // merged parents up.
  std::vector<Level> levels_;
  std::shared_ptr<const ChunkRegion> region_;
  CarveEvaluation evaluation_ = CarveEvaluation::kFast;
  bool partial_ = false;
  bool simplified_ = false;
  uint64_t num_wedges_ = 0;
  uint64_t num_leaf_updates_ = 0;
  uint64_t num_leaf_touches_ = 0;
};

}  // namespace carvemap

// Thin unobserved pockets inside carved free space, filled as free for the merge's stages.
//
// §4.3.2 counts unobserved space as exterior. Between the sweeps of a backpack's line scanners
// some of the room's air is crossed by no wedge: a layer a few cells thick at the height where
// no scanner's plane reaches, a gap under a ceiling. Bounded by carved free space, such a
// pocket is exterior to the octree, so the dense mesh closes it (a floating surface, a false
// ceiling), the levels and wall samples see a ceiling in mid-air, and the segmentation may take
// it for an object (a slab at scanner height). Solid surfaces are observed (their wedges reach
// σ past the points), so unobserved space with observed free space on both sides is air no
// ray happened to cross, not the inside of a wall or of furniture (those end at solid cells).
//
// A finest unobserved cell is a candidate when, along some axis, it lies in a run of unobserved
// cells no longer than max_thickness_m whose two neighbours beyond the run are observed interior
// (free) cells. A pocket is a 6-connected set of candidates; it is filled only whole, when no
// cell of it touches unobserved space that is not a candidate: filling the thin part of a
// region that thickens would put a surface of our own where the thickness passes the limit (a
// wall where a ceiling's pocket deepens). A filled cell gets one vote of the lowest p of the
// free cells ending its runs, so the isosurface beside it sits as beside its neighbours. The
// job's own tiles keep the pockets unobserved (octree.bt says what the scan saw); the merge
// meshes and segments a copy with the pockets filled.
//
// In three steps, so that a pocket may span chunks and the work stays out of core:
// PocketCandidates per chunk (with its 26 neighbours), FillablePocketCells or
// KeepFillablePocketCells over all chunks' candidates (24 bytes a candidate, and 5 for the
// sets), WithFilledCells per chunk. Plain functions over plain data: no files, no logging.
#pragma once

#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/octree_keys.h"
#include "services/mesh/boundary_faces.h"
#include "storage/tile_store.h"

namespace carvemap {

struct PocketFillOptions {
  // The thickest pocket filled, m: runs of at most this many cells' length (at least one cell).
  // A slab of unswept air left between a backpack's scanner planes at 10 Hz was 0.45 m thick;
  // a room's air between two walls is far wider than this.
  double max_thickness_m = 0.5;
  // InvalidArgument naming the field.
  [[nodiscard]] absl::Status Validate() const;
};

// A candidate cell of a pocket, in global finest-cell coordinates. 24 bytes: the merge holds
// every candidate of the building at once.
struct PocketCell {
  LeafKey cell = LeafKey::Zero();
  bool tainted = false;  // a 6-neighbour is unobserved and no candidate
  double p = 0;          // the vote it gets when filled
};

// The candidates of `hood.chunk`, sorted by cell (z, then y, then x). A chunk without a tile
// has none (a run through it would be longer than the chunk). Grids of fewer than 4 cells a
// side have none (no room for a run and its ends in the 26 neighbours). Errors:
// InvalidArgument for bad options or a neighbourhood NeighbourhoodIndex::Build rejects (a tile
// in the wrong slot or at another depth, a leaf outside its chunk, overlapping leaves).
[[nodiscard]] absl::StatusOr<std::vector<PocketCell>> PocketCandidates(
    const ChunkNeighbourhood& hood, const PocketFillOptions& options = {});

// Of all chunks' candidates (any order), those whose pocket holds no tainted cell, sorted by
// cell as PocketCandidates sorts them.
[[nodiscard]] std::vector<PocketCell> FillablePocketCells(std::vector<PocketCell> candidates);

// Drops from one chunk's candidates (PocketCandidates' result for `chunk`, sorted) the pockets
// that lie wholly inside the chunk, touch none of its faces and hold a tainted cell: no other
// chunk's candidate can join them, so they are never filled. Most thin unobserved layers are
// such (a four-level office's finer re-carve filled 3,713 cells, while holding all its
// candidates took the merge from 0.34 to 1.0 GiB), and the merge holds every chunk's
// candidates at once. Keeps the order.
void DropInnerTaintedPockets(std::vector<PocketCell>& cells, const ChunkKey& chunk,
                             const OctreeGrid& grid);

// FillablePocketCells over the candidates kept per chunk, in place, without a copy of them
// all: each entry of `chunks` is a chunk and its candidates (sorted by cell as
// PocketCandidates gives them, each in that chunk by ChunkOfLeaf, a chunk at most once); on
// return each keeps only its fillable cells, in the same order, and the entries are sorted by
// ChunkKeyLess. The cells kept are FillablePocketCells' of all entries'.
// InvalidArgument for a cell outside its entry's chunk or a chunk given twice.
[[nodiscard]] absl::Status KeepFillablePocketCells(
    std::vector<std::pair<ChunkKey, std::vector<PocketCell>>>& chunks, const OctreeGrid& grid);

// `tile` with one finest leaf per cell of `cells` (each in its chunk, unobserved in it):
// sum_w 1, Σ w p = p, count 1. InvalidArgument for a cell outside the chunk.
[[nodiscard]] absl::StatusOr<TileData> WithFilledCells(const TileData& tile,
                                                       std::span<const PocketCell> cells);

}  // namespace carvemap

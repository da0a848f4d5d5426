// Thin unobserved pockets inside carved free space, filled as free for the merge's stages.
//
// §4.3.2 counts unobserved space as exterior. Between the sweeps of a backpack's line scanners
// some of the room's air is crossed by no wedge: a layer a few cells thick at the height where
// no scanner's plane reaches, a gap under a ceiling. Bounded on both sides by carved free
// space, such a pocket is exterior to the octree, so the dense mesh closes it (a floating
// surface, a false ceiling), the levels and wall samples see a ceiling in mid-air, and the
// segmentation may take it for an object (a slab at scanner height). Solid surfaces are
// observed (their wedges reach σ past the points), so a run of unobserved cells with observed
// free space at both ends, along an axis, is air no ray happened to cross, not the inside of a
// wall or of furniture (those end at observed solid cells).
//
// A finest cell is filled when, along some axis, it lies in a run of unobserved cells no longer
// than max_thickness_m whose two neighbours beyond the run are observed interior (free) cells.
// It gets one vote of the lower of those two cells' p, so the isosurface beside it sits as
// beside its neighbours. The job's own tiles keep the pocket unobserved (octree.bt says what
// the scan saw); the merge meshes and segments a copy with the pockets filled.
//
// Plain function over plain data: no files, no logging. Per chunk, with its 26 neighbours for
// the runs that cross its faces, so it runs out of core.
#pragma once

#include <cstdint>

#include "absl/status/statusor.h"
#include "services/mesh/boundary_faces.h"
#include "storage/tile_store.h"

namespace carvemap {

struct PocketFillOptions {
  // The thickest pocket filled, m: runs of at most this many cells' length (at least one cell).
  // The slab left between a backpack's scanner planes at 10 Hz was 0.45 m thick (issue of
  // objects on real layouts); a room's air between two walls is far wider than this, and a
  // wall's inside ends at observed solid cells whatever its thickness.
  double max_thickness_m = 0.5;
  // InvalidArgument naming the field.
  [[nodiscard]] absl::Status Validate() const;
};

struct FilledChunk {
  TileData tile;              // the chunk's leaves and one finest leaf per filled cell
  uint64_t filled_cells = 0;  // 0: `tile` has the input's leaves unchanged
};

// The chunk `hood.chunk` with its pockets filled. Its tile may be null (all unobserved: such
// a chunk gets no leaves, filled_cells 0). Errors: InvalidArgument for bad options or a
// neighbourhood NeighbourhoodIndex::Build rejects.
[[nodiscard]] absl::StatusOr<FilledChunk> FillPockets(const ChunkNeighbourhood& hood,
                                                      const PocketFillOptions& options = {});

}  // namespace carvemap

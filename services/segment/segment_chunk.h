// Segmentation of one chunk of the octree against the extruded floor plans (§5.5, §5.6;
// docs/DESIGN.md §6 stages 6–7). Every finest cell gets one of four classes:
//   - free: interior in the octree (p > 0.5) and within d of the plan (§5.5);
//   - trimmed: interior in the octree but farther than d = trim_distance_m from the plan's
//     interior (2D, on its level): space seen through windows and open doors, not meshed;
//   - object: exterior in the octree and interior in the extruded plan, the cell's whole box
//     inside it (§5.6: "volume intersected by the boundary of the 2.5D floor plan is considered
//     exterior", so walls, floors and ceilings stay building). Observed solid space always;
//     unobserved space only where it is hidden behind a solid surface (below); interior space
//     where the scan points say it is solid (below);
//   - building: every other exterior cell.
// The result is two tiles of the same chunk that the existing stages mesh unchanged:
//   - building: interior = free ∪ object (the union of both models' interiors, §5.6), so its
//     planar mesh keeps the wall surfaces hidden behind furniture; trimmed cells are exterior;
//   - objects: interior = object cells only, so its dense mesh is the objects, closed at the
//     back where they touch the plan's walls and floors.
// Unobserved space: §4.3.2 makes it exterior, and the dissertation fills the hidden backs of
// furniture "based on the wall location" (§5.6.2, Fig 5.18e). But a backpack's line scanners leave
// much of a room unswept (measured on the simulated office: 96 % of the candidate object cells were
// unobserved, most of them empty air near walls and floors), so unobserved space is object
// only when, looking along the plan's wall normal through the cell, the first observed cell
// away from the nearest wall is solid and the first one towards it is solid or the wall itself,
// both within hidden_fill_m: the space between a shelf's seen front and the wall behind it,
// or inside a chair's seen shell; not a pocket of unswept air in front of an empty wall.
// Scan points: the wedges of §4.3.1 interpolate between neighbouring rays, so a ray passing
// beside a 2–5 cm leg, rod or board carves it as free even at 1.5625 cm (measured on the
// simulated office: desks came out as their tops, lamps without their rods). §4.2.3 keeps such
// detail in voxel carving with a second voxel set, the voxels holding scan points, which it
// treats as exterior. Here the points (LeafStats::points, counted by the worker) count over
// cubes of point_cell_m (a cell, or on grids finer than it a cube of cells: a scan's points
// lie a few cm apart, so 1.5625 cm cells would leave a leg as a dotted line), and an interior
// cell whose cube holds at least min_points of them is classified as solid: an object where
// the plan says so, else as carved. Measured on the simulated office (docs/BENCHMARKS.md),
// objects re-carved at 3.125 cm: one point per 3.125 cm cube found 62 of 96 objects, two per
// 6.25 cm cube 52 (fewer chairs and lamps: a lamp's 2 cm rod gets 0–11 points in all).
// Relabelled leaves keep their evidence mirrored (p → 1 − p, sums mirrored exactly) so the
// Fig 4.9 isosurface between an object and the free space beside it sits where the octree put
// it; unobserved cells that become interior get p = kUnobservedObjectP.
//
// Plain function over plain data: no files, no logging. Per chunk, so it runs out of core.
#pragma once

#include <cstdint>

#include "absl/status/statusor.h"
#include "geometry/chunk_region.h"
#include "geometry/octree_keys.h"
#include "services/mesh/boundary_faces.h"
#include "services/segment/plan_volume.h"
#include "storage/tile_store.h"

namespace carvemap {

struct SegmentOptions {
  // §5.5: interior octree space farther than this from the floor plan's interior is dropped
  // (the dissertation's Fig 5.14 uses a 1 m buffer), m. The PlanVolume must be rasterized with a
  // margin larger than this: columns beyond its raster count as farther.
  double trim_distance_m = 1.0;
  // §5.6.1: the plan is aligned with the octree but simplified (§3.3.3 moves walls by up to the
  // error bound) and its floor/ceiling heights are medians; a cell is an object only when its
  // box lies inside the extruded plan by at least this much more, m. < 0: one finest cell
  // (the carved walls and ceilings seen at grazing angles lie up to a cell or two inside the
  // plan's, measured on the simulated office).
  double plan_tolerance_m = -1;
  // §4.3.2 counts unobserved space as exterior, so inside the plan it is object (the hidden
  // backs and insides of furniture). false: unobserved space is never object.
  bool unobserved_is_object = true;
  // How far the hidden-space test above looks each way, m.
  double hidden_fill_m = 1.0;
  // §4.2.3 point evidence (above): an interior cell is solid when the cube of side
  // point_cell_m around it (aligned with the octree; at least one cell) holds at least
  // min_points scan points. 0 = off.
  int min_points = 1;
  double point_cell_m = 0.03125;
  // Such cells keep this much more from the plan's walls than solid cells do, m: a wall's
  // scan points lie in the free layer in front of its carved surface, one cell further into
  // the room, and §3.3.3's simplification moves the plan's walls by up to its error bound.
  // Measured: office2's false objects 11 % with 0, 9 % with 0.05 or 0.1 m; 0.1 m lost shelves.
  double point_wall_margin_m = 0.05;
  // InvalidArgument naming the bad field.
  [[nodiscard]] absl::Status Validate() const;
};

// p given to unobserved cells that the segmentation turns into interior (objects' hidden
// backs and insides): clearly interior, so the isosurface sits near the cell boundary.
inline constexpr double kUnobservedObjectP = 0.75;

enum class CellSegment : uint8_t { kFree = 0, kTrimmed = 1, kObject = 2, kBuilding = 3 };

// The class of a finest cell with centre `centre`, interior (p > 0.5) or not, observed or not,
// from the plan alone (an unobserved cell it calls object still needs the hidden-space test of
// SegmentChunk). `points`: its point cube holds at least min_points (an interior cell is then
// classified as solid). `res_m` is the finest resolution.
// `above_is_object`: the cell directly above is an object. Furniture stands on the floor, and
// the tolerance band above the plan's floor would otherwise cut every standing object a cell
// or two above it (measured on the simulated office: boxes stopped 8 cm above the floor); so a
// solid, unobserved or point cell in that band whose centre is above the floor is an object
// under one (unobserved: hidden from above by the object, so no hidden-space test).
[[nodiscard]] CellSegment ClassifyCell(const PlanVolume& plan, const Eigen::Vector3d& centre,
                                       bool interior, bool observed, bool points, double res_m,
                                       const SegmentOptions& options, bool above_is_object = false);

struct SegmentedChunk {
  TileData building;  // same chunk and grid as the input
  TileData objects;   // no leaves when the chunk has no object cell
  uint64_t object_cells = 0;
  uint64_t unobserved_object_cells = 0;  // of object_cells
  uint64_t trimmed_cells = 0;
};

// Segments `hood.chunk` (its tile may be null: all unobserved); the neighbours' tiles serve the
// hidden-space test across chunk borders (beyond them it sees nothing and fails). Leaves are
// split only where the class changes inside them; uniform runs stay one leaf.
// `only_in` (§5.6.1's second pass): cells outside it are never object (they were not carved
// again; null = the whole chunk).
// InvalidArgument: bad options, or NeighbourhoodIndex::Build's errors (a tile of another chunk
// or grid than its slot).
[[nodiscard]] absl::StatusOr<SegmentedChunk> SegmentChunk(const ChunkNeighbourhood& hood,
                                                          const PlanVolume& plan,
                                                          const SegmentOptions& options,
                                                          const ChunkRegion* only_in = nullptr);

// §5.6.1: the part of a chunk worth carving again finer, from its object tile (SegmentChunk's
// `objects`): every object cell at the tile's depth, the cells within `margin_cells` of one,
// the columns below one down to its room's floor (furniture stands on legs and frames that
// the coarse grid may have carved away), and, for a cell whose top is within
// `ceiling_reach_m` of its room's ceiling, the column above it up to the ceiling (a hanging
// lamp's rod). Empty when the tile has no object cell.
// The rods are 2 cm: the wedges carve them away even at 1.5625 cm, but a few of the scan's
// points hit them (0–25 per rod on the simulated office), and those make their cells solid
// (the point evidence above), so the lamp's box reaches up its rod. Before the point evidence
// existed, columns up to the ceiling found nothing.
[[nodiscard]] ChunkRegion ObjectRecarveRegion(const TileData& objects, const PlanVolume& plan,
                                              int margin_cells, double ceiling_reach_m = 0);

}  // namespace carvemap

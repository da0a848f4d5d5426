// The planar regions (§4.2.4) that the levels (§5.2) and the floor plans' wall samples (§5.3.1)
// are made from, fitted a part of the building at a time, so that their memory follows a plane
// or a level rather than the whole building (docs/DESIGN.md §6 stages 2–4).
//
// Levels: §5.2 reads only the near-horizontal regions, and those are flat: a floor or ceiling
// spans centimetres in height, and takes in only the one-cell risers of its carved steps (a
// group joins a region when all its points lie within the grid-size tolerance of the union's
// plane, whatever its axis). So the building is fitted in slabs of height, each with a margin
// above and below, and each region is kept by the one slab whose core holds its centroid: the
// near-horizontal regions come out as from one fit of the whole building, but where a wall cut
// at a slab's edge changes the order in which growth meets the groups (docs/BENCHMARKS.md
// measures the difference on the office). Walls are cut there; the levels do not read them.
//
// Walls: each level's wall samples come from the regions of the faces in its height range and
// a margin (LevelBand), fitted for that level alone.
//
// Both read the faces sorted by height (sorted_faces.h) a range at a time, so that the merge
// holds a slab's or a level's faces, not the building's.
//
// Plain functions over plain data: no files, no logging. Thread-compatible.
#pragma once

#include <cstddef>
#include <span>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "geometry/octree_keys.h"
#include "services/levels/level_split.h"
#include "services/mesh/boundary_faces.h"
#include "services/mesh/planar_regions.h"
#include "services/mesh/sorted_faces.h"

namespace carvemap {

// Faces in a slab's core (LevelRegions): ~200 MiB of fitting at ~200 B per face
// (docs/BENCHMARKS.md "The planar stages' own memory"), plus its margins. One lattice plane
// with more faces is one core.
inline constexpr size_t kLevelSlabFaces = size_t{1} << 20;
// A slab's margin above and below its core, m: many times the grid-size tolerance and a floor's
// carved steps, so that a region whose centroid lies in the core is fitted whole.
inline constexpr double kLevelSlabMarginM = 0.5;

// The planar regions that the levels read, of the sorted faces that `heights` indexes and
// `read` reads, fitted slab by slab: the cores are consecutive ranges of the faces' centre
// heights (whole lattice planes, at most `slab_faces` faces each unless one plane has more);
// each slab adds the faces within `margin_m` above and below its core. A region is kept when its
// centroid's height lies in its slab's core. Each keeps its normal, centroid, area and
// eigenvalues; its `faces` list is left empty. The order: slabs from the bottom up, each slab's
// regions in FitPlanarRegions' order; ids are positions. Errors: FitPlanarRegions' and
// `read`'s, and InvalidArgument for slab_faces = 0 or a negative or non-finite margin.
[[nodiscard]] absl::StatusOr<std::vector<PlanarRegion>> LevelRegions(
    const FaceHeights& heights, const ReadFacesFn& read, const OctreeGrid& grid,
    const PlanarRegionOptions& options = {}, size_t slab_faces = kLevelSlabFaces,
    double margin_m = kLevelSlabMarginM);

// LevelRegions of faces held in memory, sorted by height; also InvalidArgument for faces that
// are not sorted or whose height is not finite.
[[nodiscard]] absl::StatusOr<std::vector<PlanarRegion>> LevelRegions(
    std::span<const BoundaryFace> faces, const OctreeGrid& grid,
    const PlanarRegionOptions& options = {}, size_t slab_faces = kLevelSlabFaces,
    double margin_m = kLevelSlabMarginM);

// Beyond a level's split heights, the faces its wall regions are fitted from reach this far, m:
// a wall's plane is fitted over more than the level's own part of it (the split lies within a
// slab, a few decimetres from the nearest ceiling or floor), as when the whole building was
// fitted at once.
inline constexpr double kLevelBandMarginM = 0.5;

// The index range of the sorted faces whose centre's height lies in
// [level.split_z_low − margin_m, level.split_z_high + margin_m).
[[nodiscard]] std::pair<uint64_t, uint64_t> LevelBand(const FaceHeights& heights,
                                                      const Level& level,
                                                      double margin_m = kLevelBandMarginM);

}  // namespace carvemap

// The building's boundary faces cut at heights into closed parts, one per level, so that the
// planar mesh (§4.3.3) is made a level at a time and its memory follows a level, not the
// building (docs/DESIGN.md §6 stage 8).
//
// A part is the boundary of the interior cells between two cut planes: the faces whose
// interior side lies between them, and caps on each plane where the cells just below and just
// above it are both interior (a stairwell, a shaft; the planes lie in the slabs between levels,
// so elsewhere there is solid). A cap's isosurface is a quarter of a finest cell inside its
// part, so that the caps of the two parts on one plane lie half a cell apart and do not meet.
// Coarse vertical faces that straddle a plane are cut into finest squares.
//
// Plain function over plain data: no files, no logging. The octree is read through
// `InteriorAtFn`, which the caller wraps around TileSet::Query.
#pragma once

#include <functional>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "geometry/octree_keys.h"
#include "services/mesh/boundary_faces.h"

namespace carvemap {

// Whether the finest cell holding the point is interior (p > 0.5). Errors are passed on.
using InteriorAtFn = std::function<absl::StatusOr<bool>(const Eigen::Vector3d&)>;

// A cut plane: the lattice plane nearest a height, and the finest columns where the cells just
// below and just above it are both interior (where the parts on either side get caps).
struct CutPlane {
  double z = 0;                            // m; ±infinity: no plane
  std::vector<Eigen::Vector2d> crossings;  // the columns' centres, m
};

// The cut plane nearest `z` (±infinity: no plane, no crossings), its crossings looked for over
// the finest columns of `xy_min`–`xy_max` (the faces' extent). Found once per plane, it caps
// the parts on both its sides. Errors: InvalidArgument for an extent of more than 2^28 columns;
// those of `interior_at`.
[[nodiscard]] absl::StatusOr<CutPlane> FindCutPlane(const OctreeGrid& grid, double z,
                                                    const Eigen::Vector2d& xy_min,
                                                    const Eigen::Vector2d& xy_max,
                                                    const InteriorAtFn& interior_at);

struct LevelPart {
  std::vector<BoundaryFace> faces;  // the part's faces, then its caps
  size_t caps = 0;                  // the caps among them (the last ones)
};

// The part of `faces` between the planes `low` and `high` (FindCutPlane's), capped at each
// plane's crossings. Errors: InvalidArgument for low.z ≥ high.z, or a face whose size is not a
// whole number of finest cells.
[[nodiscard]] absl::StatusOr<LevelPart> CutLevelPart(std::span<const BoundaryFace> faces,
                                                     const OctreeGrid& grid, const CutPlane& low,
                                                     const CutPlane& high);

}  // namespace carvemap

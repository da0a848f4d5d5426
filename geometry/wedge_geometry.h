// The volume of a wedge (§4.2.1, §4.3.1) and its intersection with axis-aligned boxes (octree
// nodes and 2 m chunks). Shared by the coordinator, which bins wedges into the chunks they
// touch, and the workers, which find the leaves they touch: both must agree.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "absl/status/status.h"
#include "geometry/carving_types.h"

namespace carvemap {

// A convex volume as half-spaces normal·x <= offset, plus its bounding box.
struct WedgeHull {
  std::vector<Eigen::Vector4d> planes;  // (nx, ny, nz, offset), unit normals pointing out
  Eigen::AlignedBox3d box;
};

// The hull of the wedge's sensor means and its point means extended `sigmas` standard
// deviations (F_p's: the point's range given its offset across the ray, carve_map.h) past the
// point (§4.3.1: 3σ). A single-ray
// wedge is that segment in a box 1σ wide across the ray along the principal axes of its lateral
// spread (not `sigmas`: see kSingleRayLateralSigmas in the .cc).
// `facets`, if given, receives a hint for rebuilding the same hull faster (the facet triples of
// the points, 0 when the hull is not made of them): see HullOfWedgePoints.
[[nodiscard]] WedgeHull MakeWedgeHull(const Wedge& wedge, double sigmas = 3.0,
                                      uint64_t* facets = nullptr);
// The same hull from a multi-ray wedge's points, for callers that computed them once per ray:
// the rays' sensor means and their ExtendedPointMean (same order, 2 to 4 rays). `facets`, if
// given, is a hint in and out: in, a nonzero hint from an earlier call on the same points
// (the binning's, kept with the wedge for its chunks) skips the search for facets and gives
// the same hull bit for bit (a hint naming a non-facet is ignored; one missing a facet would
// give a larger hull); out, the hint for this hull.
[[nodiscard]] WedgeHull HullOfWedgePoints(std::span<const Eigen::Vector3d> sensor_means,
                                          std::span<const Eigen::Vector3d> far_ends,
                                          uint64_t* facets = nullptr);
// A box that contains HullOfWedgePoints' hull of the same points (its bounding box, however
// thin the points are), without building the hull: where the box meets nothing of interest,
// neither does the hull.
[[nodiscard]] Eigen::AlignedBox3d WedgePointsBox(std::span<const Eigen::Vector3d> sensor_means,
                                                 std::span<const Eigen::Vector3d> far_ends);

// Conservative: true whenever the hull and the box intersect (it may also say true for a box
// that only comes near the hull, never false for one that touches it).
[[nodiscard]] bool HullIntersectsBox(const WedgeHull& hull, const Eigen::AlignedBox3d& box);

// The ray's point mean moved `sigmas`·σ_∥ further along the ray (σ_∥ of F_p, the range given the
// offset across the ray, PointRangeGivenLateral; d the unit direction from sensor to point): the
// far end of the wedge's volume. A zero-length ray is not moved.
[[nodiscard]] Eigen::Vector3d ExtendedPointMean(const RayModel& ray, double sigmas = 3.0);

// OK iff num_rays is in [1, 4] and every value of its rays is finite; InvalidArgument naming
// the ray and the field otherwise.
[[nodiscard]] absl::Status ValidateWedge(const Wedge& wedge);

// Whether x satisfies every half-space of the hull (and lies in its box).
[[nodiscard]] bool HullContainsPoint(const WedgeHull& hull, const Eigen::Vector3d& x);

}  // namespace carvemap

// Planar regions of the octree's boundary faces (seed §4.2.4, §4.3.3; DESIGN §6 stage 2):
// flood fill of connected faces with the same direction, PCA region growing with the
// grid-size tolerance, then relaxation that merges adjacent regions whose planes are within
// 15°. Planes are fitted by PCA on the faces' isosurface positions (Fig 4.9), weighted by area.
//
// A global stage: it takes the faces of the whole octree (or of one level).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "services/geometry/octree_keys.h"
#include "services/mesh/boundary_faces.h"

namespace carvemap {

struct PlanarRegionOptions {
  // §4.2.4: a face joins a region when its isosurface point lies within this distance of the
  // region's plane. 0 = the grid resolution ("grid-size tolerance").
  double distance_tolerance_m = 0;
  // §4.2.4: relaxation merges adjacent regions whose normals differ by less than this.
  double merge_angle_deg = 15.0;
};

struct PlanarRegion {
  int id = 0;                     // index in PlanarRegionSet::regions
  Eigen::Vector3d normal;         // unit; oriented like its faces (into free space)
  Eigen::Vector3d centroid;       // area-weighted mean of the faces' isosurface points, m
  double area_m2 = 0;             // Σ face areas
  std::vector<uint32_t> faces;    // indices into the face list given to FitPlanarRegions
  // PCA eigenvalues of the face points (ascending; λ0 = spread off the plane), m².
  Eigen::Vector3d eigenvalues = Eigen::Vector3d::Zero();
};

struct PlanarRegionSet {
  std::vector<PlanarRegion> regions;  // deterministic order (by smallest face index)
  std::vector<int> face_region;       // per input face: its region id
};

// Errors: InvalidArgument for negative tolerances or a merge angle outside [0, 90].
[[nodiscard]] absl::StatusOr<PlanarRegionSet> FitPlanarRegions(std::span<const BoundaryFace> faces,
                                                              const OctreeGrid& grid,
                                                              const PlanarRegionOptions& options);

}  // namespace carvemap

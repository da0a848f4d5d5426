// Boundary faces of a voxelised free space for tests of the planar stages: what
// ChunkBoundaryFaces reports for finest leaves, without carving.
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "services/mesh/boundary_faces.h"

namespace carvemap {

// A signed distance-like function: > 0 in free space (interior, p > 0.5), ≤ 0 in solid.
using Field = std::function<double(const Eigen::Vector3d&)>;

// The boundary faces of a voxelised free space, as ChunkBoundaryFaces would report them for
// finest leaves: every pair of axis neighbours in the cell box [lo, hi) with one free and one
// solid cell gives a face; its isosurface point (Fig 4.9) is where `field`, linearly
// interpolated between the two cell centres, crosses 0. `jitter_cells` moves it along the
// axis by a uniform random amount (noise), seeded.
inline std::vector<BoundaryFace> VoxelFaces(double res, const Eigen::Vector3i& lo,
                                            const Eigen::Vector3i& hi, const Field& field,
                                            double jitter_cells = 0, uint32_t seed = 1) {
  using Eigen::Vector3d;
  using Eigen::Vector3i;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  auto center = [&](const Vector3i& c) {
    return (c.cast<double>() + Vector3d::Constant(0.5)) * res;
  };
  std::vector<BoundaryFace> faces;
  for (int x = lo.x(); x < hi.x(); ++x) {
    for (int y = lo.y(); y < hi.y(); ++y) {
      for (int z = lo.z(); z < hi.z(); ++z) {
        const Vector3i a(x, y, z);
        const double fa = field(center(a));
        for (int axis = 0; axis < 3; ++axis) {
          Vector3i b = a;
          b[axis] += 1;
          if (b[axis] >= hi[axis]) continue;
          const double fb = field(center(b));
          if ((fa > 0) == (fb > 0)) continue;
          const Vector3i& free_c = fa > 0 ? a : b;
          const Vector3i& solid_c = fa > 0 ? b : a;
          const double f_free = fa > 0 ? fa : fb;
          const double f_solid = fa > 0 ? fb : fa;
          BoundaryFace f;
          f.axis = static_cast<int8_t>(axis);
          f.sign = free_c[axis] > solid_c[axis] ? 1 : -1;
          f.size_m = res;
          f.center = 0.5 * (center(a) + center(b));
          const double t = std::clamp(f_solid / (f_solid - f_free), 0.0, 1.0);
          // The two cells differ along `axis` only.
          f.isosurface_m = (center(solid_c) + t * (center(free_c) - center(solid_c)))[axis];
          if (jitter_cells > 0) f.isosurface_m += jitter_cells * res * u(rng);
          faces.push_back(f);
        }
      }
    }
  }
  return faces;
}

}  // namespace carvemap

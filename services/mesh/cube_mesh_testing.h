// A closed cube mesh for the tests of mesh checks.
#pragma once

#include <Eigen/Core>

#include "storage/ply_io.h"

namespace carvemap::testing {

// A cube of side `s` at `origin` as 12 outward-facing triangles, appended to `m`.
inline void AddCube(TriangleMesh& m, const Eigen::Vector3f& origin, float s) {
  TriangleMesh c;
  for (int i = 0; i < 8; ++i) {
    c.vertices.push_back(origin + s * Eigen::Vector3f(i & 1, (i >> 1) & 1, (i >> 2) & 1));
  }
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    c.triangles.emplace_back(q[0], q[1], q[2]);
    c.triangles.emplace_back(q[0], q[2], q[3]);
  }
  m.Append(c);
}

}  // namespace carvemap::testing

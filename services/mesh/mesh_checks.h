// Structural checks of triangle meshes (watertight: every edge shared by exactly two
// faces, no degenerate or duplicate faces). Used by tests and by the merge's summary.
#pragma once

#include <cstdint>
#include <string>

#include "storage/ply_io.h"

namespace carvemap {

struct MeshCheck {
  uint64_t triangles = 0;
  uint64_t edges = 0;                 // undirected edges
  uint64_t boundary_edges = 0;        // used by one triangle
  uint64_t nonmanifold_edges = 0;     // used by three or more triangles
  uint64_t misoriented_edges = 0;     // two triangles traverse it in the same direction
  uint64_t degenerate_triangles = 0;  // repeated index or zero area (< area_epsilon)
  uint64_t duplicate_triangles = 0;   // same three vertices as an earlier triangle
  uint64_t bad_indices = 0;           // index outside the vertex list
  // Watertight: every edge shared by exactly two triangles, consistently
  // oriented, none degenerate or duplicate.
  [[nodiscard]] bool watertight() const {
    return boundary_edges == 0 && nonmanifold_edges == 0 && misoriented_edges == 0 &&
           degenerate_triangles == 0 && duplicate_triangles == 0 && bad_indices == 0;
  }
  [[nodiscard]] std::string ToString() const;
};

// Vertices are compared by index (callers weld equal positions first).
[[nodiscard]] MeshCheck CheckMesh(const TriangleMesh& mesh, double area_epsilon_m2 = 1e-12);

}  // namespace carvemap

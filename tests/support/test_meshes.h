// Small meshes and file helpers the tests of mesh writers share (PLY, GLB, the objects' files).
#pragma once

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <Eigen/Core>

#include "storage/ply_io.h"

namespace carvemap::testing {

// A closed tetrahedron with its right-angle corner at `at` and legs `size` m along +x, +y,
// +z, counter-clockwise seen from outside.
inline TriangleMesh Tetrahedron(const Eigen::Vector3f& at, float size) {
  TriangleMesh m;
  m.vertices = {at, at + Eigen::Vector3f(size, 0, 0), at + Eigen::Vector3f(0, size, 0),
                at + Eigen::Vector3f(0, 0, size)};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return m;
}

// A file's bytes ("" when it cannot be read).
inline std::string ReadFileBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace carvemap::testing

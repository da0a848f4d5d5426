// Triangle meshes as binary little-endian PLY (DESIGN §7): `vertex` float x y z and
// `face` list uchar int vertex_indices, optionally one extra int property per face.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace carvemap {

struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Eigen::Vector3i> triangles;  // counter-clockwise seen from outside

  // Appends `other`, offsetting its indices.
  void Append(const TriangleMesh& other);
};

// Writes `mesh` to `path` (through "<path>.partial" and a rename). If `face_values` is set it
// holds one value per triangle, written as face property `int <face_property>`.
absl::Status WritePly(const std::string& path, const TriangleMesh& mesh,
                      const std::vector<int>* face_values = nullptr,
                      const std::string& face_property = "label");

}  // namespace carvemap

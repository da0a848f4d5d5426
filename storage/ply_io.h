// Triangle meshes as binary little-endian PLY (docs/DESIGN.md §7): `vertex` float x y z and
// `face` list uchar int vertex_indices, optionally one extra int property per face.
#pragma once

#include <optional>
#include <span>
#include <string>
#include <utility>
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

// One mesh of several written as one PLY (WritePlyParts); its triangles carry `face_value`.
struct PlyPart {
  const TriangleMesh* mesh = nullptr;
  int face_value = 0;
};

// The same bytes as WritePly of the parts appended in order (TriangleMesh::Append), each
// part's triangles with its face_value, without making that mesh: a large building's objects
// are hundreds of MB, and objects.ply and combined.ply are each all of them.
absl::Status WritePlyParts(const std::string& path, std::span<const PlyPart> parts,
                           const std::string& face_property);

// A mesh read back from PLY, with its integer face properties by name.
struct PlyMesh {
  TriangleMesh mesh;                                      // polygons fanned into triangles
  std::vector<std::pair<std::string, std::vector<int>>> face_values;  // one value per triangle
};

// Reads binary little-endian PLY as WritePly writes it and as docs/DESIGN.md §7 specifies: vertex
// properties of which the first three are float x y z (more scalar properties are skipped),
// faces as a `list uchar int` (polygons are fanned into triangles) followed by scalar
// properties, of which the int/uint/short/ushort/char/uchar ones are returned. Errors name the
// file: NotFound, or DataLoss for an unsupported header, an index out of range or a
// truncated body.
absl::StatusOr<PlyMesh> ReadPly(const std::string& path);

}  // namespace carvemap

// Triangle meshes as binary little-endian PLY (docs/DESIGN.md §7): `vertex` float x y z and
// `face` list uchar int vertex_indices, optionally one extra int property per face.
#pragma once

#include <cstdint>
#include <fstream>
#include <memory>
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

// WritePly for a mesh that comes a piece at a time, in its final order (vertices, and
// triangles with their final indices), and is never held whole: the pieces go to two files
// beside `path` ("<path>.vertices.partial", "<path>.faces.partial"), joined under the header
// into `path` by Finish (through "<path>.partial" and a rename). The bytes are WritePly's of
// the whole mesh; with a `face_property`, each triangle carries the int value given with it
// (WritePly's with face values, for meshes added one after another with AddMesh). The temporaries
// are removed by Finish or by the destructor; a writer not finished leaves nothing under `path`.
// Errors name the file: PermissionDenied when a file cannot be opened, DataLoss when a write fails
// (with the system's reason).
class PlyStreamWriter {
 public:
  [[nodiscard]] static absl::StatusOr<std::unique_ptr<PlyStreamWriter>> Create(
      const std::string& path, const std::string& face_property = "");
  ~PlyStreamWriter();
  PlyStreamWriter(const PlyStreamWriter&) = delete;
  PlyStreamWriter& operator=(const PlyStreamWriter&) = delete;

  [[nodiscard]] absl::Status AddVertices(std::span<const Eigen::Vector3f> vertices);
  // `face_value` is written only with a face property.
  [[nodiscard]] absl::Status AddTriangles(std::span<const Eigen::Vector3i> triangles,
                                          int face_value = 0);
  // A whole mesh after the ones before it: its vertices, then its triangles offset by the
  // vertices given before it.
  [[nodiscard]] absl::Status AddMesh(const TriangleMesh& mesh, int face_value = 0);
  [[nodiscard]] absl::Status Finish();
  [[nodiscard]] uint64_t vertices() const { return vertices_; }
  [[nodiscard]] uint64_t triangles() const { return triangles_; }

 private:
  PlyStreamWriter(std::string path, std::string face_property);
  std::string path_, face_property_;
  std::ofstream vertex_out_, face_out_;
  uint64_t vertices_ = 0, triangles_ = 0;
  bool finished_ = false;
};

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

#include "storage/ply_io.h"

#include <bit>
#include <ostream>

#include "absl/strings/str_cat.h"
#include "storage/atomic_file.h"

namespace carvemap {

void TriangleMesh::Append(const TriangleMesh& other) {
  const int offset = static_cast<int>(vertices.size());
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  triangles.reserve(triangles.size() + other.triangles.size());
  for (const Eigen::Vector3i& t : other.triangles) triangles.push_back(t.array() + offset);
}

absl::Status WritePly(const std::string& path, const TriangleMesh& mesh,
                      const std::vector<int>* face_values, const std::string& face_property) {
  static_assert(std::endian::native == std::endian::little, "PLY writer assumes little-endian");
  if (face_values && face_values->size() != mesh.triangles.size()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", face_values->size(),
                                                   " face values for ", mesh.triangles.size(),
                                                   " triangles"));
  }
  return WriteFileAtomically(path, [&](std::ostream& out) {
    out << "ply\nformat binary_little_endian 1.0\ncomment carvemap\n"
        << "element vertex " << mesh.vertices.size() << "\n"
        << "property float x\nproperty float y\nproperty float z\n"
        << "element face " << mesh.triangles.size() << "\n"
        << "property list uchar int vertex_indices\n";
    if (face_values) out << "property int " << face_property << "\n";
    out << "end_header\n";
    for (const Eigen::Vector3f& v : mesh.vertices) {
      out.write(reinterpret_cast<const char*>(v.data()), 3 * sizeof(float));
    }
    const unsigned char three = 3;
    for (size_t i = 0; i < mesh.triangles.size(); ++i) {
      out.write(reinterpret_cast<const char*>(&three), 1);
      out.write(reinterpret_cast<const char*>(mesh.triangles[i].data()), 3 * sizeof(int));
      if (face_values) out.write(reinterpret_cast<const char*>(&(*face_values)[i]), sizeof(int));
    }
  });
}

}  // namespace carvemap

// Triangle meshes as PLY (storage/ply_io.h ReadPly: truth meshes, merge outputs read back).
// Any bytes give a mesh or an error naming the file; every index of an accepted mesh is in
// range, and face values come one per triangle.
#include <cstddef>
#include <cstdint>

#include "storage/ply_io.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  const std::string path = fuzz::WriteInput("mesh.ply", data, size);
  absl::StatusOr<PlyMesh> ply = ReadPly(path);
  if (!ply.ok()) {
    fuzz::RequireNamesFile(ply.status(), path);
    return 0;
  }
  fuzz::Trace(absl::OkStatus());
  const int n = static_cast<int>(ply->mesh.vertices.size());
  for (const Eigen::Vector3i& t : ply->mesh.triangles) {
    fuzz::Require((t.array() >= 0).all() && (t.array() < n).all(), "indices in range");
  }
  for (const auto& [name, values] : ply->face_values) {
    fuzz::Require(values.size() == ply->mesh.triangles.size(), "one face value per triangle");
  }
  return 0;
}

// Triangle meshes as one binary glTF 2.0 file (.glb; docs/DESIGN.md §7 mesh/model.glb): a tree
// of named nodes, each with at most one mesh, coloured by materials, for viewers and the web
// (three.js, Blender, any glTF viewer).
//
// Ours, not libtinygltf's writer: tinygltf builds the whole model in memory, buffers and all,
// and a building's objects are millions of triangles (office4 at 10 Hz: 19.5 M, ~350 MB of
// buffers), while the merge holds an object at a time. Here each mesh's bytes go to a scratch
// file as it is added, and only the JSON's entries are held; Finish writes the GLB (header,
// JSON chunk, BIN chunk) through "<path>.partial" and a rename. The tests read the files back
// with libtinygltf (Debian's), an independent reader.
//
// Layout: vertices in our frame (metres, z up) as float32 POSITION, triangles as uint32
// indices; no normals (viewers make flat ones, as glTF 2.0 §3.7.2.1 asks). The root node turns
// z-up into glTF's y-up (a −90° rotation about x), so that the files open upright.
#pragma once

#include <array>
#include <cstdint>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "storage/ply_io.h"

namespace carvemap {

class GlbStreamWriter {
 public:
  // Errors: PermissionDenied naming the file when its scratch file cannot be created.
  [[nodiscard]] static absl::StatusOr<std::unique_ptr<GlbStreamWriter>> Create(
      const std::string& path);
  ~GlbStreamWriter();
  GlbStreamWriter(const GlbStreamWriter&) = delete;
  GlbStreamWriter& operator=(const GlbStreamWriter&) = delete;

  // A metallic-roughness material of one colour (linear RGBA in [0, 1]); alpha < 1 blends.
  // Returns its index.
  int AddMaterial(const std::string& name, const std::array<float, 4>& rgba, bool double_sided);

  // A node under `parent` (−1: the root) with `mesh` (none when empty) drawn with `material`,
  // and `extras` (a JSON object, or null) for the application. Returns the node's index, to
  // be a parent. Errors: InvalidArgument for an unknown parent or material, or a triangle
  // naming a vertex the mesh lacks; DataLoss naming the file when the scratch file cannot be
  // written.
  [[nodiscard]] absl::StatusOr<int> AddNode(const std::string& name, int parent,
                                            const TriangleMesh& mesh, int material,
                                            const nlohmann::json& extras = nullptr);

  // Writes the file. Errors: DataLoss naming the file; InvalidArgument when the buffer would
  // pass the GLB's 4 GiB limit.
  [[nodiscard]] absl::Status Finish();

  [[nodiscard]] uint64_t buffer_bytes() const { return bin_bytes_; }

 private:
  explicit GlbStreamWriter(std::string path) : path_(std::move(path)) {}
  absl::Status AppendView(const void* data, uint64_t bytes, int target, int* view);

  std::string path_;
  std::ofstream bin_;
  uint64_t bin_bytes_ = 0;
  bool finished_ = false;
  nlohmann::json nodes_ = nlohmann::json::array();
  nlohmann::json meshes_ = nlohmann::json::array();
  nlohmann::json accessors_ = nlohmann::json::array();
  nlohmann::json views_ = nlohmann::json::array();
  nlohmann::json materials_ = nlohmann::json::array();
};

}  // namespace carvemap

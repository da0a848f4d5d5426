// The objects' meshes on their way from the stream that finds them (ObjectSplitter, §5.6.2)
// to their files (docs/DESIGN.md §7: mesh/objects/<id>.ply, mesh/objects.ply,
// mesh/combined.ply), without holding them all: a large building's objects are millions of
// triangles (office4 at 10 Hz: 19.5 M, ~1 GB as meshes), and the objects are known, grouped
// and numbered only once the whole mesh has streamed past. So each kept piece's mesh goes to a
// scratch file as the stream finishes it, and the files are written afterwards an object at a
// time, read back by its pieces' keys.
//
// Scratch, not an output: the file lives in the merge's hidden scratch folder and is removed
// by the destructor; no fsync.
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/status/statusor.h"
#include "services/merge/dense_mesh.h"
#include "services/mesh/self_intersections.h"
#include "services/segment/object_meshes.h"
#include "storage/ply_io.h"

namespace carvemap {

// Pieces' meshes by key, appended as they come (one thread), read back by any number of
// threads after FinishWriting.
class ObjectPieceFile {
 public:
  // Errors: Unavailable when `path` cannot be created (its folder must exist).
  [[nodiscard]] static absl::StatusOr<std::unique_ptr<ObjectPieceFile>> Create(std::string path);
  ~ObjectPieceFile();
  ObjectPieceFile(const ObjectPieceFile&) = delete;
  ObjectPieceFile& operator=(const ObjectPieceFile&) = delete;

  // Before FinishWriting. Errors: InvalidArgument for a key added twice; DataLoss naming the
  // file when it cannot be written.
  [[nodiscard]] absl::Status Add(uint64_t key, const TriangleMesh& mesh);
  [[nodiscard]] absl::Status FinishWriting();
  // The meshes of `keys` appended in that order (an object's mesh from its pieces'). Errors:
  // NotFound for a key never added; DataLoss naming the file when it cannot be read whole.
  [[nodiscard]] absl::StatusOr<TriangleMesh> Read(std::span<const uint64_t> keys) const;

  [[nodiscard]] uint64_t bytes() const { return bytes_; }

 private:
  struct Entry {
    uint64_t offset = 0;
    uint32_t vertices = 0, triangles = 0;
  };
  explicit ObjectPieceFile(std::string path) : path_(std::move(path)) {}

  std::string path_;
  std::ofstream out_;
  uint64_t bytes_ = 0;
  bool finished_ = false;
  absl::flat_hash_map<uint64_t, Entry> entries_;
};

struct ObjectFilesResult {
  // Per object of the layout, in its order.
  std::vector<uint64_t> triangles;
  std::vector<SelfIntersections> crossings;
};

// Writes mesh/objects/<id>.ply for each object of `layout` (its pieces read from `pieces`),
// counts each one's self-intersections (each object on its own: objects that touch one another
// are separate models), and streams them, in id order, into mesh/objects.ply and, after
// `building` (face value −1), mesh/combined.ply (face property `object`). Objects are read,
// written and checked on `threads` threads a batch at a time; memory is a batch of objects.
// `progress` (objects done, objects) may cancel; `also`, when set, gets each object with its
// mesh, in id order, after the joined files (mesh/model.glb). `out` is the output folder, with
// mesh/ in it. Errors name the file, or are `also`'s; Cancelled when `progress` says so.
using ObjectMeshFn = std::function<absl::Status(const SegmentedObject&, const TriangleMesh&)>;
[[nodiscard]] absl::StatusOr<ObjectFilesResult> WriteObjectFiles(
    const ObjectLayout& layout, const ObjectPieceFile& pieces, const TriangleMesh& building,
    const std::filesystem::path& out, int threads, const ChunkProgressFn& progress = nullptr,
    const ObjectMeshFn& also = nullptr);

}  // namespace carvemap

#include "services/merge/object_files.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <limits>
#include <system_error>
#include <utility>

#include "absl/strings/str_cat.h"
#include "services/merge/parallel_for.h"
#include "storage/atomic_file.h"

namespace carvemap {

namespace fs = std::filesystem;

absl::StatusOr<std::unique_ptr<ObjectPieceFile>> ObjectPieceFile::Create(std::string path) {
  std::unique_ptr<ObjectPieceFile> f(new ObjectPieceFile(std::move(path)));
  f->out_.open(f->path_, std::ios::binary | std::ios::trunc);
  if (!f->out_) {
    return absl::UnavailableError(absl::StrCat(
        f->path_, ": cannot create the objects' scratch file: ", std::strerror(errno)));
  }
  return f;
}

ObjectPieceFile::~ObjectPieceFile() {
  out_.close();
  std::error_code ec;
  fs::remove(path_, ec);
}

absl::Status ObjectPieceFile::Add(uint64_t key, const TriangleMesh& mesh) {
  static_assert(sizeof(Eigen::Vector3f) == 12 && sizeof(Eigen::Vector3i) == 12);
  if (finished_) return absl::FailedPreconditionError(absl::StrCat(path_, ": already finished"));
  if (mesh.vertices.size() > std::numeric_limits<uint32_t>::max() ||
      mesh.triangles.size() > std::numeric_limits<uint32_t>::max()) {
    return absl::InvalidArgumentError(absl::StrCat(path_, ": piece ", key, " is too large"));
  }
  const Entry entry{bytes_, uint32_t(mesh.vertices.size()), uint32_t(mesh.triangles.size())};
  if (!entries_.emplace(key, entry).second) {
    return absl::InvalidArgumentError(absl::StrCat(path_, ": piece ", key, " added twice"));
  }
  errno = 0;
  out_.write(reinterpret_cast<const char*>(mesh.vertices.data()),
             std::streamsize(12 * mesh.vertices.size()));
  out_.write(reinterpret_cast<const char*>(mesh.triangles.data()),
             std::streamsize(12 * mesh.triangles.size()));
  if (!out_) return StreamWriteError(path_, errno);
  bytes_ += 12 * (mesh.vertices.size() + mesh.triangles.size());
  return absl::OkStatus();
}

absl::Status ObjectPieceFile::FinishWriting() {
  finished_ = true;
  errno = 0;
  out_.close();
  if (!out_) return StreamWriteError(path_, errno);
  return absl::OkStatus();
}

absl::StatusOr<TriangleMesh> ObjectPieceFile::Read(std::span<const uint64_t> keys) const {
  if (!finished_) {
    return absl::FailedPreconditionError(absl::StrCat(path_, ": read before it was finished"));
  }
  std::ifstream in(path_, std::ios::binary);
  if (!in)
    return absl::DataLossError(absl::StrCat(path_, ": cannot open the objects' scratch file"));
  TriangleMesh mesh, piece;
  for (uint64_t key : keys) {
    auto it = entries_.find(key);
    if (it == entries_.end()) {
      return absl::NotFoundError(absl::StrCat(path_, ": no piece ", key));
    }
    const Entry& e = it->second;
    piece.vertices.resize(e.vertices);
    piece.triangles.resize(e.triangles);
    in.seekg(std::streamoff(e.offset));
    in.read(reinterpret_cast<char*>(piece.vertices.data()), std::streamsize(12 * e.vertices));
    in.read(reinterpret_cast<char*>(piece.triangles.data()), std::streamsize(12 * e.triangles));
    if (!in) {
      return absl::DataLossError(absl::StrCat(
          path_, ": the objects' scratch file ends inside piece ", key, " (truncated?)"));
    }
    mesh.Append(piece);
  }
  return mesh;
}

absl::StatusOr<ObjectFilesResult> WriteObjectFiles(
    const ObjectLayout& layout, const ObjectPieceFile& pieces, const TriangleMesh& building,
    const fs::path& out, int threads, const ChunkProgressFn& progress, const ObjectMeshFn& also) {
  const fs::path objects_dir = out / "mesh" / "objects";
  std::error_code ec;
  fs::remove_all(objects_dir, ec);  // an earlier merge's objects are not this one's
  fs::create_directories(objects_dir, ec);
  if (ec) {
    return absl::UnavailableError(
        absl::StrCat(objects_dir.string(), ": cannot create: ", ec.message()));
  }
  absl::StatusOr<std::unique_ptr<PlyStreamWriter>> all =
      PlyStreamWriter::Create((out / "mesh" / "objects.ply").string(), "object");
  if (!all.ok()) return all.status();
  absl::StatusOr<std::unique_ptr<PlyStreamWriter>> combined =
      PlyStreamWriter::Create((out / "mesh" / "combined.ply").string(), "object");
  if (!combined.ok()) return combined.status();
  if (absl::Status s = (*combined)->AddMesh(building, -1); !s.ok()) return s;

  const size_t n = layout.objects.size();
  ObjectFilesResult result;
  result.triangles.resize(n);
  result.crossings.resize(n);
  threads = std::max(threads, 1);
  // A batch of objects at a time on every thread (reading, writing its file and counting its
  // crossings take minutes on a large building), then the batch appended in id order to the
  // joined files.
  const size_t batch = 4 * size_t(threads);
  std::vector<TriangleMesh> meshes(batch);
  std::vector<absl::Status> status(batch);
  for (size_t first = 0; first < n; first += batch) {
    if (progress && !progress(first, n)) {
      return absl::CancelledError("merge cancelled during object_files");
    }
    const size_t count = std::min(batch, n - first);
    ParallelFor(count, threads, [&](size_t i) {
      const size_t id = first + i;
      absl::StatusOr<TriangleMesh> mesh = pieces.Read(layout.pieces[id]);
      if (!mesh.ok()) {
        status[i] = mesh.status();
        return;
      }
      status[i] =
          WritePly((objects_dir / absl::StrCat(layout.objects[id].id, ".ply")).string(), *mesh);
      if (status[i].ok()) result.crossings[id] = CountSelfIntersections(*mesh);
      meshes[i] = *std::move(mesh);
    });
    for (size_t i = 0; i < count; ++i) {
      if (!status[i].ok()) return status[i];
      const int id = layout.objects[first + i].id;
      result.triangles[first + i] = meshes[i].triangles.size();
      if (absl::Status s = (*all)->AddMesh(meshes[i], id); !s.ok()) return s;
      if (absl::Status s = (*combined)->AddMesh(meshes[i], id); !s.ok()) return s;
      if (also) {
        if (absl::Status s = also(layout.objects[first + i], meshes[i]); !s.ok()) return s;
      }
      meshes[i] = TriangleMesh{};
    }
  }
  if (absl::Status s = (*all)->Finish(); !s.ok()) return s;
  if (absl::Status s = (*combined)->Finish(); !s.ok()) return s;
  return result;
}

}  // namespace carvemap

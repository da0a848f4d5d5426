#include "storage/glb_writer.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <filesystem>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "storage/atomic_file.h"

namespace carvemap {
namespace {

// glTF 2.0's codes (its specification, §3.6 and §5).
constexpr int kArrayBuffer = 34962, kElementArrayBuffer = 34963;
constexpr int kFloat = 5126, kUnsignedInt = 5125;
constexpr int kTriangles = 4;
constexpr uint32_t kGlbMagic = 0x46546C67;  // "glTF"
constexpr uint32_t kChunkJson = 0x4E4F534A, kChunkBin = 0x004E4942;

std::string ScratchPath(const std::string& path) { return path + ".bin.partial"; }

void WriteU32(std::ostream& out, uint32_t v) {
  static_assert(std::endian::native == std::endian::little, "GLB writer assumes little-endian");
  out.write(reinterpret_cast<const char*>(&v), 4);
}

}  // namespace

absl::StatusOr<std::unique_ptr<GlbStreamWriter>> GlbStreamWriter::Create(const std::string& path) {
  std::unique_ptr<GlbStreamWriter> w(new GlbStreamWriter(path));
  w->bin_.open(ScratchPath(path), std::ios::binary | std::ios::trunc);
  if (!w->bin_) return absl::PermissionDeniedError(absl::StrCat(path, ": cannot open for writing"));
  // The root: our frame's z up turned to glTF's y up (−90° about x).
  const double h = std::sqrt(0.5);
  w->nodes_.push_back({{"name", "carvemap"}, {"rotation", {-h, 0.0, 0.0, h}}});
  return w;
}

GlbStreamWriter::~GlbStreamWriter() {
  bin_.close();
  std::error_code ec;
  std::filesystem::remove(ScratchPath(path_), ec);
}

int GlbStreamWriter::AddMaterial(const std::string& name, const std::array<float, 4>& rgba,
                                 bool double_sided) {
  nlohmann::json m = {{"name", name},
                      {"pbrMetallicRoughness",
                       {{"baseColorFactor", {rgba[0], rgba[1], rgba[2], rgba[3]}},
                        {"metallicFactor", 0.0},
                        {"roughnessFactor", 0.9}}},
                      {"doubleSided", double_sided}};
  if (rgba[3] < 1) m["alphaMode"] = "BLEND";
  materials_.push_back(std::move(m));
  return static_cast<int>(materials_.size()) - 1;
}

absl::Status GlbStreamWriter::AppendView(const void* data, uint64_t bytes, int target, int* view) {
  errno = 0;
  bin_.write(static_cast<const char*>(data), std::streamsize(bytes));
  if (!bin_) return StreamWriteError(path_, errno);
  views_.push_back(
      {{"buffer", 0}, {"byteOffset", bin_bytes_}, {"byteLength", bytes}, {"target", target}});
  bin_bytes_ += bytes;  // 12-byte vertices and 4-byte indices keep every view 4-aligned
  *view = static_cast<int>(views_.size()) - 1;
  return absl::OkStatus();
}

absl::StatusOr<int> GlbStreamWriter::AddNode(const std::string& name, int parent,
                                             const TriangleMesh& mesh, int material,
                                             const nlohmann::json& extras) {
  if (finished_) return absl::FailedPreconditionError(absl::StrCat(path_, ": already finished"));
  if (parent < -1 || parent >= static_cast<int>(nodes_.size())) {
    return absl::InvalidArgumentError(absl::StrCat(path_, ": node ", name, ": no parent ", parent));
  }
  nlohmann::json node = {{"name", name}};
  if (extras.is_object()) node["extras"] = extras;
  if (!mesh.triangles.empty()) {
    if (material < 0 || material >= static_cast<int>(materials_.size())) {
      return absl::InvalidArgumentError(
          absl::StrCat(path_, ": node ", name, ": no material ", material));
    }
    const int nv = static_cast<int>(mesh.vertices.size());
    Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::infinity());
    Eigen::Vector3f hi = -lo;
    for (const Eigen::Vector3f& v : mesh.vertices) {
      lo = lo.cwiseMin(v);
      hi = hi.cwiseMax(v);
    }
    for (const Eigen::Vector3i& t : mesh.triangles) {
      if (t.minCoeff() < 0 || t.maxCoeff() >= nv) {
        return absl::InvalidArgumentError(
            absl::StrCat(path_, ": node ", name, ": a triangle names a vertex of ", nv));
      }
    }
    int positions = 0, indices = 0;
    if (absl::Status s =
            AppendView(mesh.vertices.data(), 12 * uint64_t(nv), kArrayBuffer, &positions);
        !s.ok()) {
      return s;
    }
    if (absl::Status s = AppendView(mesh.triangles.data(), 12 * uint64_t(mesh.triangles.size()),
                                    kElementArrayBuffer, &indices);
        !s.ok()) {
      return s;
    }
    accessors_.push_back({{"bufferView", positions},
                          {"componentType", kFloat},
                          {"count", nv},
                          {"type", "VEC3"},
                          {"min", {lo.x(), lo.y(), lo.z()}},
                          {"max", {hi.x(), hi.y(), hi.z()}}});
    accessors_.push_back({{"bufferView", indices},
                          {"componentType", kUnsignedInt},
                          {"count", 3 * mesh.triangles.size()},
                          {"type", "SCALAR"}});
    const int a = static_cast<int>(accessors_.size());
    meshes_.push_back({{"name", name},
                       {"primitives",
                        {{{"attributes", {{"POSITION", a - 2}}},
                          {"indices", a - 1},
                          {"material", material},
                          {"mode", kTriangles}}}}});
    node["mesh"] = meshes_.size() - 1;
  }
  nodes_.push_back(std::move(node));
  const int index = static_cast<int>(nodes_.size()) - 1;
  nodes_[parent < 0 ? 0 : parent]["children"].push_back(index);
  return index;
}

absl::Status GlbStreamWriter::Finish() {
  if (finished_) return absl::FailedPreconditionError(absl::StrCat(path_, ": already finished"));
  finished_ = true;
  errno = 0;
  bin_.close();
  if (!bin_) return StreamWriteError(path_, errno);
  nlohmann::json gltf = {{"asset", {{"version", "2.0"}, {"generator", "carvemap"}}},
                         {"scene", 0},
                         {"scenes", {{{"nodes", {0}}}}},
                         {"nodes", nodes_}};
  // glTF's arrays, when present, hold at least one element.
  if (!meshes_.empty()) gltf["meshes"] = meshes_;
  if (!accessors_.empty()) gltf["accessors"] = accessors_;
  if (!views_.empty()) gltf["bufferViews"] = views_;
  if (!materials_.empty()) gltf["materials"] = materials_;
  if (bin_bytes_ > 0) gltf["buffers"] = {{{"byteLength", bin_bytes_}}};
  std::string json = gltf.dump();
  json.resize((json.size() + 3) / 4 * 4, ' ');  // chunks are 4-aligned; JSON pads with spaces
  const uint64_t bin_padded = (bin_bytes_ + 3) / 4 * 4;
  const uint64_t total = 12 + 8 + json.size() + (bin_bytes_ > 0 ? 8 + bin_padded : 0);
  if (total > std::numeric_limits<uint32_t>::max()) {
    return absl::InvalidArgumentError(
        absl::StrCat(path_, ": ", total, " bytes pass the GLB format's 4 GiB limit"));
  }
  const absl::Status written = WriteFileAtomically(path_, [&](std::ostream& out) {
    WriteU32(out, kGlbMagic);
    WriteU32(out, 2);
    WriteU32(out, uint32_t(total));
    WriteU32(out, uint32_t(json.size()));
    WriteU32(out, kChunkJson);
    out << json;
    if (bin_bytes_ == 0) return;
    WriteU32(out, uint32_t(bin_padded));
    WriteU32(out, kChunkBin);
    std::ifstream in(ScratchPath(path_), std::ios::binary);
    std::vector<char> buffer(size_t{1} << 20);
    uint64_t copied = 0;
    while (in && copied < bin_bytes_) {
      in.read(buffer.data(),
              std::streamsize(std::min<uint64_t>(buffer.size(), bin_bytes_ - copied)));
      out.write(buffer.data(), in.gcount());
      copied += uint64_t(in.gcount());
    }
    if (copied != bin_bytes_) out.setstate(std::ios::badbit);
    const char zeros[3] = {0, 0, 0};
    out.write(zeros, std::streamsize(bin_padded - bin_bytes_));
  });
  std::error_code ec;
  std::filesystem::remove(ScratchPath(path_), ec);
  return written;
}

}  // namespace carvemap

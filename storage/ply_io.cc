#include "storage/ply_io.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <ostream>
#include <sstream>
#include <system_error>
#include <utility>

#include "absl/strings/str_cat.h"
#include "storage/atomic_file.h"

namespace carvemap {

void TriangleMesh::Append(const TriangleMesh& other) {
  const int offset = static_cast<int>(vertices.size());
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  // Geometric growth, as insert gives the vertices: reserving the exact size on every call made
  // an object of many pieces, appended one by one, quadratic.
  if (const size_t need = triangles.size() + other.triangles.size(); need > triangles.capacity()) {
    triangles.reserve(std::max(need, 2 * triangles.capacity()));
  }
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

PlyStreamWriter::PlyStreamWriter(std::string path, std::string face_property)
    : path_(std::move(path)), face_property_(std::move(face_property)) {}

absl::StatusOr<std::unique_ptr<PlyStreamWriter>> PlyStreamWriter::Create(
    const std::string& path, const std::string& face_property) {
  std::unique_ptr<PlyStreamWriter> w(new PlyStreamWriter(path, face_property));
  w->vertex_out_.open(path + ".vertices.partial", std::ios::binary | std::ios::trunc);
  w->face_out_.open(path + ".faces.partial", std::ios::binary | std::ios::trunc);
  if (!w->vertex_out_ || !w->face_out_) {
    return absl::PermissionDeniedError(absl::StrCat(path, ": cannot open for writing"));
  }
  return w;
}

PlyStreamWriter::~PlyStreamWriter() {
  vertex_out_.close();
  face_out_.close();
  std::error_code ec;
  std::filesystem::remove(path_ + ".vertices.partial", ec);
  std::filesystem::remove(path_ + ".faces.partial", ec);
}

absl::Status PlyStreamWriter::AddVertices(std::span<const Eigen::Vector3f> vertices) {
  static_assert(std::endian::native == std::endian::little, "PLY writer assumes little-endian");
  errno = 0;
  for (const Eigen::Vector3f& v : vertices) {
    vertex_out_.write(reinterpret_cast<const char*>(v.data()), 3 * sizeof(float));
  }
  if (!vertex_out_) return StreamWriteError(path_, errno);
  vertices_ += vertices.size();
  if (vertices_ > uint64_t(std::numeric_limits<int>::max())) {
    return absl::InvalidArgumentError(
        absl::StrCat(path_, ": ", vertices_, " vertices do not fit PLY's int indices"));
  }
  return absl::OkStatus();
}

absl::Status PlyStreamWriter::AddTriangles(std::span<const Eigen::Vector3i> triangles,
                                           int face_value) {
  errno = 0;
  const unsigned char three = 3;
  for (const Eigen::Vector3i& t : triangles) {
    face_out_.write(reinterpret_cast<const char*>(&three), 1);
    face_out_.write(reinterpret_cast<const char*>(t.data()), 3 * sizeof(int));
    if (!face_property_.empty()) {
      face_out_.write(reinterpret_cast<const char*>(&face_value), sizeof(int));
    }
  }
  if (!face_out_) return StreamWriteError(path_, errno);
  triangles_ += triangles.size();
  return absl::OkStatus();
}

absl::Status PlyStreamWriter::AddMesh(const TriangleMesh& mesh, int face_value) {
  const int offset = static_cast<int>(vertices_);
  if (absl::Status s = AddVertices(mesh.vertices); !s.ok()) return s;
  std::vector<Eigen::Vector3i> shifted;
  shifted.reserve(mesh.triangles.size());
  for (const Eigen::Vector3i& t : mesh.triangles) shifted.push_back(t.array() + offset);
  return AddTriangles(shifted, face_value);
}

absl::Status PlyStreamWriter::Finish() {
  if (finished_) return absl::FailedPreconditionError(absl::StrCat(path_, ": already finished"));
  finished_ = true;
  errno = 0;
  vertex_out_.close();
  face_out_.close();
  if (!vertex_out_ || !face_out_) return StreamWriteError(path_, errno);
  // The parts copied under the header a buffer at a time.
  return WriteFileAtomically(path_, [&](std::ostream& out) {
    out << "ply\nformat binary_little_endian 1.0\ncomment carvemap\n"
        << "element vertex " << vertices_ << "\n"
        << "property float x\nproperty float y\nproperty float z\n"
        << "element face " << triangles_ << "\n"
        << "property list uchar int vertex_indices\n";
    if (!face_property_.empty()) out << "property int " << face_property_ << "\n";
    out << "end_header\n";
    std::vector<char> buffer(size_t{1} << 20);
    for (const char* part : {".vertices.partial", ".faces.partial"}) {
      std::ifstream in(path_ + part, std::ios::binary);
      if (!in) {
        out.setstate(std::ios::badbit);
        return;
      }
      while (in) {
        in.read(buffer.data(), std::streamsize(buffer.size()));
        out.write(buffer.data(), in.gcount());
      }
    }
  });
}

namespace {

int ScalarBytes(const std::string& type) {
  if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "float" || type == "int32" ||
      type == "uint32" || type == "float32") {
    return 4;
  }
  if (type == "double" || type == "float64") return 8;
  return 0;
}

// A little-endian scalar of `type` from `p` as an int (floats truncated; only ints are used).
int ScalarAsInt(const std::string& type, const char* p) {
  if (type == "char" || type == "int8") return static_cast<int8_t>(p[0]);
  if (type == "uchar" || type == "uint8") return static_cast<uint8_t>(p[0]);
  if (type == "short" || type == "int16") { int16_t v; std::memcpy(&v, p, 2); return v; }
  if (type == "ushort" || type == "uint16") { uint16_t v; std::memcpy(&v, p, 2); return v; }
  int32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

bool IsIntType(const std::string& type) {
  return type != "float" && type != "float32" && type != "double" && type != "float64";
}

}  // namespace

absl::StatusOr<PlyMesh> ReadPly(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  auto bad = [&path](const std::string& why) {
    return absl::DataLossError(absl::StrCat(path, ": ", why));
  };
  std::string line;
  if (!std::getline(in, line) || line != "ply") return bad("not a PLY file");
  std::string element;
  size_t num_vertices = 0, num_faces = 0;
  std::vector<std::string> vertex_props, vertex_names;
  std::vector<std::string> face_props, face_names;  // after the index list
  bool have_list = false, binary_le = false;
  while (std::getline(in, line) && line != "end_header") {
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    if (word == "format") {
      std::string fmt;
      ls >> fmt;
      binary_le = fmt == "binary_little_endian";
    } else if (word == "element") {
      size_t count = 0;
      if (!(ls >> element >> count)) return bad("bad element line '" + line + "'");
      if (element == "vertex") num_vertices = count;
      else if (element == "face") num_faces = count;
      else return bad("unsupported element '" + element + "'");
    } else if (word == "property") {
      std::string type;
      ls >> type;
      if (type == "list") {
        std::string count_type, index_type, name;
        ls >> count_type >> index_type >> name;
        if (element != "face" || have_list || count_type != "uchar" ||
            (index_type != "int" && index_type != "int32")) {
          return bad("unsupported list property '" + line + "'");
        }
        have_list = true;
        continue;
      }
      std::string name;
      ls >> name;
      if (ScalarBytes(type) == 0) return bad("unsupported property type '" + type + "'");
      if (element == "vertex") {
        vertex_props.push_back(type);
        vertex_names.push_back(name);
      } else if (element == "face") {
        if (!have_list) return bad("face properties before vertex_indices are not supported");
        face_props.push_back(type);
        face_names.push_back(name);
      }
    }
  }
  if (line != "end_header") return bad("no end_header");
  if (!binary_le) return bad("only binary_little_endian PLY is supported");
  if (vertex_props.size() < 3 || vertex_names[0] != "x" || vertex_names[1] != "y" ||
      vertex_names[2] != "z" || vertex_props[0] != "float" || vertex_props[1] != "float" ||
      vertex_props[2] != "float") {
    return bad("vertices must start with float x, y, z");
  }
  if (num_faces > 0 && !have_list) return bad("faces without vertex_indices");

  size_t vertex_bytes = 0;
  for (const std::string& t : vertex_props) vertex_bytes += ScalarBytes(t);
  // The count comes from the file: bound it by the bytes that follow before allocating.
  const std::streampos body = in.tellg();
  in.seekg(0, std::ios::end);
  const std::streamoff body_bytes = in.tellg() - body;
  in.seekg(body);
  if (!in || num_vertices > static_cast<size_t>(body_bytes) / vertex_bytes) {
    return bad(absl::StrCat("header declares ", num_vertices, " vertices of ", vertex_bytes,
                            " bytes but only ", body_bytes, " bytes follow (truncated?)"));
  }
  PlyMesh out;
  out.mesh.vertices.resize(num_vertices);
  std::vector<char> buf(std::max<size_t>(vertex_bytes, 8));
  for (size_t i = 0; i < num_vertices; ++i) {
    if (!in.read(buf.data(), static_cast<std::streamsize>(vertex_bytes))) {
      return bad(absl::StrCat("truncated at vertex ", i, " of ", num_vertices));
    }
    std::memcpy(out.mesh.vertices[i].data(), buf.data(), 3 * sizeof(float));
  }
  std::vector<size_t> kept;  // face property indices returned
  for (size_t p = 0; p < face_props.size(); ++p) {
    if (IsIntType(face_props[p])) {
      kept.push_back(p);
      out.face_values.emplace_back(face_names[p], std::vector<int>{});
    }
  }
  std::vector<int> idx;
  for (size_t f = 0; f < num_faces; ++f) {
    unsigned char count = 0;
    if (!in.read(reinterpret_cast<char*>(&count), 1)) {
      return bad(absl::StrCat("truncated at face ", f, " of ", num_faces));
    }
    idx.resize(count);
    if (!in.read(reinterpret_cast<char*>(idx.data()), 4 * std::streamsize(count))) {
      return bad(absl::StrCat("truncated at face ", f, " of ", num_faces));
    }
    for (int v : idx) {
      if (v < 0 || static_cast<size_t>(v) >= num_vertices) {
        return bad(absl::StrCat("face ", f, " has vertex index ", v, " (", num_vertices,
                                " vertices)"));
      }
    }
    std::vector<int> values(face_props.size(), 0);
    for (size_t p = 0; p < face_props.size(); ++p) {
      const int bytes = ScalarBytes(face_props[p]);
      if (!in.read(buf.data(), bytes)) return bad(absl::StrCat("truncated at face ", f));
      values[p] = ScalarAsInt(face_props[p], buf.data());
    }
    for (int j = 1; j + 1 < count; ++j) {
      out.mesh.triangles.emplace_back(idx[0], idx[j], idx[j + 1]);
      for (size_t k = 0; k < kept.size(); ++k) out.face_values[k].second.push_back(values[kept[k]]);
    }
  }
  return out;
}

}  // namespace carvemap

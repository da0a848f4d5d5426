#include "storage/ply_io.h"

#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(PlyIoTest, WritesDesignSevenLayoutExactly) {
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 2}};
  const std::string path = testing::TempDir() + "/tri.ply";
  ASSERT_TRUE(WritePly(path, mesh).ok());
  EXPECT_FALSE(std::filesystem::exists(path + ".partial"));
  const std::string data = ReadAll(path);
  const std::string header =
      "ply\nformat binary_little_endian 1.0\ncomment carvemap\nelement vertex 3\n"
      "property float x\nproperty float y\nproperty float z\nelement face 1\n"
      "property list uchar int vertex_indices\nend_header\n";
  ASSERT_EQ(data.substr(0, header.size()), header);
  ASSERT_EQ(data.size(), header.size() + 3 * 12 + 1 + 12);
  float x1;
  std::memcpy(&x1, data.data() + header.size() + 12, 4);
  EXPECT_EQ(x1, 1.0f);
  EXPECT_EQ(static_cast<unsigned char>(data[header.size() + 36]), 3);
  int i2;
  std::memcpy(&i2, data.data() + header.size() + 36 + 1 + 8, 4);
  EXPECT_EQ(i2, 2);
}

TEST(PlyIoTest, FaceValuesAndAppend) {
  TriangleMesh a, b;
  a.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  a.triangles = {{0, 1, 2}};
  b = a;
  a.Append(b);
  ASSERT_EQ(a.vertices.size(), 6u);
  EXPECT_EQ(a.triangles[1], Eigen::Vector3i(3, 4, 5));
  std::vector<int> labels = {7, 9};
  const std::string path = testing::TempDir() + "/two.ply";
  ASSERT_TRUE(WritePly(path, a, &labels, "region").ok());
  EXPECT_NE(ReadAll(path).find("property int region\n"), std::string::npos);
  std::vector<int> wrong = {1};
  EXPECT_EQ(WritePly(path, a, &wrong).code(), absl::StatusCode::kInvalidArgument);
}

// Meshes streamed one after another with a face property: the very bytes of their
// concatenation with per-face values.
TEST(PlyIoTest, StreamedMeshesAreTheirConcatenation) {
  TriangleMesh a, b, c;
  a.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
  a.triangles = {{0, 1, 2}, {2, 1, 3}};
  b.vertices = {{5, 5, 5}, {6, 5, 5}, {5, 6, 5}};
  b.triangles = {{0, 2, 1}};
  c.vertices = {{-1, -2, -3}, {-1, -2, 4}, {-1, 7, -3}};
  c.triangles = {{1, 0, 2}};
  TriangleMesh whole = a;
  whole.Append(b);
  whole.Append(TriangleMesh{});
  whole.Append(c);
  const std::vector<int> values = {-1, -1, 4, 11};
  const std::string dir = testing::TempDir();
  ASSERT_TRUE(WritePly(dir + "/whole.ply", whole, &values, "object").ok());
  absl::StatusOr<std::unique_ptr<PlyStreamWriter>> w =
      PlyStreamWriter::Create(dir + "/parts.ply", "object");
  ASSERT_TRUE(w.ok()) << w.status();
  ASSERT_TRUE((*w)->AddMesh(a, -1).ok());
  ASSERT_TRUE((*w)->AddMesh(b, 4).ok());
  ASSERT_TRUE((*w)->AddMesh(TriangleMesh{}, 8).ok());
  ASSERT_TRUE((*w)->AddMesh(c, 11).ok());
  ASSERT_TRUE((*w)->Finish().ok());
  EXPECT_EQ(ReadAll(dir + "/parts.ply"), ReadAll(dir + "/whole.ply"));
  // No meshes: a valid empty mesh, as WritePly writes one.
  const std::vector<int> none;
  ASSERT_TRUE(WritePly(dir + "/empty_whole.ply", TriangleMesh{}, &none, "object").ok());
  w = PlyStreamWriter::Create(dir + "/empty_parts.ply", "object");
  ASSERT_TRUE(w.ok()) << w.status();
  ASSERT_TRUE((*w)->Finish().ok());
  EXPECT_EQ(ReadAll(dir + "/empty_parts.ply"), ReadAll(dir + "/empty_whole.ply"));
}

TEST(PlyIoTest, StreamWriterWritesWritePlysBytes) {
  TriangleMesh mesh;
  for (int i = 0; i < 1000; ++i) mesh.vertices.emplace_back(0.5f * i, -0.25f * i, 1.0f + i);
  for (int i = 0; i + 2 < 1000; i += 3) mesh.triangles.emplace_back(i, i + 2, i + 1);
  const std::string dir = testing::TempDir();
  ASSERT_TRUE(WritePly(dir + "/whole_stream.ply", mesh).ok());
  absl::StatusOr<std::unique_ptr<PlyStreamWriter>> w =
      PlyStreamWriter::Create(dir + "/streamed.ply");
  ASSERT_TRUE(w.ok()) << w.status();
  // Pieces of uneven sizes, vertices and triangles interleaved.
  const std::span<const Eigen::Vector3f> v(mesh.vertices);
  const std::span<const Eigen::Vector3i> t(mesh.triangles);
  ASSERT_TRUE((*w)->AddVertices(v.first(10)).ok());
  ASSERT_TRUE((*w)->AddTriangles(t.first(3)).ok());
  ASSERT_TRUE((*w)->AddVertices(v.subspan(10)).ok());
  ASSERT_TRUE((*w)->AddTriangles(t.subspan(3, 0)).ok());
  ASSERT_TRUE((*w)->AddTriangles(t.subspan(3)).ok());
  EXPECT_FALSE(std::filesystem::exists(dir + "/streamed.ply"));  // nothing final before Finish
  ASSERT_TRUE((*w)->Finish().ok());
  EXPECT_EQ((*w)->vertices(), 1000u);
  EXPECT_EQ((*w)->triangles(), 333u);
  w->reset();
  EXPECT_EQ(ReadAll(dir + "/streamed.ply"), ReadAll(dir + "/whole_stream.ply"));
  EXPECT_FALSE(std::filesystem::exists(dir + "/streamed.ply.vertices.partial"));
  EXPECT_FALSE(std::filesystem::exists(dir + "/streamed.ply.faces.partial"));
}

TEST(PlyIoTest, StreamWriterNotFinishedLeavesNothing) {
  const std::string dir = testing::TempDir();
  {
    absl::StatusOr<std::unique_ptr<PlyStreamWriter>> w =
        PlyStreamWriter::Create(dir + "/abandoned.ply");
    ASSERT_TRUE(w.ok());
    const std::vector<Eigen::Vector3f> v = {{1, 2, 3}};
    ASSERT_TRUE((*w)->AddVertices(v).ok());
  }
  EXPECT_FALSE(std::filesystem::exists(dir + "/abandoned.ply"));
  EXPECT_FALSE(std::filesystem::exists(dir + "/abandoned.ply.vertices.partial"));
  absl::StatusOr<std::unique_ptr<PlyStreamWriter>> bad =
      PlyStreamWriter::Create("/nonexistent-dir/x.ply");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(std::string(bad.status().message()).find("/nonexistent-dir/x.ply"), std::string::npos);
}

TEST(PlyIoTest, UnwritableDirectoryIsAClearError) {
  TriangleMesh mesh;
  absl::Status s = WritePly("/nonexistent-dir/x.ply", mesh);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(std::string(s.message()).find("/nonexistent-dir/x.ply"), std::string::npos);
}

TEST(PlyIoTest, ReadsBackWhatItWrites) {
  TriangleMesh a;
  a.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.5f, -2.25f, 3}};
  a.triangles = {{0, 1, 2}, {1, 3, 2}};
  std::vector<int> regions = {4, -7};
  const std::string path = testing::TempDir() + "/back.ply";
  ASSERT_TRUE(WritePly(path, a, &regions, "region").ok());
  absl::StatusOr<PlyMesh> b = ReadPly(path);
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(b->mesh.vertices, a.vertices);
  EXPECT_EQ(b->mesh.triangles, a.triangles);
  ASSERT_EQ(b->face_values.size(), 1u);
  EXPECT_EQ(b->face_values[0].first, "region");
  EXPECT_EQ(b->face_values[0].second, regions);
}

TEST(PlyIoTest, ReadFansPolygonsAndSkipsExtraProperties) {
  // A quad with a float face property and a vertex with an extra uchar, written by hand.
  std::string data =
      "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n"
      "property float y\nproperty float z\nproperty uchar red\nelement face 1\n"
      "property list uchar int vertex_indices\nproperty float quality\n"
      "property ushort part\nend_header\n";
  const float xyz[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  for (const auto& v : xyz) {
    data.append(reinterpret_cast<const char*>(v), 12);
    data.push_back(char(200));
  }
  data.push_back(char(4));
  const int idx[4] = {0, 1, 2, 3};
  data.append(reinterpret_cast<const char*>(idx), 16);
  const float q = 0.5f;
  data.append(reinterpret_cast<const char*>(&q), 4);
  const uint16_t part = 513;
  data.append(reinterpret_cast<const char*>(&part), 2);
  const std::string path = testing::TempDir() + "/quad.ply";
  std::ofstream(path, std::ios::binary) << data;
  absl::StatusOr<PlyMesh> m = ReadPly(path);
  ASSERT_TRUE(m.ok()) << m.status();
  ASSERT_EQ(m->mesh.triangles.size(), 2u);
  EXPECT_EQ(m->mesh.triangles[1], Eigen::Vector3i(0, 2, 3));
  EXPECT_EQ(m->mesh.vertices[2], Eigen::Vector3f(1, 1, 0));
  ASSERT_EQ(m->face_values.size(), 1u);  // the float property is not returned
  EXPECT_EQ(m->face_values[0].first, "part");
  EXPECT_EQ(m->face_values[0].second, (std::vector<int>{513, 513}));
}

TEST(PlyIoTest, ReadErrorsNameTheFile) {
  EXPECT_EQ(ReadPly(testing::TempDir() + "/missing.ply").status().code(),
            absl::StatusCode::kNotFound);
  TriangleMesh a;
  a.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  a.triangles = {{0, 1, 2}};
  const std::string path = testing::TempDir() + "/cut.ply";
  ASSERT_TRUE(WritePly(path, a).ok());
  std::string data = ReadAll(path);
  std::ofstream(path, std::ios::binary | std::ios::trunc) << data.substr(0, data.size() - 3);
  absl::Status s = ReadPly(path).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(std::string(s.message()).find(path), std::string::npos) << s;
  EXPECT_NE(std::string(s.message()).find("truncated"), std::string::npos) << s;
  // An index out of range.
  data[data.size() - 4] = 9;
  std::ofstream(path, std::ios::binary | std::ios::trunc) << data;
  s = ReadPly(path).status();
  EXPECT_NE(std::string(s.message()).find("vertex index 9"), std::string::npos) << s;
  std::ofstream(path, std::ios::binary | std::ios::trunc) << "ply\nformat ascii 1.0\nend_header\n";
  EXPECT_EQ(ReadPly(path).status().code(), absl::StatusCode::kDataLoss);
}

// Found by tests/fuzz (ply_mesh): a vertex count too large for size_t, or larger than the
// file could hold, threw std::length_error / bad_alloc from the vertex buffer's resize.
TEST(PlyIoTest, AbsurdVertexCountIsAnErrorNotAnAllocation) {
  const std::string path = testing::TempDir() + "/huge.ply";
  const std::string header_start =
      "ply\nformat binary_little_endian 1.0\nelement vertex ";
  const std::string header_end =
      "\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
  for (const std::string count : {"88888888888888888888888", "1000000000000", "2"}) {
    std::ofstream(path, std::ios::binary | std::ios::trunc)
        << header_start << count << header_end << std::string(12, '\0');
    absl::Status s = ReadPly(path).status();
    EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss) << count;
    EXPECT_NE(std::string(s.message()).find(path), std::string::npos) << s;
  }
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      << header_start << "1000000000000" << header_end << std::string(12, '\0');
  EXPECT_NE(std::string(ReadPly(path).status().message()).find("only 12 bytes follow"),
            std::string::npos);
}

}  // namespace
}  // namespace carvemap

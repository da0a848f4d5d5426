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

TEST(PlyIoTest, UnwritableDirectoryIsAClearError) {
  TriangleMesh mesh;
  absl::Status s = WritePly("/nonexistent-dir/x.ply", mesh);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(std::string(s.message()).find("/nonexistent-dir/x.ply"), std::string::npos);
}

}  // namespace
}  // namespace carvemap

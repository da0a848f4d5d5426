#include "storage/glb_writer.h"

#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include "tests/support/test_meshes.h"

namespace carvemap {
namespace {

using testing::Tetrahedron;

namespace fs = std::filesystem;

// An accessor's elements as T, through its buffer view, as a reader finds them.
template <typename T>
std::vector<T> Elements(const tinygltf::Model& model, int accessor, int components) {
  const tinygltf::Accessor& a = model.accessors.at(accessor);
  const tinygltf::BufferView& v = model.bufferViews.at(a.bufferView);
  const std::vector<unsigned char>& data = model.buffers.at(v.buffer).data;
  std::vector<T> out(a.count * components);
  EXPECT_LE(v.byteOffset + a.byteOffset + out.size() * sizeof(T), data.size());
  std::memcpy(out.data(), data.data() + v.byteOffset + a.byteOffset, out.size() * sizeof(T));
  return out;
}

tinygltf::Model Load(const std::string& path) {
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string err, warn;
  EXPECT_TRUE(loader.LoadBinaryFromFile(&model, &err, &warn, path)) << err;
  EXPECT_TRUE(err.empty()) << err;
  EXPECT_TRUE(warn.empty()) << warn;
  return model;
}

// What the writer was given is what libtinygltf reads: the node tree with names and extras,
// each mesh's vertices and triangles, bounds and materials, under a root turning z up to y up.
TEST(GlbWriterTest, ReadBackByTinyGltf) {
  const std::string path = ::testing::TempDir() + "/model.glb";
  absl::StatusOr<std::unique_ptr<GlbStreamWriter>> w = GlbStreamWriter::Create(path);
  ASSERT_TRUE(w.ok()) << w.status();
  const int grey = (*w)->AddMaterial("building", {0.8f, 0.8f, 0.8f, 1}, false);
  const int glass = (*w)->AddMaterial("room", {0.2f, 0.4f, 1, 0.25f}, true);
  const TriangleMesh building = Tetrahedron({-1, -2, 0}, 10);
  const TriangleMesh chair = Tetrahedron({1, 1, 0}, 0.5f), desk = Tetrahedron({3, 1, 0}, 1);
  ASSERT_TRUE((*w)->AddNode("building", -1, building, grey).ok());
  absl::StatusOr<int> objects = (*w)->AddNode("objects", -1, TriangleMesh{}, -1);
  ASSERT_TRUE(objects.ok());
  ASSERT_TRUE(
      (*w)->AddNode("object 0", *objects, chair, glass, {{"id", 0}, {"volume_m3", 0.5}}).ok());
  ASSERT_TRUE((*w)->AddNode("object 1", *objects, desk, grey, {{"id", 1}}).ok());
  EXPECT_EQ((*w)->buffer_bytes(), 3u * (4 * 12 + 4 * 12));
  ASSERT_TRUE((*w)->Finish().ok());
  EXPECT_FALSE(fs::exists(path + ".bin.partial"));

  const tinygltf::Model model = Load(path);
  EXPECT_EQ(model.asset.version, "2.0");
  ASSERT_EQ(model.scenes.size(), 1u);
  ASSERT_EQ(model.scenes[0].nodes, std::vector<int>{0});
  ASSERT_EQ(model.nodes.size(), 5u);
  const tinygltf::Node& root = model.nodes[0];
  EXPECT_EQ(root.name, "carvemap");
  ASSERT_EQ(root.rotation.size(), 4u);
  EXPECT_NEAR(root.rotation[0], -std::sqrt(0.5), 1e-12);
  EXPECT_NEAR(root.rotation[3], std::sqrt(0.5), 1e-12);
  EXPECT_EQ(root.children, (std::vector<int>{1, 2}));
  EXPECT_EQ(model.nodes[2].name, "objects");
  EXPECT_EQ(model.nodes[2].mesh, -1);
  EXPECT_EQ(model.nodes[2].children, (std::vector<int>{3, 4}));
  EXPECT_EQ(model.nodes[3].extras.Get("id").GetNumberAsInt(), 0);
  EXPECT_DOUBLE_EQ(model.nodes[3].extras.Get("volume_m3").GetNumberAsDouble(), 0.5);

  const std::vector<const TriangleMesh*> given = {&building, &chair, &desk};
  const std::vector<int> material = {grey, glass, grey};
  for (int n = 0; n < 3; ++n) {
    const tinygltf::Node& node = model.nodes[n == 0 ? 1 : n + 2];
    ASSERT_GE(node.mesh, 0);
    const tinygltf::Primitive& p = model.meshes[node.mesh].primitives.at(0);
    EXPECT_EQ(p.mode, TINYGLTF_MODE_TRIANGLES);
    EXPECT_EQ(p.material, material[n]);
    const int pos = p.attributes.at("POSITION");
    EXPECT_EQ(model.accessors[pos].componentType, TINYGLTF_COMPONENT_TYPE_FLOAT);
    EXPECT_EQ(model.accessors[p.indices].componentType, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT);
    const std::vector<float> xyz = Elements<float>(model, pos, 3);
    const std::vector<uint32_t> idx = Elements<uint32_t>(model, p.indices, 1);
    const TriangleMesh& m = *given[n];
    ASSERT_EQ(xyz.size(), 3 * m.vertices.size());
    ASSERT_EQ(idx.size(), 3 * m.triangles.size());
    for (size_t i = 0; i < m.vertices.size(); ++i) {
      for (int k = 0; k < 3; ++k) EXPECT_EQ(xyz[3 * i + k], m.vertices[i][k]);
    }
    for (size_t i = 0; i < m.triangles.size(); ++i) {
      for (int k = 0; k < 3; ++k) EXPECT_EQ(int(idx[3 * i + k]), m.triangles[i][k]);
    }
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(model.accessors[pos].minValues[k], m.vertices[0][k]);
      EXPECT_EQ(model.accessors[pos].maxValues[k], m.vertices[k + 1][k]);
    }
  }
  EXPECT_EQ(model.materials[glass].alphaMode, "BLEND");
  EXPECT_TRUE(model.materials[glass].doubleSided);
  EXPECT_EQ(model.materials[grey].alphaMode, "OPAQUE");
  EXPECT_NEAR(model.materials[glass].pbrMetallicRoughness.baseColorFactor[3], 0.25, 1e-7);
}

// Nothing but the root: still a file every reader opens (no empty arrays, no buffer).
TEST(GlbWriterTest, EmptyModelIsValid) {
  const std::string path = ::testing::TempDir() + "/empty.glb";
  absl::StatusOr<std::unique_ptr<GlbStreamWriter>> w = GlbStreamWriter::Create(path);
  ASSERT_TRUE(w.ok()) << w.status();
  ASSERT_TRUE((*w)->Finish().ok());
  const tinygltf::Model model = Load(path);
  EXPECT_EQ(model.nodes.size(), 1u);
  EXPECT_TRUE(model.buffers.empty());
  EXPECT_EQ(fs::file_size(path) % 4, 0u);
}

// Bad nodes are refused, and a writer never finished leaves no file.
TEST(GlbWriterTest, BadNodesAreErrorsAndAnUnfinishedWriterLeavesNothing) {
  const std::string path = ::testing::TempDir() + "/unfinished.glb";
  fs::remove(path);
  {
    absl::StatusOr<std::unique_ptr<GlbStreamWriter>> w = GlbStreamWriter::Create(path);
    ASSERT_TRUE(w.ok()) << w.status();
    const int m = (*w)->AddMaterial("m", {1, 1, 1, 1}, false);
    TriangleMesh bad = Tetrahedron({0, 0, 0}, 1);
    bad.triangles[2][1] = 4;
    EXPECT_EQ((*w)->AddNode("bad", -1, bad, m).status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_EQ((*w)->AddNode("orphan", 7, TriangleMesh{}, m).status().code(),
              absl::StatusCode::kInvalidArgument);
    EXPECT_EQ((*w)->AddNode("bare", -1, Tetrahedron({0, 0, 0}, 1), m + 1).status().code(),
              absl::StatusCode::kInvalidArgument);
    ASSERT_TRUE((*w)->AddNode("fine", -1, Tetrahedron({0, 0, 0}, 1), m).ok());
  }
  EXPECT_FALSE(fs::exists(path));
  EXPECT_FALSE(fs::exists(path + ".bin.partial"));
}

}  // namespace
}  // namespace carvemap

#include "services/merge/model_glb.h"

#include <set>
#include <string>

#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include "tests/support/test_meshes.h"

namespace carvemap {
namespace {

using testing::Tetrahedron;

// Two rooms side by side (4 × 2 m and 2 × 2 m) on a square grid, two triangles per cell.
FloorPlan TwoRooms() {
  FloorPlan plan;
  for (int j = 0; j <= 2; ++j) {
    for (int i = 0; i <= 3; ++i) {
      plan.vertices.emplace_back(2.0 * i, 1.0 * j);
      plan.vertex_floor_z.push_back(0);
      plan.vertex_ceiling_z.push_back(3);
    }
  }
  auto v = [](int i, int j) { return static_cast<uint32_t>(j * 4 + i); };
  for (int j = 0; j < 2; ++j) {
    for (int i = 0; i < 3; ++i) {
      plan.triangles.push_back({v(i, j), v(i + 1, j), v(i + 1, j + 1)});
      plan.triangles.push_back({v(i, j), v(i + 1, j + 1), v(i, j + 1)});
      plan.triangle_room.insert(plan.triangle_room.end(), 2, i < 2 ? 0 : 1);
    }
  }
  plan.rooms.resize(2);
  plan.rooms[0] = {.area_m2 = 8, .floor_z = 0, .ceiling_z = 2.5};
  plan.rooms[1] = {.area_m2 = 4, .floor_z = 0.1, .ceiling_z = 2.7};
  return plan;
}

// The scene a viewer opens: building, rooms and objects under the root, named, with their
// extras and materials, as libtinygltf reads them.
TEST(ModelGlbTest, BuildingRoomsAndObjectsAsNamedNodes) {
  const std::string path = ::testing::TempDir() + "/model.glb";
  Level level;
  level.index = 1;
  const std::vector<std::pair<Level, FloorPlan>> plans = {{level, TwoRooms()}};
  absl::StatusOr<std::unique_ptr<ModelGlb>> model =
      ModelGlb::Create(path, Tetrahedron({0, 0, 0}, 10), plans);
  ASSERT_TRUE(model.ok()) << model.status();
  for (int id = 0; id < 14; ++id) {
    SegmentedObject o;
    o.id = id;
    o.level = 1;
    o.room = id % 2;
    o.volume_m3 = 0.001 * id;
    o.box = Eigen::AlignedBox3d(Eigen::Vector3d(id, 0, 0), Eigen::Vector3d(id + 0.5, 0.5, 0.5));
    ASSERT_TRUE((*model)->AddObject(o, Tetrahedron({float(id), 0, 0}, 0.5f)).ok());
  }
  ASSERT_TRUE((*model)->Finish().ok());

  tinygltf::Model gltf;
  tinygltf::TinyGLTF loader;
  std::string err, warn;
  ASSERT_TRUE(loader.LoadBinaryFromFile(&gltf, &err, &warn, path)) << err;
  const tinygltf::Node& root = gltf.nodes.at(0);
  ASSERT_EQ(root.children.size(), 3u);
  const tinygltf::Node& building = gltf.nodes.at(root.children[0]);
  const tinygltf::Node& rooms = gltf.nodes.at(root.children[1]);
  const tinygltf::Node& objects = gltf.nodes.at(root.children[2]);
  EXPECT_EQ(building.name, "building");
  EXPECT_GE(building.mesh, 0);
  EXPECT_EQ(rooms.name, "rooms");
  ASSERT_EQ(rooms.children.size(), 2u);
  const tinygltf::Node& room1 = gltf.nodes.at(rooms.children[1]);
  EXPECT_EQ(room1.name, "level 1 room 1");
  EXPECT_DOUBLE_EQ(room1.extras.Get("area_m2").GetNumberAsDouble(), 4);
  EXPECT_DOUBLE_EQ(room1.extras.Get("ceiling_z").GetNumberAsDouble(), 2.7);
  // The room's solid spans its floor to its ceiling over its 2 × 2 m.
  const tinygltf::Accessor& pos =
      gltf.accessors.at(gltf.meshes.at(room1.mesh).primitives.at(0).attributes.at("POSITION"));
  ASSERT_EQ(pos.minValues.size(), 3u);
  EXPECT_NEAR(pos.maxValues[2] - pos.minValues[2], 2.6, 1e-6);
  const tinygltf::Material& glass =
      gltf.materials.at(gltf.meshes.at(room1.mesh).primitives.at(0).material);
  EXPECT_EQ(glass.alphaMode, "BLEND");
  EXPECT_EQ(objects.name, "objects");
  ASSERT_EQ(objects.children.size(), 14u);
  std::set<int> materials;
  for (int id = 0; id < 14; ++id) {
    const tinygltf::Node& o = gltf.nodes.at(objects.children[id]);
    EXPECT_EQ(o.name, "object " + std::to_string(id));
    EXPECT_EQ(o.extras.Get("id").GetNumberAsInt(), id);
    EXPECT_EQ(o.extras.Get("room").GetNumberAsInt(), id % 2);
    EXPECT_DOUBLE_EQ(o.extras.Get("aabb").Get(1).Get(0).GetNumberAsDouble(), id + 0.5);
    materials.insert(gltf.meshes.at(o.mesh).primitives.at(0).material);
  }
  EXPECT_EQ(materials.size(), 12u);  // the palette, reused past 12
}

TEST(ModelGlbTest, PaletteNeighboursDiffer) {
  for (int k = 0; k + 1 < 12; ++k) {
    const std::array<float, 4> a = ObjectColour(k), b = ObjectColour(k + 1);
    const float d = std::abs(a[0] - b[0]) + std::abs(a[1] - b[1]) + std::abs(a[2] - b[2]);
    EXPECT_GT(d, 0.2f) << k;
    for (int c = 0; c < 3; ++c) {
      EXPECT_GE(a[c], 0.0f);
      EXPECT_LE(a[c], 1.0f);
    }
  }
}

}  // namespace
}  // namespace carvemap

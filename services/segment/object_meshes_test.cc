#include "services/segment/object_meshes.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <span>

#include <gtest/gtest.h>

#include "services/mesh/dual_contouring.h"
#include "services/mesh/mesh_checks.h"
#include "services/segment/segment_chunk.h"
#include "services/segment/segment_test_util.h"

namespace carvemap {
namespace {

using testing::RectanglePlan;

// A box as 12 triangles facing into it (as dual contouring orients the object volume's surface:
// counter-clockwise seen from the free space, i.e. normals into the object).
TriangleMesh InwardBox(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
  TriangleMesh m;
  for (int i = 0; i < 8; ++i) {
    m.vertices.emplace_back(i & 1 ? hi.x() : lo.x(), i & 2 ? hi.y() : lo.y(),
                            i & 4 ? hi.z() : lo.z());
  }
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {  // outward quads, reversed
    m.triangles.emplace_back(q[0], q[2], q[1]);
    m.triangles.emplace_back(q[0], q[3], q[2]);
  }
  return m;
}

TriangleMesh Reversed(TriangleMesh m) {
  for (Eigen::Vector3i& t : m.triangles) std::swap(t[1], t[2]);
  return m;
}

class ObjectMeshesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    plan_ = RectanglePlan({{{0, 0}, {4, 4}, 0.0, 2.5}, {{4, 0}, {8, 4}, 0.0, 2.5}});
    const PlanLevelInput in{&plan_, 0, -1.0, 3.0};
    volume_ = *RasterizePlanVolume({&in, 1}, 0.0625, 1.0);
  }
  FloorPlan plan_;
  PlanVolume volume_;
};

TEST_F(ObjectMeshesTest, SplitsPiecesOrientsThemOutwardAndDropsSpecksAndCavities) {
  TriangleMesh all;
  all.Append(InwardBox({5, 1, 0}, {6, 2, 0.5}));             // a table in room 1
  all.Append(InwardBox({1, 1, 0}, {2, 3, 1}));               // a cabinet in room 0 ...
  all.Append(Reversed(InwardBox({1.2f, 1.2f, 0.2f}, {1.8f, 2.8f, 0.8f})));  // ... hollow
  all.Append(InwardBox({3, 3, 1}, {3.05f, 3.05f, 1.05f}));   // a speck
  all.Append(InwardBox({6.5f, 3, 1}, {6.64f, 3.14f, 1.1f}));  // a 2-litre sliver of a wall
  ObjectSplitReport report;
  const std::vector<SegmentedObject> objects =
      SplitObjects(all, volume_, ObjectSplitOptions{}, &report);
  EXPECT_EQ(report.components, 5u);
  EXPECT_EQ(report.dropped_small, 2u);  // below the default 5 litres
  EXPECT_EQ(report.dropped_cavities, 1u);
  ASSERT_EQ(objects.size(), 2u);
  // Ordered by box min x: the cabinet first.
  EXPECT_EQ(objects[0].id, 0);
  EXPECT_EQ(objects[0].room, 0);
  EXPECT_EQ(objects[0].level, 0);
  EXPECT_NEAR(objects[0].volume_m3, 2.0, 1e-5);  // the outer surface's volume: filled
  EXPECT_TRUE(objects[0].box.isApprox(
      Eigen::AlignedBox3d(Eigen::Vector3d(1, 1, 0), Eigen::Vector3d(2, 3, 1))));
  EXPECT_EQ(objects[1].id, 1);
  EXPECT_EQ(objects[1].room, 1);
  EXPECT_NEAR(objects[1].volume_m3, 0.5, 1e-6);
  for (const SegmentedObject& o : objects) {
    EXPECT_EQ(o.mesh.vertices.size(), 8u);
    EXPECT_EQ(o.mesh.triangles.size(), 12u);
    EXPECT_TRUE(CheckMesh(o.mesh).watertight()) << CheckMesh(o.mesh).ToString();
  }
  // With 1 litre the sliver is an object.
  ObjectSplitOptions litre;
  litre.min_volume_m3 = 0.001;
  EXPECT_EQ(SplitObjects(all, volume_, litre).size(), 3u);
  // Thin pieces go with min_thickness_m.
  ObjectSplitOptions thin;
  thin.min_thickness_m = 0.6;
  EXPECT_EQ(SplitObjects(all, volume_, thin).size(), 1u);
}

// A shelf whose side panels the carve lost comes out as boards stacked over each other: one
// object. A chair beside it (footprints apart) and a lamp far above a table stay apart.
TEST_F(ObjectMeshesTest, StackedPiecesAreOneObject) {
  TriangleMesh all;
  for (float z : {0.05f, 0.45f, 0.85f, 1.25f}) {
    all.Append(InwardBox({1, 1, z}, {2, 1.35f, z + 0.05f}));  // a shelf's boards
  }
  all.Append(InwardBox({2.05f, 1.0f, 0.0f}, {2.5f, 1.45f, 0.9f}));  // a chair beside it
  all.Append(InwardBox({5, 1, 0.4f}, {6, 2, 0.75f}));                 // a table ...
  all.Append(InwardBox({5.2f, 1.2f, 1.9f}, {5.8f, 1.8f, 2.0f}));     // ... a lamp 1.15 m over it
  ObjectSplitReport report;
  const std::vector<SegmentedObject> objects =
      SplitObjects(all, volume_, ObjectSplitOptions{}, &report);
  EXPECT_EQ(report.components, 7u);
  EXPECT_EQ(report.grouped, 3u);
  ASSERT_EQ(objects.size(), 4u);
  const SegmentedObject& shelf = objects[0];
  EXPECT_TRUE(shelf.box.isApprox(
      Eigen::AlignedBox3d(Eigen::Vector3d(1, 1, 0.05), Eigen::Vector3d(2, 1.35, 1.3)), 1e-6));
  EXPECT_NEAR(shelf.volume_m3, 4 * 0.35 * 0.05, 1e-5);
  EXPECT_EQ(shelf.mesh.triangles.size(), 4u * 12u);
  EXPECT_TRUE(CheckMesh(shelf.mesh).watertight()) << CheckMesh(shelf.mesh).ToString();
  EXPECT_NEAR(objects[1].box.min().x(), 2.05, 1e-6);  // the chair
  EXPECT_EQ(objects[2].mesh.triangles.size(), 12u);   // the table
  EXPECT_EQ(objects[3].mesh.triangles.size(), 12u);   // the lamp
  // The dissertation's rule: one object per piece.
  ObjectSplitOptions pieces;
  pieces.stack_gap_m = -1;
  EXPECT_EQ(SplitObjects(all, volume_, pieces).size(), 7u);
}

// Pieces are matched wherever their footprints meet, not only near their corners: a cabinet
// and a speck under and over the far end of a 3.6 m table join it; a speck as far from
// everything stays alone and is dropped. The speck widens the table's box, not its mesh.
TEST_F(ObjectMeshesTest, PiecesStackWhereverTheirFootprintsMeet) {
  TriangleMesh all;
  all.Append(InwardBox({0.2f, 0.2f, 0.7f}, {3.8f, 3.8f, 0.75f}));     // a table top
  all.Append(InwardBox({3.3f, 3.3f, 0.0f}, {3.7f, 3.7f, 0.6f}));      // a cabinet under it
  all.Append(InwardBox({3.6f, 0.3f, 0.8f}, {3.63f, 0.33f, 0.83f}));   // a speck on it
  all.Append(InwardBox({6.0f, 3.0f, 0.8f}, {6.03f, 3.03f, 0.83f}));   // a speck alone
  ObjectSplitReport report;
  const std::vector<SegmentedObject> objects =
      SplitObjects(all, volume_, ObjectSplitOptions{}, &report);
  EXPECT_EQ(report.grouped, 2u);
  EXPECT_EQ(report.dropped_small, 1u);
  ASSERT_EQ(objects.size(), 1u);
  EXPECT_TRUE(objects[0].box.isApprox(
      Eigen::AlignedBox3d(Eigen::Vector3d(0.2, 0.2, 0), Eigen::Vector3d(3.8, 3.8, 0.83)), 1e-6));
  EXPECT_EQ(report.specks_unmeshed, 1u);
  EXPECT_EQ(objects[0].mesh.triangles.size(), 2u * 12u);  // the top and the cabinet
  Eigen::AlignedBox3d meshed;
  for (const Eigen::Vector3f& v : objects[0].mesh.vertices) meshed.extend(v.cast<double>());
  EXPECT_NEAR(meshed.max().z(), 0.75, 1e-6);
  EXPECT_NEAR(objects[0].volume_m3, 3.6 * 3.6 * 0.05 + 0.4 * 0.4 * 0.6, 1e-5);
  EXPECT_TRUE(CheckMesh(objects[0].mesh).watertight());
}

// Under drift a wall's points fill specks along it inside the room: with wall_smear_m they
// no longer join the desk standing against the wall below them, and are dropped; a speck
// farther from the wall, and one under the desk, still join it.
TEST_F(ObjectMeshesTest, SpecksAlongAWallDoNotStackOnTheObjectBelow) {
  TriangleMesh all;
  all.Append(InwardBox({1.0f, 0.05f, 0.0f}, {2.4f, 0.75f, 0.75f}));  // a desk against y = 0
  all.Append(InwardBox({1.5f, 0.1f, 1.2f}, {1.53f, 0.13f, 1.23f}));  // wall smear over it
  all.Append(InwardBox({2.0f, 0.5f, 1.1f}, {2.03f, 0.53f, 1.13f}));  // 0.53 m from the wall
  all.Append(InwardBox({1.2f, 0.1f, 0.0f}, {1.23f, 0.13f, 0.03f}));  // under its top's edge
  ObjectSplitOptions options;
  ObjectSplitReport plain;
  std::vector<SegmentedObject> objects = SplitObjects(all, volume_, options, &plain);
  ASSERT_EQ(objects.size(), 1u);
  EXPECT_NEAR(objects[0].box.max().z(), 1.23, 1e-6);  // the smear took the desk up
  EXPECT_EQ(plain.specks_off_walls, 0u);
  options.wall_smear_m = 0.3;
  ObjectSplitReport report;
  objects = SplitObjects(all, volume_, options, &report);
  ASSERT_EQ(objects.size(), 1u);
  EXPECT_TRUE(objects[0].box.isApprox(
      Eigen::AlignedBox3d(Eigen::Vector3d(1.0, 0.05, 0), Eigen::Vector3d(2.4, 0.75, 1.13)), 1e-6));
  EXPECT_EQ(report.specks_off_walls, 1u);
  EXPECT_EQ(report.grouped, 2u);
  EXPECT_EQ(report.dropped_small, 1u);  // the smear, left alone
}

// Under drift the wall itself lands inside the room as a slab up to the ceiling, deeper than a
// door header, the plan's wall line through it: with wall_smear_m it is dropped. A piece up to
// the ceiling away from the walls, and one along the wall that stops below the ceiling, stay.
TEST_F(ObjectMeshesTest, AWallSlabUpToTheCeilingIsNoObject) {
  TriangleMesh all;
  all.Append(InwardBox({1.0f, -0.2f, 1.6f}, {2.2f, 0.25f, 2.5f}));  // the wall's slab, 0.45 m deep
  all.Append(InwardBox({2.5f, 1.5f, 0.0f}, {3.0f, 2.0f, 2.45f}));   // a tall cabinet in the room
  all.Append(InwardBox({1.0f, -0.2f, 0.3f}, {2.2f, 0.25f, 1.0f}));  // along the wall, low
  ObjectSplitOptions options;
  ObjectSplitReport plain;
  EXPECT_EQ(SplitObjects(all, volume_, options, &plain).size(), 3u);
  EXPECT_EQ(plain.dropped_wall_smear, 0u);
  EXPECT_EQ(plain.dropped_ceiling, 0u);  // deeper than a door header
  options.wall_smear_m = 0.3;
  ObjectSplitReport report;
  const std::vector<SegmentedObject> objects = SplitObjects(all, volume_, options, &report);
  ASSERT_EQ(objects.size(), 2u);
  EXPECT_EQ(report.dropped_wall_smear, 1u);
  for (const SegmentedObject& o : objects) EXPECT_LT(o.box.min().z(), 1.0) << o.box.min().z();
}

// The mesh as StreamDenseMesh gives it, a chunk column at a time (columns 1 m wide here, by
// each triangle's lowest x): pieces are finished as the stream passes them, and the objects
// are those of the whole mesh, meshes and all.
TEST_F(ObjectMeshesTest, StreamedByColumnsGivesTheWholeMeshsObjects) {
  TriangleMesh boxes;
  boxes.Append(InwardBox({5, 1, 0}, {6, 2, 0.5}));
  boxes.Append(InwardBox({1, 1, 0}, {2, 3, 1}));
  boxes.Append(Reversed(InwardBox({1.2f, 1.2f, 0.2f}, {1.8f, 2.8f, 0.8f})));
  for (float z : {0.05f, 0.45f, 0.85f})
    boxes.Append(InwardBox({3, 1, z}, {3.9f, 1.35f, z + 0.05f}));
  boxes.Append(InwardBox({6.5f, 3, 1}, {6.64f, 3.14f, 1.1f}));
  boxes.Append(InwardBox({5.5f, 1.5f, 0.6f}, {5.53f, 1.53f, 0.63f}));  // a speck over the table
  const auto column_of = [&](const Eigen::Vector3i& t) {
    float x = boxes.vertices[t[0]].x();
    for (int k = 1; k < 3; ++k) x = std::min(x, boxes.vertices[t[k]].x());
    return static_cast<int64_t>(std::floor(x));
  };
  // The triangles in column order, as the stream gives them.
  TriangleMesh streamed = boxes;
  std::stable_sort(streamed.triangles.begin(), streamed.triangles.end(),
                   [&](const Eigen::Vector3i& a, const Eigen::Vector3i& b) {
                     return column_of(a) < column_of(b);
                   });
  ObjectSplitReport whole_report;
  const std::vector<SegmentedObject> whole =
      SplitObjects(streamed, volume_, ObjectSplitOptions{}, &whole_report);
  ASSERT_EQ(whole.size(), 3u);  // the cabinet, the stacked boards, the table

  std::map<uint64_t, TriangleMesh> pieces;
  ObjectSplitter splitter(volume_, ObjectSplitOptions{}, [&](uint64_t key, const TriangleMesh& m) {
    EXPECT_TRUE(pieces.emplace(key, m).second) << key;
    return absl::OkStatus();
  });
  splitter.AddVertices(streamed.vertices);
  size_t open_at_table = 0;
  for (size_t i = 0; i < streamed.triangles.size();) {
    const int64_t column = column_of(streamed.triangles[i]);
    size_t j = i;
    while (j < streamed.triangles.size() && column_of(streamed.triangles[j]) == column) ++j;
    ASSERT_TRUE(
        splitter.AddTriangles(column, std::span(streamed.triangles).subspan(i, j - i)).ok());
    if (column == 5) open_at_table = splitter.open_triangles();
    i = j;
  }
  // By column 5 the cabinet (columns 1–2) and the boards (column 3) are finished: only the
  // table's triangles are open, all but the two of its side at x = 6 (column 6), and the speck's.
  EXPECT_EQ(open_at_table, 10u + 12u);
  absl::StatusOr<ObjectLayout> layout = splitter.Finish();
  ASSERT_TRUE(layout.ok()) << layout.status();
  EXPECT_EQ(splitter.open_triangles(), 0u);
  EXPECT_EQ(layout->report.components, whole_report.components);
  EXPECT_EQ(layout->report.grouped, whole_report.grouped);
  EXPECT_EQ(layout->report.dropped_cavities, 1u);
  EXPECT_EQ(layout->report.specks_unmeshed, 1u);
  // The sink saw every kept piece but the speck: the cabinet, three boards, the table and the
  // 2-litre sliver (dropped later, as too small an object).
  EXPECT_EQ(pieces.size(), 6u);
  ASSERT_EQ(layout->objects.size(), whole.size());
  for (size_t i = 0; i < whole.size(); ++i) {
    const SegmentedObject& o = layout->objects[i];
    EXPECT_EQ(o.id, whole[i].id);
    EXPECT_EQ(o.room, whole[i].room);
    EXPECT_EQ(o.volume_m3, whole[i].volume_m3);
    EXPECT_TRUE(o.box.isApprox(whole[i].box, 0));
    TriangleMesh mesh;
    for (uint64_t key : layout->pieces[i]) mesh.Append(pieces.at(key));
    EXPECT_EQ(mesh.vertices, whole[i].mesh.vertices) << i;
    EXPECT_EQ(mesh.triangles, whole[i].mesh.triangles) << i;
  }
}

// A triangle that reaches back to a piece the stream has already finished is an error, not
// a second object.
TEST_F(ObjectMeshesTest, TriangleJoiningAFinishedPieceIsAnError) {
  const TriangleMesh box = InwardBox({1, 1, 0}, {2, 2, 1});
  ObjectSplitter splitter(volume_, ObjectSplitOptions{}, nullptr);
  splitter.AddVertices(box.vertices);
  const std::span<const Eigen::Vector3i> tris(box.triangles);
  ASSERT_TRUE(splitter.AddTriangles(0, tris.first(6)).ok());
  const absl::Status s = splitter.AddTriangles(2, tris.subspan(6));
  EXPECT_EQ(s.code(), absl::StatusCode::kInternal) << s;
  EXPECT_EQ(splitter.AddTriangles(1, tris.subspan(6)).code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(ObjectMeshesTest, EmptyMeshHasNoObjects) {
  ObjectSplitReport report;
  EXPECT_TRUE(SplitObjects(TriangleMesh{}, volume_, ObjectSplitOptions{}, &report).empty());
  EXPECT_EQ(report.components, 0u);
}

// The whole path on a synthetic octree: a room with a box on its floor, segmented, dual
// contoured and split, gives one watertight object where the box is.
TEST(SegmentThenMesh, BoxOnTheFloorComesOutAsOneObject) {
  const OctreeGrid grid = *OctreeGrid::FromResolution(0.0625);
  const FloorPlan plan = RectanglePlan({{{0.25, 0.25}, {1.75, 1.75}, 0.25, 1.75}});
  const PlanLevelInput in{&plan, 0, -1.0, 3.0};
  const PlanVolume volume = *RasterizePlanVolume({&in, 1}, grid.resolution_m(), 1.5);
  const TileData tile = testing::FinestTile(grid, [](const Eigen::Vector3d& c) {
    const bool in_room =
        testing::Inside(c, Eigen::Vector3d::Constant(0.25), Eigen::Vector3d::Constant(1.75));
    const bool in_box = testing::Inside(c, {0.75, 0.5, 0.25}, {1.25, 1.25, 0.75});
    return in_room && !in_box ? 0.8 : 0.2;
  });
  ChunkNeighbourhood alone;
  alone.grid = grid;
  alone.chunk = ChunkKey::Zero();
  alone.tiles[ChunkNeighbourhood::Index(0, 0, 0)] = &tile;
  absl::StatusOr<SegmentedChunk> seg = SegmentChunk(alone, volume, SegmentOptions{});
  ASSERT_TRUE(seg.ok()) << seg.status();
  std::map<ChunkKey, TileData, ChunkKeyLess> tiles{{ChunkKey::Zero(), seg->objects}};
  std::vector<ChunkMesh> meshes;
  const std::vector<ChunkKey> keys{ChunkKey::Zero()};
  for (const ChunkKey& chunk : DenseMeshChunks(keys)) {
    ChunkNeighbourhood hood;
    hood.grid = grid;
    hood.chunk = chunk;
    for (int j = 0; j < 27; ++j) {
      auto it = tiles.find(chunk + ChunkKey(j % 3 - 1, (j / 3) % 3 - 1, j / 9 - 1));
      if (it != tiles.end()) hood.tiles[j] = &it->second;
    }
    absl::StatusOr<ChunkMesh> m = DualContourChunk(hood);
    ASSERT_TRUE(m.ok()) << m.status();
    meshes.push_back(std::move(*m));
  }
  ChunkMeshWelder welder(grid.leaves_per_side());
  for (ChunkMesh& m : meshes) ASSERT_TRUE(welder.Add(std::move(m)).ok());
  absl::StatusOr<TriangleMesh> welded = welder.Finish();
  ASSERT_TRUE(welded.ok()) << welded.status();
  const TriangleMesh& dense = *welded;
  ObjectSplitReport report;
  const std::vector<SegmentedObject> objects =
      SplitObjects(dense, volume, ObjectSplitOptions{}, &report);
  ASSERT_EQ(objects.size(), 1u) << report.components << " pieces";
  const SegmentedObject& o = objects[0];
  EXPECT_TRUE(CheckMesh(o.mesh).watertight()) << CheckMesh(o.mesh).ToString();
  EXPECT_EQ(o.room, 0);
  // The box is 0.5 × 0.75 × 0.5 m, standing on the floor: the floor's boundary layer under it
  // is object too (§5.6 keeps that layer building elsewhere), so its surface is within a cell of
  // the box's faces, the bottom too.
  const double r = grid.resolution_m();
  EXPECT_NEAR(o.box.min().x(), 0.75, r);
  EXPECT_NEAR(o.box.max().x(), 1.25, r);
  EXPECT_NEAR(o.box.min().y(), 0.5, r);
  EXPECT_NEAR(o.box.max().y(), 1.25, r);
  EXPECT_NEAR(o.box.min().z(), 0.25, 0.5 * r);
  EXPECT_NEAR(o.box.max().z(), 0.75, r);
  EXPECT_NEAR(o.volume_m3, 0.5 * 0.75 * 0.5, 0.15 * 0.5 * 0.75 * 0.5);
}

}  // namespace
}  // namespace carvemap

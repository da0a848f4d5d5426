#include "services/segment/segment_chunk.h"

#include <cmath>

#include <gtest/gtest.h>

#include "services/segment/segment_test_util.h"

namespace carvemap {
namespace {

using testing::FinestTile;
using testing::Inside;
using testing::RectanglePlan;

LeafStats WithP(double p) {
  LeafStats s;
  s.Add(p, 0.5);
  s.Add(p, 0.25);
  return s;
}

// The finest cells of a tile, each with the stats of the leaf covering it (count 0: none).
std::vector<LeafStats> Cells(const TileData& t, int* covered_twice = nullptr) {
  const int n = t.grid.leaves_per_side(), k = t.grid.chunk_depth;
  std::vector<LeafStats> cells(static_cast<size_t>(n) * n * n);
  std::vector<int> cover(cells.size(), 0);
  for (const TileLeaf& l : t.leaves) {
    const int s = 1 << (k - l.node.depth);
    const Eigen::Vector3i lo = l.node.local * s;
    for (int z = lo.z(); z < lo.z() + s; ++z)
      for (int y = lo.y(); y < lo.y() + s; ++y)
        for (int x = lo.x(); x < lo.x() + s; ++x) {
          const size_t i = x + static_cast<size_t>(n) * (y + static_cast<size_t>(n) * z);
          cells[i] = l.stats;
          ++cover[i];
        }
  }
  if (covered_twice) {
    *covered_twice = 0;
    for (int c : cover) *covered_twice += c > 1;
  }
  return cells;
}

// A chunk alone: its tile (may be null) and no neighbours.
absl::StatusOr<SegmentedChunk> SegmentAlone(const TileData* tile, const ChunkKey& chunk,
                                            const OctreeGrid& grid, const PlanVolume& volume,
                                            const SegmentOptions& options,
                                            const ChunkRegion* only_in = nullptr) {
  ChunkNeighbourhood hood;
  hood.grid = grid;
  hood.chunk = chunk;
  hood.tiles[ChunkNeighbourhood::Index(0, 0, 0)] = tile;
  return SegmentChunk(hood, volume, options, only_in);
}

class SegmentChunkTest : public ::testing::Test {
 protected:
  void SetUp() override {
    grid_ = *OctreeGrid::FromResolution(0.0625);
    // One room [0.25, 1.75]² with floor 0.25 and ceiling 1.75, in chunk (0, 0, 0).
    plan_ = RectanglePlan({{{0.25, 0.25}, {1.75, 1.75}, 0.25, 1.75}});
    const PlanLevelInput in{&plan_, 0, -1.0, 3.0};
    volume_ = *RasterizePlanVolume({&in, 1}, grid_.resolution_m(), 1.5);
  }

  // The chunk at the finest depth: free inside the room, solid walls, floor and ceiling, and a
  // solid box [0.75, 1.25]² × [0.25, 0.75] standing on the floor; one leaf per cell.
  TileData RoomWithBox() const {
    return FinestTile(grid_, [](const Eigen::Vector3d& c) {
      const bool in_room = Inside(c, Eigen::Vector3d::Constant(0.25), Eigen::Vector3d::Constant(1.75));
      const bool in_box = Inside(c, {0.75, 0.75, 0.25}, {1.25, 1.25, 0.75});
      return in_room && !in_box ? 0.9 : 0.2;
    });
  }

  OctreeGrid grid_;
  FloorPlan plan_;
  PlanVolume volume_;
};

TEST_F(SegmentChunkTest, ClassifiesCellsByTheOctreeAndThePlan) {
  const double r = grid_.resolution_m();
  const SegmentOptions o;
  // Free space in the room, and interior space 0.5 m outside the plan (within the 1 m buffer).
  EXPECT_EQ(ClassifyCell(volume_, {1.0, 1.0, 1.0}, true, true, false, r, o), CellSegment::kFree);
  EXPECT_EQ(ClassifyCell(volume_, {-0.25, 1.0, 1.0}, true, true, false, r, o), CellSegment::kFree);
  // §5.5: interior space more than 1 m outside the plan is trimmed; above every level it stays.
  EXPECT_EQ(ClassifyCell(volume_, {3.0, 1.0, 1.0}, true, true, false, r, o), CellSegment::kTrimmed);
  EXPECT_EQ(ClassifyCell(volume_, {3.0, 1.0, 5.0}, true, true, false, r, o), CellSegment::kFree);
  // Solid or unobserved in the room's volume: object; on the plan's walls, floor or ceiling,
  // or outside it: building.
  EXPECT_EQ(ClassifyCell(volume_, {1.0, 1.0, 1.0}, false, true, false, r, o), CellSegment::kObject);
  EXPECT_EQ(ClassifyCell(volume_, {0.28125, 1.0, 1.0}, false, true, false, r, o), CellSegment::kBuilding);
  EXPECT_EQ(ClassifyCell(volume_, {0.21875, 1.0, 1.0}, false, true, false, r, o), CellSegment::kBuilding);
  EXPECT_EQ(ClassifyCell(volume_, {1.0, 1.0, 0.28125}, false, true, false, r, o), CellSegment::kBuilding);
  EXPECT_EQ(ClassifyCell(volume_, {1.0, 1.0, 1.71875}, false, true, false, r, o), CellSegment::kBuilding);
  EXPECT_EQ(ClassifyCell(volume_, {1.0, 1.0, 0.34375}, false, true, false, r, o), CellSegment::kObject);
  EXPECT_EQ(ClassifyCell(volume_, {5.0, 1.0, 1.0}, false, true, false, r, o), CellSegment::kBuilding);
  SegmentOptions no_fill;
  no_fill.unobserved_is_object = false;
  EXPECT_EQ(ClassifyCell(volume_, {1.0, 1.0, 1.0}, false, false, false, r, o), CellSegment::kObject);
  EXPECT_EQ(ClassifyCell(volume_, {1.0, 1.0, 1.0}, false, false, false, r, no_fill),
            CellSegment::kBuilding);
}

TEST_F(SegmentChunkTest, BoxOnTheFloorBecomesObjectAndFreeSpaceForTheBuilding) {
  const TileData tile = RoomWithBox();
  absl::StatusOr<SegmentedChunk> seg =
      SegmentAlone(&tile, ChunkKey::Zero(), grid_, volume_, SegmentOptions{});
  ASSERT_TRUE(seg.ok()) << seg.status();
  // The box's cells are 8 × 8 × 8. Its bottom layer lies in the plan's floor band (§5.6:
  // volume on the plan's boundary is building), but under the box and above the floor: it
  // stands on the floor, and so is object too.
  EXPECT_EQ(seg->object_cells, 8u * 8u * 8u);
  EXPECT_EQ(seg->trimmed_cells, 0u);

  int twice = 0;
  const std::vector<LeafStats> in = Cells(tile);
  const std::vector<LeafStats> building = Cells(seg->building, &twice);
  EXPECT_EQ(twice, 0);
  const std::vector<LeafStats> objects = Cells(seg->objects, &twice);
  EXPECT_EQ(twice, 0);
  const int n = grid_.leaves_per_side();
  int object_interior = 0, building_changed = 0;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const size_t i = x + static_cast<size_t>(n) * (y + static_cast<size_t>(n) * z);
        const Eigen::Vector3d c = LeafCenter(grid_, Eigen::Vector3i(x, y, z));
        const bool object = c.x() > 0.75 && c.x() < 1.25 && c.y() > 0.75 && c.y() < 1.25 &&
                            c.z() > 0.25 && c.z() < 0.75;
        // Objects tile: interior exactly on the object cells, their p mirrored (0.2 ➜ 0.8);
        // free space mirrored to exterior (0.9 ➜ 0.1); walls unstored.
        EXPECT_EQ(objects[i].interior(), object) << c.transpose();
        if (object) {
          ++object_interior;
          EXPECT_NEAR(objects[i].p(), 0.8, 1e-9);
        } else if (in[i].interior()) {
          EXPECT_NEAR(objects[i].p(), 0.1, 1e-9);
        } else {
          EXPECT_FALSE(objects[i].observed());
        }
        // Building tile: the objects become free space; everything else as carved.
        EXPECT_EQ(building[i].interior(), in[i].interior() || object) << c.transpose();
        if (!object) {
          EXPECT_DOUBLE_EQ(building[i].p(), in[i].p());
          EXPECT_EQ(building[i].count, in[i].count);
        } else {
          ++building_changed;
        }
      }
  EXPECT_EQ(object_interior, 8 * 8 * 8);
  EXPECT_EQ(building_changed, 8 * 8 * 8);
}

// §4.2.3's point voxels: a table whose leg the wedges carved free (p = 0.9) but whose scan
// points lie in the leg's cells. The leg becomes object, joined to the top; points on the
// wall and floor stay building's free side; too few points change nothing.
TEST_F(SegmentChunkTest, ScanPointsKeepALegTheWedgesCarvedAway) {
  auto in_top = [](const Eigen::Vector3d& c) {
    return Inside(c, {0.75, 0.75, 0.75}, {1.25, 1.25, 0.8125});
  };
  auto in_leg = [](const Eigen::Vector3d& c) {  // one cell a side, floor to top
    return Inside(c, {0.75, 0.75, 0.25}, {0.8125, 0.8125, 0.75});
  };
  auto on_wall = [](const Eigen::Vector3d& c) {  // the first free layer in front of x = 0.25
    return Inside(c, {0.25, 0.5, 0.5}, {0.3125, 1.5, 1.5});
  };
  TileData tile = FinestTile(grid_, [&](const Eigen::Vector3d& c) {
    const bool in_room = Inside(c, Eigen::Vector3d::Constant(0.25), Eigen::Vector3d::Constant(1.75));
    return in_room && !in_top(c) ? 0.9 : 0.2;
  });
  auto with_points = [&](uint32_t points) {
    TileData t = tile;
    for (TileLeaf& l : t.leaves) {
      const Eigen::Vector3d c = LeafCenter(grid_, l.node.local);
      if (in_leg(c) || on_wall(c)) l.stats.points = points;
    }
    return t;
  };
  absl::StatusOr<SegmentedChunk> none =
      SegmentAlone(&tile, ChunkKey::Zero(), grid_, volume_, SegmentOptions{});
  ASSERT_TRUE(none.ok()) << none.status();
  EXPECT_EQ(none->object_cells, 8u * 8u);  // the top alone

  SegmentOptions two;
  two.min_points = 2;
  const TileData one_point = with_points(1);  // below min_points = 2
  absl::StatusOr<SegmentedChunk> few =
      SegmentAlone(&one_point, ChunkKey::Zero(), grid_, volume_, two);
  ASSERT_TRUE(few.ok()) << few.status();
  EXPECT_EQ(few->object_cells, 8u * 8u);

  const TileData points = with_points(3);
  absl::StatusOr<SegmentedChunk> seg =
      SegmentAlone(&points, ChunkKey::Zero(), grid_, volume_, two);
  ASSERT_TRUE(seg.ok()) << seg.status();
  // The leg's 8 cells, the one in the floor band too: it stands under the leg.
  EXPECT_EQ(seg->object_cells, 8u * 8u + 8u);
  const std::vector<LeafStats> objects = Cells(seg->objects);
  const int n = grid_.leaves_per_side();
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const Eigen::Vector3d c = LeafCenter(grid_, Eigen::Vector3i(x, y, z));
        const bool object = in_top(c) || in_leg(c);
        EXPECT_EQ(objects[x + size_t(n) * (y + size_t(n) * z)].interior(), object)
            << c.transpose();
      }
  SegmentOptions off;
  off.min_points = 0;
  absl::StatusOr<SegmentedChunk> ignored =
      SegmentAlone(&points, ChunkKey::Zero(), grid_, volume_, off);
  ASSERT_TRUE(ignored.ok()) << ignored.status();
  EXPECT_EQ(ignored->object_cells, 8u * 8u);
}

// The floor band under a standing object is object only where the object is above it: carved
// space under a table top stays free, and unswept air under an object above the band is not
// filled down to the floor.
TEST_F(SegmentChunkTest, TheFloorBandIsObjectOnlyUnderAnObject) {
  // A table top [0.75, 1.25]² × [0.75, 0.8125] over carved space, and beside it a box seen
  // only from above: x ∈ [1.375, 1.625], y ∈ [0.75, 1.25], solid over z ∈ [0.5, 0.75),
  // unobserved below it down to the floor.
  const TileData tile = FinestTile(grid_, [](const Eigen::Vector3d& c) {
    const bool in_room =
        Inside(c, Eigen::Vector3d::Constant(0.25), Eigen::Vector3d::Constant(1.75));
    const bool in_top = Inside(c, {0.75, 0.75, 0.75}, {1.25, 1.25, 0.8125});
    const bool in_box = Inside(c, {1.375, 0.75, 0.5}, {1.625, 1.25, 0.75});
    const bool under_box = Inside(c, {1.375, 0.75, 0.25}, {1.625, 1.25, 0.5});
    if (in_room && under_box) return -1.0;
    return in_room && !in_top && !in_box ? 0.9 : 0.2;
  });
  absl::StatusOr<SegmentedChunk> seg =
      SegmentAlone(&tile, ChunkKey::Zero(), grid_, volume_, SegmentOptions{});
  ASSERT_TRUE(seg.ok()) << seg.status();
  // The top, and the box's 4 × 8 × 4 solid cells: the unswept air under the box has free space
  // on both sides along the walls' normal, so the hidden-space test leaves it building, and the
  // floor band under it has no object above.
  EXPECT_EQ(seg->object_cells, 8u * 8u + 4u * 8u * 4u);
  EXPECT_EQ(seg->unobserved_object_cells, 0u);
}

// A floor a cell below a chunk's top: the band's lower cell is in this chunk, its upper one and
// the object over both in the chunk above, whose tile the segmentation reads across the border.
TEST_F(SegmentChunkTest, TheFloorBandReachesAcrossTheChunkAbove) {
  // One room [0.25, 1.75]² with floor 1.95 and ceiling 3.5, and a solid box
  // [0.75, 1.25]² × [1.95, 2.5] standing on it: the band holds the cells centred at 1.96875
  // (chunk 0's top layer) and 2.03125 (chunk 1's bottom layer).
  const FloorPlan plan = RectanglePlan({{{0.25, 0.25}, {1.75, 1.75}, 1.95, 3.5}});
  const PlanLevelInput in{&plan, 0, 1.0, 4.0};
  const PlanVolume volume = *RasterizePlanVolume({&in, 1}, grid_.resolution_m(), 1.5);
  auto p_at = [&](const LeafKey& cell) {
    const Eigen::Vector3d c = LeafCenter(grid_, cell);
    const bool in_room = Inside(c, {0.25, 0.25, 1.95}, {1.75, 1.75, 3.5});
    const bool in_box = Inside(c, {0.75, 0.75, 1.9}, {1.25, 1.25, 2.5});
    return in_room && !in_box ? 0.9 : 0.2;
  };
  const TileData lower = testing::FinestTileOfChunk(grid_, ChunkKey::Zero(), p_at);
  const TileData upper = testing::FinestTileOfChunk(grid_, ChunkKey(0, 0, 1), p_at);
  absl::StatusOr<SegmentedChunk> alone =
      SegmentAlone(&lower, ChunkKey::Zero(), grid_, volume, SegmentOptions{});
  ASSERT_TRUE(alone.ok()) << alone.status();
  EXPECT_EQ(alone->object_cells, 0u);  // nothing above: the chunk above is unknown
  ChunkNeighbourhood hood;
  hood.grid = grid_;
  hood.tiles[ChunkNeighbourhood::Index(0, 0, 0)] = &lower;
  hood.tiles[ChunkNeighbourhood::Index(0, 0, 1)] = &upper;
  absl::StatusOr<SegmentedChunk> seg = SegmentChunk(hood, volume, SegmentOptions{});
  ASSERT_TRUE(seg.ok()) << seg.status();
  EXPECT_EQ(seg->object_cells, 8u * 8u);  // the band's lower cell under the box
  const std::vector<LeafStats> objects = Cells(seg->objects);
  const int n = grid_.leaves_per_side();
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const Eigen::Vector3d c = LeafCenter(grid_, Eigen::Vector3i(x, y, n - 1));
      EXPECT_EQ(objects[x + size_t(n) * (y + size_t(n) * (n - 1))].interior(),
                Inside(c, {0.75, 0.75, 1.9}, {1.25, 1.25, 2.5}))
          << c.transpose();
    }
  // And the chunk above, with this one below it: its band cell and the box.
  ChunkNeighbourhood above;
  above.grid = grid_;
  above.chunk = ChunkKey(0, 0, 1);
  above.tiles[ChunkNeighbourhood::Index(0, 0, 0)] = &upper;
  above.tiles[ChunkNeighbourhood::Index(0, 0, -1)] = &lower;
  absl::StatusOr<SegmentedChunk> top = SegmentChunk(above, volume, SegmentOptions{});
  ASSERT_TRUE(top.ok()) << top.status();
  EXPECT_EQ(top->object_cells, 8u * 8u * 8u);  // z from 2.0 to 2.5
}

// A wall's points lie in the free layer in front of it: point cells keep point_wall_margin_m
// more from the plan's walls than solid cells.
TEST_F(SegmentChunkTest, PointCellsKeepAMarginFromThePlansWalls) {
  const double r = grid_.resolution_m();
  // A cell 0.125–0.1875 m from the wall at x = 0.25: far enough for a solid cell.
  const Eigen::Vector3d c(0.40625, 1.03125, 1.03125);
  EXPECT_EQ(ClassifyCell(volume_, c, false, true, false, r, SegmentOptions{}), CellSegment::kObject);
  SegmentOptions none, wide;
  none.point_wall_margin_m = 0;
  wide.point_wall_margin_m = 0.2;
  EXPECT_EQ(ClassifyCell(volume_, c, true, true, true, r, none), CellSegment::kObject);
  EXPECT_EQ(ClassifyCell(volume_, c, true, true, true, r, wide), CellSegment::kFree);
  // The margin is from the walls only: a point cell one cell above the floor's tolerance.
  EXPECT_EQ(ClassifyCell(volume_, {1.0, 1.0, 0.34375}, true, true, true, r, wide),
            CellSegment::kObject);
}

// On a finer grid the points count over cubes of point_cell_m: a scan's points are a few cm
// apart, so on a 1.5625 cm grid one finest cell in four along a leg holds one.
TEST_F(SegmentChunkTest, PointsCountOverCubesOfPointCellSize) {
  const OctreeGrid fine = *OctreeGrid::FromResolution(0.015625);
  const PlanLevelInput in{&plan_, 0, -1.0, 3.0};
  const PlanVolume volume = *RasterizePlanVolume({&in, 1}, fine.resolution_m(), 1.5);
  TileData tile;
  tile.grid = fine;
  // Free space in the room as one leaf per 6.25 cm cube except the cube [1, 1.0625)³, whose 64
  // finest cells are leaves; two of them hold a point each.
  const int k = fine.chunk_depth;
  for (int z = 0; z < 32; ++z)
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 32; ++x) {
        const Eigen::Vector3d c = (Eigen::Vector3d(x, y, z).array() + 0.5) * 0.0625;
        if (!Inside(c, Eigen::Vector3d::Constant(0.25), Eigen::Vector3d::Constant(1.75))) continue;
        if (x == 16 && y == 16 && z == 16) {
          for (int i = 0; i < 64; ++i) {
            TileLeaf l{ChunkNode{Eigen::Vector3i(64 + (i & 3), 64 + ((i >> 2) & 3), 64 + (i >> 4)), k},
                       WithP(0.9)};
            l.stats.points = (i == 0 || i == 63) ? 1 : 0;
            tile.leaves.push_back(l);
          }
          continue;
        }
        tile.leaves.push_back(TileLeaf{ChunkNode{Eigen::Vector3i(x, y, z), k - 2}, WithP(0.9)});
      }
  SortTileLeaves(fine, tile.leaves);
  SegmentOptions cubes;
  cubes.min_points = 2;
  cubes.point_cell_m = 0.0625;
  absl::StatusOr<SegmentedChunk> seg =
      SegmentAlone(&tile, ChunkKey::Zero(), fine, volume, cubes);
  ASSERT_TRUE(seg.ok()) << seg.status();
  EXPECT_EQ(seg->object_cells, 64u);  // the whole cube, from 2 points
  cubes.point_cell_m = 0.03125;  // 2 × 2 × 2 cells, one point each in two of them
  absl::StatusOr<SegmentedChunk> smaller =
      SegmentAlone(&tile, ChunkKey::Zero(), fine, volume, cubes);
  ASSERT_TRUE(smaller.ok()) << smaller.status();
  EXPECT_EQ(smaller->object_cells, 0u);
  cubes.min_points = 1;  // the two 8-cell cubes holding a point
  smaller = SegmentAlone(&tile, ChunkKey::Zero(), fine, volume, cubes);
  ASSERT_TRUE(smaller.ok()) << smaller.status();
  EXPECT_EQ(smaller->object_cells, 16u);
  SegmentOptions per_cell;
  per_cell.min_points = 2;
  per_cell.point_cell_m = fine.resolution_m();
  absl::StatusOr<SegmentedChunk> fine_cells =
      SegmentAlone(&tile, ChunkKey::Zero(), fine, volume, per_cell);
  ASSERT_TRUE(fine_cells.ok()) << fine_cells.status();
  EXPECT_EQ(fine_cells->object_cells, 0u);  // one point per cell < min_points
}

// §5.6.1: the region to carve again holds the object, a cell around it, and the column down
// to the floor; segmenting inside a region finds objects only there.
TEST_F(SegmentChunkTest, RecarveRegionCoversTheObjectDownToTheFloor) {
  // A table top [0.75, 1.25]² × [0.75, 0.8125] on legs too thin for the grid: the coarse octree
  // saw only the top, which floats 0.5 m above the floor.
  const TileData tile = FinestTile(grid_, [](const Eigen::Vector3d& c) {
    const bool in_room = Inside(c, Eigen::Vector3d::Constant(0.25), Eigen::Vector3d::Constant(1.75));
    const bool in_top = Inside(c, {0.75, 0.75, 0.75}, {1.25, 1.25, 0.8125});
    return in_room && !in_top ? 0.9 : 0.2;
  });
  absl::StatusOr<SegmentedChunk> seg =
      SegmentAlone(&tile, ChunkKey::Zero(), grid_, volume_, SegmentOptions{});
  ASSERT_TRUE(seg.ok()) << seg.status();
  ASSERT_EQ(seg->object_cells, 8u * 8u);
  const ChunkRegion region = ObjectRecarveRegion(seg->objects, volume_, 1);
  EXPECT_EQ(region.depth(), grid_.chunk_depth);
  const double r = grid_.resolution_m();
  auto cell = [&](double x, double y, double z) {
    return ChunkNode{Eigen::Vector3i(int(x / r), int(y / r), int(z / r)), grid_.chunk_depth};
  };
  EXPECT_TRUE(region.Intersects(cell(1.0, 1.0, 0.78)));   // the top
  EXPECT_TRUE(region.Intersects(cell(0.72, 1.0, 0.78)));  // a cell beside it
  EXPECT_TRUE(region.Intersects(cell(0.77, 0.77, 0.3)));  // under it, where legs would be
  EXPECT_TRUE(region.Intersects(cell(1.0, 1.0, 0.22)));   // down to the floor (and a cell)
  EXPECT_FALSE(region.Intersects(cell(1.0, 1.0, 0.9)));   // two cells above
  EXPECT_FALSE(region.Intersects(cell(0.6, 1.0, 0.5)));   // two cells beside
  EXPECT_FALSE(region.Intersects(cell(1.5, 1.5, 0.5)));
  // (8 + 2)² columns from the floor cell below (z index 3) to one cell above the top (13).
  EXPECT_EQ(region.count(), 10u * 10u * 11u);
  // No object cells, no region.
  TileData empty = seg->objects;
  empty.leaves.clear();
  EXPECT_TRUE(ObjectRecarveRegion(empty, volume_, 1).empty());

  // Only inside a region: the box of RoomWithBox with a region holding its lower half.
  const TileData box = RoomWithBox();
  std::vector<Eigen::Vector3i> lower;
  for (int z = 0; z < 8; ++z)
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 32; ++x) lower.emplace_back(x, y, z);  // z < 0.5 m
  const ChunkRegion half(5, lower);
  absl::StatusOr<SegmentedChunk> limited =
      SegmentAlone(&box, ChunkKey::Zero(), grid_, volume_, SegmentOptions{}, &half);
  ASSERT_TRUE(limited.ok()) << limited.status();
  EXPECT_EQ(limited->object_cells, 8u * 8u * 4u);  // z cells 4..7 of the box's 4..11
  const ChunkRegion nothing;
  limited = SegmentAlone(&box, ChunkKey::Zero(), grid_, volume_, SegmentOptions{}, &nothing);
  ASSERT_TRUE(limited.ok()) << limited.status();
  EXPECT_EQ(limited->object_cells, 0u);
}

// A lamp's shade hanging under the ceiling on a rod too thin for the grid: the region reaches
// up its column to the ceiling only when the shade is within ceiling_reach_m of it.
TEST_F(SegmentChunkTest, RecarveRegionReachesUpToTheCeilingOverHangingObjects) {
  // The shade [0.75, 1.25]² × [1.375, 1.5] under the ceiling at 1.75 (0.25 m above its top).
  const TileData tile = FinestTile(grid_, [](const Eigen::Vector3d& c) {
    const bool in_room = Inside(c, Eigen::Vector3d::Constant(0.25), Eigen::Vector3d::Constant(1.75));
    const bool in_shade = Inside(c, {0.75, 0.75, 1.375}, {1.25, 1.25, 1.5});
    return in_room && !in_shade ? 0.9 : 0.2;
  });
  absl::StatusOr<SegmentedChunk> seg =
      SegmentAlone(&tile, ChunkKey::Zero(), grid_, volume_, SegmentOptions{});
  ASSERT_TRUE(seg.ok()) << seg.status();
  ASSERT_EQ(seg->object_cells, 8u * 8u * 2u);
  const double r = grid_.resolution_m();
  auto cell = [&](double x, double y, double z) {
    return ChunkNode{Eigen::Vector3i(int(x / r), int(y / r), int(z / r)), grid_.chunk_depth};
  };
  const ChunkRegion near = ObjectRecarveRegion(seg->objects, volume_, 1, 0.3);
  EXPECT_TRUE(near.Intersects(cell(1.0, 1.0, 1.7)));    // the rod's cell under the ceiling
  EXPECT_TRUE(near.Intersects(cell(1.0, 1.0, 1.78)));   // the ceiling's own cell
  EXPECT_TRUE(near.Intersects(cell(0.72, 1.0, 1.7)));   // and a cell around the column
  EXPECT_FALSE(near.Intersects(cell(0.6, 1.0, 1.7)));   // not two
  EXPECT_FALSE(near.Intersects(cell(1.0, 1.0, 1.9)));   // not above the ceiling's cell and one
  // 0.25 m to the ceiling is farther than 0.2 m: up to one cell above the shade only.
  const ChunkRegion far = ObjectRecarveRegion(seg->objects, volume_, 1, 0.2);
  EXPECT_TRUE(far.Intersects(cell(1.0, 1.0, 1.53)));
  EXPECT_FALSE(far.Intersects(cell(1.0, 1.0, 1.6)));
  EXPECT_GT(near.count(), far.count());
}

TEST_F(SegmentChunkTest, LeavesSplitOnlyWhereTheClassChanges) {
  // One observed solid leaf over the whole chunk: the room's volume inside it is object.
  TileData tile;
  tile.grid = grid_;
  tile.leaves.push_back(TileLeaf{ChunkNode{Eigen::Vector3i::Zero(), 0}, WithP(0.2)});
  absl::StatusOr<SegmentedChunk> seg =
      SegmentAlone(&tile, ChunkKey::Zero(), grid_, volume_, SegmentOptions{});
  ASSERT_TRUE(seg.ok()) << seg.status();
  uint64_t expected = 0;  // counted with the rule itself, top down for the floor band
  const int n = grid_.leaves_per_side();
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      bool above = false;
      for (int z = n - 1; z >= 0; --z) {
        above =
            ClassifyCell(volume_, LeafCenter(grid_, Eigen::Vector3i(x, y, z)), false, true, false,
                         grid_.resolution_m(), SegmentOptions{}, above) == CellSegment::kObject;
        expected += above;
      }
    }
  EXPECT_GT(expected, 1000u);
  EXPECT_EQ(seg->object_cells, expected);
  EXPECT_EQ(seg->unobserved_object_cells, 0u);
  // Far fewer leaves than cells: uniform octants stay whole.
  EXPECT_LT(seg->objects.leaves.size(), expected / 3);
  int twice = 0;
  const std::vector<LeafStats> cells = Cells(seg->building, &twice);
  EXPECT_EQ(twice, 0);
  for (const LeafStats& c : cells) EXPECT_TRUE(c.observed());  // the chunk stays covered
  for (const TileLeaf& l : seg->objects.leaves) {
    EXPECT_TRUE(l.stats.interior());
    EXPECT_NEAR(l.stats.p(), 0.8, 1e-12);
  }
}

TEST_F(SegmentChunkTest, UnobservedSpaceIsObjectOnlyWhenHiddenBehindSolid) {
  // The room is free space except: a shelf's seen front, solid, x ∈ [0.5, 1.5], y ∈ [0.75,
  // 0.875), z ∈ [0.25, 1.25), with unswept (unobserved) space between it and the south wall;
  // and unswept air in front of the empty north wall (y ∈ [1.375, 1.75)) with free space
  // before it.
  const TileData tile = FinestTile(grid_, [](const Eigen::Vector3d& c) {
    const bool in_room = Inside(c, Eigen::Vector3d::Constant(0.25), Eigen::Vector3d::Constant(1.75));
    const bool shelf_x = c.x() > 0.5 && c.x() < 1.5 && c.z() < 1.25;
    const bool front = shelf_x && c.y() > 0.75 && c.y() < 0.875;
    const bool behind = shelf_x && c.y() < 0.75;
    const bool air = c.x() > 0.5 && c.x() < 1.5 && c.y() > 1.375;
    if (in_room && (behind || air)) return -1.0;  // unobserved
    return in_room && !front ? 0.9 : 0.2;
  });
  const int n = grid_.leaves_per_side();
  absl::StatusOr<SegmentedChunk> seg =
      SegmentAlone(&tile, ChunkKey::Zero(), grid_, volume_, SegmentOptions{});
  ASSERT_TRUE(seg.ok()) << seg.status();
  const std::vector<LeafStats> objects = Cells(seg->objects);
  int hidden = 0, front = 0, air = 0;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const Eigen::Vector3d c = LeafCenter(grid_, Eigen::Vector3i(x, y, z));
        if (!objects[x + n * (y + n * z)].interior()) continue;
        if (c.y() > 1.375) ++air;
        else if (c.y() > 0.75) ++front;
        else ++hidden;
      }
  EXPECT_EQ(air, 0);
  // The front: x cells 8..23 (16), z cells 4..19 (16; the floor band's cell under it too).
  EXPECT_EQ(front, 16 * 2 * 16);
  // Behind it, down to the wall band (y cells 6..11 of 4..11: the two nearest the wall are
  // building): 16 × 6 × 16, less those near the shelf's west end that are nearer the west wall
  // than the south one: their line of sight runs along x, through the hidden space to free
  // space past the shelf's east end (the rule's known blind spot in corners).
  EXPECT_LE(hidden, 16 * 6 * 16);
  EXPECT_GT(hidden, 0.75 * 16 * 6 * 16);
  EXPECT_EQ(seg->unobserved_object_cells, static_cast<uint64_t>(hidden));
  // Without the fill, unobserved space is never object.
  SegmentOptions no_fill;
  no_fill.unobserved_is_object = false;
  seg = SegmentAlone(&tile, ChunkKey::Zero(), grid_, volume_, no_fill);
  ASSERT_TRUE(seg.ok());
  EXPECT_EQ(seg->unobserved_object_cells, 0u);
  EXPECT_EQ(seg->object_cells, 16u * 2u * 16u);
}

TEST_F(SegmentChunkTest, InteriorFarOutsideThePlanIsTrimmed) {
  // Chunk (2, 0, 0) spans x ∈ [4, 6): at least 2.25 m from the room. One interior leaf.
  TileData tile;
  tile.grid = grid_;
  tile.chunk = ChunkKey(2, 0, 0);
  tile.leaves.push_back(TileLeaf{ChunkNode{Eigen::Vector3i::Zero(), 0}, WithP(0.9)});
  absl::StatusOr<SegmentedChunk> seg =
      SegmentAlone(&tile, tile.chunk, grid_, volume_, SegmentOptions{});
  ASSERT_TRUE(seg.ok()) << seg.status();
  const uint64_t n = grid_.leaves_per_side();
  EXPECT_EQ(seg->trimmed_cells, n * n * n);
  ASSERT_EQ(seg->building.leaves.size(), 1u);
  EXPECT_FALSE(seg->building.leaves[0].stats.interior());
  EXPECT_NEAR(seg->building.leaves[0].stats.p(), 0.1, 1e-9);
  EXPECT_TRUE(seg->objects.leaves.empty());
  // A wider buffer keeps it (the raster must reach past the buffer).
  SegmentOptions wide;
  wide.trim_distance_m = 5;
  const PlanLevelInput in{&plan_, 0, -1.0, 3.0};
  const PlanVolume far = *RasterizePlanVolume({&in, 1}, grid_.resolution_m(), 6.0);
  seg = SegmentAlone(&tile, tile.chunk, grid_, far, wide);
  ASSERT_TRUE(seg.ok());
  EXPECT_EQ(seg->trimmed_cells, 0u);
  EXPECT_TRUE(seg->building.leaves[0].stats.interior());
}

TEST_F(SegmentChunkTest, RejectsAMismatchedTileAndBadOptions) {
  TileData tile;
  tile.grid = grid_;
  tile.chunk = ChunkKey(1, 0, 0);
  absl::StatusOr<SegmentedChunk> seg =
      SegmentAlone(&tile, ChunkKey::Zero(), grid_, volume_, SegmentOptions{});
  ASSERT_TRUE(absl::IsInvalidArgument(seg.status()));
  EXPECT_NE(seg.status().message().find("chunk"), std::string::npos);
  SegmentOptions bad;
  bad.trim_distance_m = -1;
  EXPECT_TRUE(absl::IsInvalidArgument(
      SegmentAlone(nullptr, ChunkKey::Zero(), grid_, volume_, bad).status()));
  bad = SegmentOptions{};
  bad.plan_tolerance_m = std::nan("");
  EXPECT_TRUE(absl::IsInvalidArgument(
      SegmentAlone(nullptr, ChunkKey::Zero(), grid_, volume_, bad).status()));
}

}  // namespace
}  // namespace carvemap

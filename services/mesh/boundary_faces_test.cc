#include "services/mesh/boundary_faces.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <random>
#include <set>
#include <tuple>

#include <gtest/gtest.h>

#include "services/mesh/mesh_test_util.h"

namespace carvemap {
namespace {

using testing::AddLeaf;
using testing::HoodOf;
using testing::StatsWithP;
using testing::Tiles;

std::vector<BoundaryFace> AllFaces(const Tiles& tiles, const OctreeGrid& grid) {
  std::vector<BoundaryFace> all;
  for (const auto& [chunk, tile] : tiles) {
    auto faces = ChunkBoundaryFaces(HoodOf(tiles, grid, chunk));
    EXPECT_TRUE(faces.ok()) << faces.status();
    if (faces.ok()) all.insert(all.end(), faces->begin(), faces->end());
  }
  return all;
}

// Brute force on the finest grid: label of every cell from the tiles (no tile row: exterior).
struct DenseLabels {
  std::map<std::tuple<int, int, int>, bool> interior;
  bool At(const LeafKey& c) const {
    auto it = interior.find({c.x(), c.y(), c.z()});
    return it != interior.end() && it->second;
  }
};
DenseLabels Densify(const Tiles& tiles, const OctreeGrid& grid) {
  DenseLabels d;
  const int n = grid.leaves_per_side(), k = grid.chunk_depth;
  for (const auto& [chunk, tile] : tiles) {
    for (const TileLeaf& l : tile.leaves) {
      const int s = 1 << (k - l.node.depth);
      const LeafKey lo = chunk * n + l.node.local * s;
      for (int z = 0; z < s; ++z)
        for (int y = 0; y < s; ++y)
          for (int x = 0; x < s; ++x)
            d.interior[{lo.x() + x, lo.y() + y, lo.z() + z}] = l.stats.interior();
    }
  }
  return d;
}

// Finest faces as (interior cell, direction 0..5 towards the exterior).
using FinestFace = std::tuple<int, int, int, int>;
std::multiset<FinestFace> BruteForceFaces(const DenseLabels& d) {
  std::multiset<FinestFace> out;
  for (const auto& [c, in] : d.interior) {
    if (!in) continue;
    const LeafKey cell(std::get<0>(c), std::get<1>(c), std::get<2>(c));
    for (int dir = 0; dir < 6; ++dir) {
      LeafKey nb = cell;
      nb[dir / 2] += (dir % 2) ? 1 : -1;
      if (!d.At(nb)) out.insert({cell.x(), cell.y(), cell.z(), dir});
    }
  }
  return out;
}

// Expands faces into the finest faces they cover.
std::multiset<FinestFace> Expand(const std::vector<BoundaryFace>& faces, const OctreeGrid& grid) {
  std::multiset<FinestFace> out;
  const double res = grid.resolution_m();
  for (const BoundaryFace& f : faces) {
    const int a = f.axis, u = (a + 1) % 3, w = (a + 2) % 3;
    const int cells = static_cast<int>(std::lround(f.size_m / res));
    const int towards_ext = f.sign < 0 ? 1 : -1;
    LeafKey lo;
    lo[a] = static_cast<int>(std::lround(f.center[a] / res)) - (towards_ext > 0 ? 1 : 0);
    lo[u] = static_cast<int>(std::lround(f.center[u] / res - 0.5 * cells));
    lo[w] = static_cast<int>(std::lround(f.center[w] / res - 0.5 * cells));
    for (int j = 0; j < cells; ++j) {
      for (int i = 0; i < cells; ++i) {
        LeafKey c = lo;
        c[u] += i;
        c[w] += j;
        out.insert({c.x(), c.y(), c.z(), 2 * a + (towards_ext > 0 ? 1 : 0)});
      }
    }
  }
  return out;
}

TEST(IsosurfaceOffset, HandComputedCasesOfFig49) {
  const double c = 1.0, h = 0.5;  // a finest cell, half of it
  EXPECT_NEAR(IsosurfaceOffsetM(0.9, 0.1, c, 10), 0.0, 1e-12);       // symmetric: midway
  EXPECT_NEAR(IsosurfaceOffsetM(0.7, 0.1, c, 10), -h / 3, 1e-12);     // t = 1/3
  EXPECT_NEAR(IsosurfaceOffsetM(0.9, 0.4, c, 10), 0.3, 1e-12);        // t = 0.8
  EXPECT_NEAR(IsosurfaceOffsetM(0.9, 0.5, c, 10), h, 1e-12);          // unobserved: ext centre
  EXPECT_NEAR(IsosurfaceOffsetM(0.9, 0.5, c, 0.45), 0.45, 1e-12);     // ... clamped
  EXPECT_NEAR(IsosurfaceOffsetM(0.5000001, 0.0, c, 0.45), -0.45, 1e-12);
}

class BoxRoom : public ::testing::TestWithParam<int> {};

// A box of interior cells [lo, hi) made of mixed leaf sizes (a big interior node in the middle
// of finest ones), inside exterior leaves and unobserved space, across chunk borders.
TEST_P(BoxRoom, AreaCountAndOffsetsMatchTheBox) {
  OctreeGrid grid;
  grid.chunk_depth = 3;  // 8 cells per chunk, 25 cm
  const double res = grid.resolution_m();
  const int lo = -4, hi = 8;  // 12 cells on each axis, spanning chunks −1 and 0
  const bool exterior_shell = GetParam() == 1;
  Tiles tiles;
  for (int z = lo - 1; z < hi + 1; ++z) {
    for (int y = lo - 1; y < hi + 1; ++y) {
      for (int x = lo - 1; x < hi + 1; ++x) {
        const bool inside = x >= lo && x < hi && y >= lo && y < hi && z >= lo && z < hi;
        // The 4³ block [0, 4)³ is one depth-1 leaf (interior).
        const bool in_big = x >= 0 && x < 4 && y >= 0 && y < 4 && z >= 0 && z < 4;
        if (in_big) continue;
        if (inside) {
          AddLeaf(tiles, grid, LeafKey(x, y, z), 3, 0.9);
        } else if (exterior_shell) {
          AddLeaf(tiles, grid, LeafKey(x, y, z), 3, 0.3);
        }
      }
    }
  }
  AddLeaf(tiles, grid, LeafKey(0, 0, 0), 1, 0.8);
  // A big exterior node far away: no faces with it.
  AddLeaf(tiles, grid, LeafKey(-16, -16, -16), 0, 0.1);
  const std::vector<BoundaryFace> faces = AllFaces(tiles, grid);
  const int side = hi - lo;
  EXPECT_EQ(faces.size(), 6u * side * side);
  double area = 0;
  for (const BoundaryFace& f : faces) {
    area += f.area_m2();
    EXPECT_EQ(f.exterior_observed, exterior_shell);
    EXPECT_EQ(f.exterior_weight, exterior_shell ? 1.5f : 0.0f);  // StatsWithP: Σ w = 1.5
    EXPECT_NEAR(f.size_m, res, 1e-12);
    // normal points into the box
    const double offset = (f.isosurface() - f.center).dot(f.normal().cast<double>());
    // Fig 4.9 with p_i = 0.9 at −res/2, p_e = 0.3 at +res/2: t = 0.4/0.6, x = res/6 outwards;
    // unobserved (0.5): the exterior centre, clamped to 0.45 res.
    const double expected = exterior_shell ? res / 6 : 0.45 * res;
    EXPECT_NEAR(-offset, expected, 1e-9);
    EXPECT_NEAR((f.isosurface() - f.center).norm(), expected, 1e-9);
  }
  EXPECT_NEAR(area, 6.0 * side * side * res * res, 1e-9);
  EXPECT_EQ(Expand(faces, grid), BruteForceFaces(Densify(tiles, grid)));
}
INSTANTIATE_TEST_SUITE_P(Exterior, BoxRoom, ::testing::Values(0, 1));

TEST(BoundaryFaces, BigInteriorNextToSmallExteriorGivesOneFacePerSmallNeighbour) {
  OctreeGrid grid;
  grid.chunk_depth = 2;  // 4 cells per chunk, 50 cm
  Tiles tiles;
  AddLeaf(tiles, grid, LeafKey(0, 0, 0), 1, 0.9);  // 2×2×2 cells, interior, half = 0.5 m
  // Across +x: four finest exterior leaves with different p.
  const double ps[4] = {0.1, 0.3, 0.45, 0.5};
  for (int j = 0; j < 4; ++j) AddLeaf(tiles, grid, LeafKey(2, j & 1, j >> 1), 2, ps[j]);
  // Across +y: one leaf as big as the interior one, p = 0.2 (t = 0.4/0.7 over the finest cells).
  AddLeaf(tiles, grid, LeafKey(0, 2, 0), 1, 0.2);
  auto faces = ChunkBoundaryFaces(HoodOf(tiles, grid, ChunkKey(0, 0, 0)));
  ASSERT_TRUE(faces.ok()) << faces.status();
  int plus_x = 0, plus_y = 0, others = 0;
  for (const BoundaryFace& f : *faces) {
    if (f.axis == 0 && f.center.x() > 0.9) {
      ++plus_x;
      EXPECT_NEAR(f.size_m, 0.5, 1e-12);
      EXPECT_EQ(f.normal(), Eigen::Vector3f(-1, 0, 0));
      EXPECT_TRUE(f.exterior_observed);
      // Each leaf's p at its finest cell beside the face (0.25 m either side), not at the
      // 1 m interior leaf's centre: IsosurfaceOffsetM.
      const int j = static_cast<int>(f.center.y() / 0.5) + 2 * static_cast<int>(f.center.z() / 0.5);
      const double pe = ps[j];
      const double t = (0.9 - 0.5) / (0.9 - pe);
      const double x = std::clamp(-0.25 + 0.5 * t, -0.45 * 0.5, 0.45 * 0.5);
      EXPECT_NEAR(f.isosurface().x(), 1.0 + x, 1e-9) << pe;
    } else if (f.axis == 1 && f.center.y() > 0.9) {
      ++plus_y;
      EXPECT_NEAR(f.size_m, 1.0, 1e-12);
      EXPECT_NEAR(f.isosurface().y(), 1.0 + (-0.25 + 0.5 * 0.4 / 0.7), 1e-9);
      EXPECT_NEAR(f.center.x(), 0.5, 1e-12);
      EXPECT_NEAR(f.center.z(), 0.5, 1e-12);
    } else {
      ++others;
      EXPECT_NEAR(f.size_m, 1.0, 1e-12);  // unobserved neighbours, as big as the leaf
      EXPECT_FALSE(f.exterior_observed);
    }
  }
  EXPECT_EQ(plus_x, 4);
  EXPECT_EQ(plus_y, 1);
  EXPECT_EQ(others, 4);
}

TEST(BoundaryFaces, UnobservedNeighbourIsTheMaximalUnobservedNode) {
  OctreeGrid grid;
  grid.chunk_depth = 3;
  Tiles tiles;
  AddLeaf(tiles, grid, LeafKey(0, 0, 0), 3, 0.9);  // one finest interior cell at the corner
  const ChunkNeighbourhood hood = HoodOf(tiles, grid, ChunkKey(0, 0, 0));
  auto faces = ChunkBoundaryFaces(hood);
  ASSERT_TRUE(faces.ok()) << faces.status();
  ASSERT_EQ(faces->size(), 6u);
  auto index = NeighbourhoodIndex::Build(hood);
  ASSERT_TRUE(index.ok()) << index.status();
  for (const BoundaryFace& f : *faces) {
    EXPECT_FALSE(f.exterior_observed);
    EXPECT_EQ(f.exterior_weight, 0.0f);
    EXPECT_NEAR(f.size_m, grid.resolution_m(), 1e-12);
    const bool outside_chunk = f.sign > 0;  // the exterior on the −axis side: the chunk below
    LeafKey across(0, 0, 0);
    across[f.axis] = outside_chunk ? -1 : 1;
    const OctreeLeafRef ext = index->LeafAt(across);
    EXPECT_FALSE(ext.stored);
    // Below: a chunk without a tile, unobserved as a whole; inside: the 1-cell sibling.
    EXPECT_EQ(ext.depth, outside_chunk ? 0 : 3) << int{f.axis};
  }
  // Sorted by axis, then min corner.
  for (size_t i = 1; i < faces->size(); ++i) {
    EXPECT_LE((*faces)[i - 1].axis, (*faces)[i].axis);
  }
}

TEST(BoundaryFaces, RandomTilesGiveEveryFinestFaceOnce) {
  std::mt19937 rng(301);
  for (int trial = 0; trial < 4; ++trial) {
    OctreeGrid grid;
    grid.chunk_depth = 3;
    Tiles tiles;
    // A 2×2×2 block of random chunks, one missing.
    for (int j = 0; j < 8; ++j) {
      const ChunkKey c(j & 1, (j >> 1) & 1, (j >> 2) & 1);
      if (j == 5) continue;
      testing::GrowRandomTile(rng, grid, c, 0.05, 0.35, 0.25, tiles);
    }
    const std::vector<BoundaryFace> faces = AllFaces(tiles, grid);
    const auto expected = BruteForceFaces(Densify(tiles, grid));
    ASSERT_GT(expected.size(), 100u);
    EXPECT_EQ(Expand(faces, grid), expected) << "trial " << trial;
    for (const BoundaryFace& f : faces) {
      const double off = (f.isosurface() - f.center).norm();
      EXPECT_LE(off, 0.45 * grid.resolution_m() + 1e-12);
      EXPECT_EQ(f.exterior_observed, f.exterior_weight > 0);
    }
  }
}

TEST(BoundaryFaces, TileInTheWrongSlotIsInvalidArgument) {
  OctreeGrid grid;
  grid.chunk_depth = 3;
  Tiles tiles;
  AddLeaf(tiles, grid, LeafKey(0, 0, 0), 3, 0.9);
  ChunkNeighbourhood hood = HoodOf(tiles, grid, ChunkKey(0, 0, 0));
  hood.tiles[ChunkNeighbourhood::Index(1, 0, 0)] = hood.tiles[13];
  auto faces = ChunkBoundaryFaces(hood);
  EXPECT_EQ(faces.status().code(), absl::StatusCode::kInvalidArgument);
  TileData overlapping = tiles.begin()->second;
  overlapping.leaves.push_back(TileLeaf{ChunkNode{Eigen::Vector3i::Zero(), 1}, StatsWithP(0.2)});
  hood = ChunkNeighbourhood{grid, ChunkKey(0, 0, 0), {}};
  hood.tiles[13] = &overlapping;
  EXPECT_EQ(ChunkBoundaryFaces(hood).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace carvemap

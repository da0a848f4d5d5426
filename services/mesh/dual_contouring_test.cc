#include "services/mesh/dual_contouring.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <random>
#include <set>
#include <tuple>

#include <gtest/gtest.h>

#include "services/mesh/mesh_checks.h"
#include "services/mesh/mesh_test_util.h"

namespace carvemap {
namespace {

using testing::AddLeaf;
using testing::HoodOf;
using testing::StatsWithP;
using testing::Tiles;

struct Meshed {
  TriangleMesh mesh;
  std::vector<ChunkMesh> chunks;
};

Meshed MeshAll(const Tiles& tiles, const OctreeGrid& grid) {
  std::vector<ChunkKey> keys;
  for (const auto& [c, t] : tiles) keys.push_back(c);
  Meshed out;
  for (const ChunkKey& c : DenseMeshChunks(keys)) {
    auto m = DualContourChunk(HoodOf(tiles, grid, c));
    EXPECT_TRUE(m.ok()) << m.status();
    if (m.ok()) out.chunks.push_back(*std::move(m));
  }
  ChunkMeshWelder welder(grid.leaves_per_side());
  for (const ChunkMesh& c : out.chunks) EXPECT_TRUE(welder.Add(c).ok());
  absl::StatusOr<TriangleMesh> welded = welder.Finish();
  EXPECT_TRUE(welded.ok()) << welded.status();
  if (welded.ok()) out.mesh = *std::move(welded);
  return out;
}

// The weld as plainly as it can be written, to check ChunkMeshWelder against: every chunk's
// vertices in one map by key (the first chunk's copy kept), numbered in key order, then each
// chunk's triangles in chunk order.
TriangleMesh ReferenceWeld(const std::vector<ChunkMesh>& chunks,
                           std::vector<uint8_t>* vertex_observed) {
  std::map<MeshVertexKey, std::pair<Eigen::Vector3f, uint8_t>> vertices;
  for (const ChunkMesh& c : chunks) {
    for (size_t i = 0; i < c.vertex_keys.size(); ++i) {
      const uint8_t observed = i < c.vertex_observed.size() ? c.vertex_observed[i] : 0;
      vertices.try_emplace(c.vertex_keys[i], c.vertex_positions[i].cast<float>(), observed);
    }
  }
  TriangleMesh mesh;
  std::map<MeshVertexKey, int> index;
  vertex_observed->clear();
  for (const auto& [key, v] : vertices) {
    index[key] = static_cast<int>(mesh.vertices.size());
    mesh.vertices.push_back(v.first);
    vertex_observed->push_back(v.second);
  }
  for (const ChunkMesh& c : chunks) {
    for (const Eigen::Vector3i& t : c.triangles) {
      mesh.triangles.emplace_back(index.at(c.vertex_keys[t[0]]), index.at(c.vertex_keys[t[1]]),
                                  index.at(c.vertex_keys[t[2]]));
    }
  }
  return mesh;
}

// Σ over triangles of v0 · (v1 × v2) / 6: the enclosed volume, positive for outward normals.
double SignedVolume(const TriangleMesh& m) {
  double v = 0;
  for (const auto& t : m.triangles) {
    v += m.vertices[t[0]].cast<double>().dot(
             m.vertices[t[1]].cast<double>().cross(m.vertices[t[2]].cast<double>())) / 6;
  }
  return v;
}

// Interior cells of the tiles (finest), and the number of finest boundary faces.
std::set<std::tuple<int, int, int>> InteriorCells(const Tiles& tiles, const OctreeGrid& grid) {
  std::set<std::tuple<int, int, int>> in;
  const int n = grid.leaves_per_side(), k = grid.chunk_depth;
  for (const auto& [chunk, tile] : tiles) {
    for (const TileLeaf& l : tile.leaves) {
      if (!l.stats.interior()) continue;
      const int s = 1 << (k - l.node.depth);
      const LeafKey lo = chunk * n + l.node.local * s;
      for (int z = 0; z < s; ++z)
        for (int y = 0; y < s; ++y)
          for (int x = 0; x < s; ++x) in.insert({lo.x() + x, lo.y() + y, lo.z() + z});
    }
  }
  return in;
}
size_t FinestFaceCount(const std::set<std::tuple<int, int, int>>& in) {
  size_t n = 0;
  for (const auto& [x, y, z] : in) {
    for (int d = 0; d < 6; ++d) {
      int c[3] = {x, y, z};
      c[d / 2] += (d % 2) ? 1 : -1;
      n += !in.count({c[0], c[1], c[2]});
    }
  }
  return n;
}
size_t FaceVertexCount(const std::vector<ChunkMesh>& chunks) {
  std::set<MeshVertexKey> keys;
  for (const ChunkMesh& c : chunks) {
    for (const MeshVertexKey& k : c.vertex_keys) {
      if (k.v[3] < 3) keys.insert(k);
    }
  }
  return keys.size();
}

TEST(DualContouring, LoneCellIsAnOctahedronFacingInwards) {
  OctreeGrid grid;
  grid.chunk_depth = 3;
  const double res = grid.resolution_m();
  Tiles tiles;
  AddLeaf(tiles, grid, LeafKey(0, 0, 0), 3, 0.9);  // at a chunk corner: neighbours mesh it too
  const Meshed m = MeshAll(tiles, grid);
  const MeshCheck check = CheckMesh(m.mesh);
  EXPECT_TRUE(check.watertight()) << check.ToString();
  EXPECT_EQ(m.mesh.vertices.size(), 6u);
  EXPECT_EQ(m.mesh.triangles.size(), 8u);
  // Unobserved neighbours: vertices at 0.45 res outside the faces, i.e. 0.95 res from the
  // centre; an octahedron of radius r has volume 4 r³ / 3, and normals point inwards.
  const double r = 0.95 * res;
  EXPECT_NEAR(SignedVolume(m.mesh), -4 * r * r * r / 3, 1e-6);
  for (const Eigen::Vector3f& v : m.mesh.vertices) {
    EXPECT_NEAR((v.cast<double>() - Eigen::Vector3d::Constant(res / 2)).norm(), r, 1e-6);
  }
}

// Two interior cells touching only along an edge, or only at a corner; and the checkerboard
// 2×2×2 block (every ambiguous configuration at once). All must stay manifold.
TEST(DualContouring, DiagonalNeighboursStayManifold) {
  OctreeGrid grid;
  grid.chunk_depth = 3;
  const std::vector<std::vector<LeafKey>> cases = {
      {LeafKey(3, 3, 3), LeafKey(4, 4, 3)},
      {LeafKey(3, 3, 3), LeafKey(4, 4, 4)},
      {LeafKey(7, 7, 7), LeafKey(8, 8, 7)},  // across chunk borders
      {LeafKey(7, 7, 7), LeafKey(8, 8, 8)},
      {LeafKey(0, 0, 0), LeafKey(1, 1, 0), LeafKey(1, 0, 1), LeafKey(0, 1, 1)},
      {LeafKey(3, 3, 3), LeafKey(4, 4, 3), LeafKey(4, 3, 4), LeafKey(3, 4, 4), LeafKey(5, 5, 5)},
      // A ring around an edge: interior cells 6-connected above and below the edge's ends.
      {LeafKey(0, 0, 0), LeafKey(1, 1, 0), LeafKey(0, 0, 1), LeafKey(1, 0, 1), LeafKey(1, 1, 1),
       LeafKey(0, 0, -1), LeafKey(1, 0, -1), LeafKey(1, 1, -1)},
  };
  for (size_t i = 0; i < cases.size(); ++i) {
    Tiles tiles;
    for (const LeafKey& c : cases[i]) AddLeaf(tiles, grid, c, 3, 0.8);
    const Meshed m = MeshAll(tiles, grid);
    const MeshCheck check = CheckMesh(m.mesh);
    EXPECT_TRUE(check.watertight()) << "case " << i << ": " << check.ToString();
    EXPECT_LT(SignedVolume(m.mesh), 0) << "case " << i;
    EXPECT_EQ(FaceVertexCount(m.chunks), FinestFaceCount(InteriorCells(tiles, grid)))
        << "case " << i;
  }
}

// A box room (interior) of mixed leaf sizes inside exterior walls, across chunk borders: one
// vertex per finest boundary face, on the Fig 4.9 plane, and the enclosed volume of the box.
TEST(DualContouring, BoxRoomVerticesLieOnTheIsosurface) {
  OctreeGrid grid;
  grid.chunk_depth = 3;
  const double res = grid.resolution_m();
  const int lo = -4, hi = 8;
  Tiles tiles;
  for (int z = lo - 1; z < hi + 1; ++z) {
    for (int y = lo - 1; y < hi + 1; ++y) {
      for (int x = lo - 1; x < hi + 1; ++x) {
        const bool inside = x >= lo && x < hi && y >= lo && y < hi && z >= lo && z < hi;
        if (x >= 0 && x < 4 && y >= 0 && y < 4 && z >= 0 && z < 4) continue;
        AddLeaf(tiles, grid, LeafKey(x, y, z), 3, inside ? 0.9 : 0.3);
      }
    }
  }
  AddLeaf(tiles, grid, LeafKey(0, 0, 0), 1, 0.8);  // a coarse interior leaf in the middle
  const Meshed m = MeshAll(tiles, grid);
  const MeshCheck check = CheckMesh(m.mesh);
  EXPECT_TRUE(check.watertight()) << check.ToString();
  const int side = hi - lo;
  EXPECT_EQ(FaceVertexCount(m.chunks), 6u * side * side);
  // Fig 4.9: p 0.9 → 0.3 between centres one cell apart: the surface is res/6 outside the
  // cell faces. Face vertices lie on the six planes; the volume is the box's minus the
  // bevelled edges and corners (corner polygons cut them).
  const double a = lo * res - res / 6, b = hi * res + res / 6;
  for (const Eigen::Vector3f& v : m.mesh.vertices) {
    const Eigen::Vector3d p = v.cast<double>();
    const double d = std::min({p.x() - a, b - p.x(), p.y() - a, b - p.y(), p.z() - a, b - p.z()});
    EXPECT_GE(d, -1e-6);
    EXPECT_LE(d, 0.5 * res + 1e-6);  // edge/corner cuts lie within half a cell
  }
  const double box = std::pow(b - a, 3);
  const double vol = -SignedVolume(m.mesh);
  EXPECT_LT(vol, box);
  EXPECT_GT(vol, 0.95 * box);
}

TEST(DualContouring, RandomOctreesAreWatertight) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 12; ++trial) {
    OctreeGrid grid;
    grid.chunk_depth = 3;
    Tiles tiles;
    for (int j = 0; j < 8; ++j) {
      const ChunkKey c(j & 1, (j >> 1) & 1, (j >> 2) & 1);
      if (j == 6) continue;
      testing::GrowRandomTile(rng, grid, c, 0.05, 0.3, 0.2, tiles);
    }
    const Meshed m = MeshAll(tiles, grid);
    const MeshCheck check = CheckMesh(m.mesh);
    EXPECT_TRUE(check.watertight()) << "trial " << trial << ": " << check.ToString();
    const auto in = InteriorCells(tiles, grid);
    EXPECT_EQ(FaceVertexCount(m.chunks), FinestFaceCount(in)) << "trial " << trial;
    // Inward normals: the signed volume is minus roughly the interior volume (the surface
    // moves by less than half a cell, and lone cells shrink or grow).
    const double cell = std::pow(grid.resolution_m(), 3);
    EXPECT_LT(SignedVolume(m.mesh), -0.3 * in.size() * cell) << "trial " << trial;
    EXPECT_GT(SignedVolume(m.mesh), -3.0 * in.size() * cell) << "trial " << trial;
    // Deterministic: meshing again gives the same mesh.
    const Meshed again = MeshAll(tiles, grid);
    EXPECT_EQ(again.mesh.vertices, m.mesh.vertices);
    EXPECT_EQ(again.mesh.triangles, m.mesh.triangles);
  }
}

TEST(DualContouring, WelderAsTheChunksComeIsTheWholeWeld) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 6; ++trial) {
    OctreeGrid grid;
    grid.chunk_depth = 3;
    Tiles tiles;
    // Four columns along x (from −2), two by two across, some chunks missing.
    for (int x = -2; x < 2; ++x) {
      for (int j = 0; j < 4; ++j) {
        if ((x + j + trial) % 5 == 0) continue;
        testing::GrowRandomTile(rng, grid, ChunkKey(x, j & 1, j >> 1), 0.05, 0.3, 0.2, tiles);
      }
    }
    const Meshed m = MeshAll(tiles, grid);
    std::vector<uint8_t> observed;
    const TriangleMesh whole = ReferenceWeld(m.chunks, &observed);
    ChunkMeshWelder welder(grid.leaves_per_side());
    for (const ChunkMesh& c : m.chunks) {
      if (c.triangles.empty()) continue;
      ASSERT_TRUE(welder.Add(c).ok()) << "trial " << trial;
    }
    std::vector<uint8_t> welded_observed;
    absl::StatusOr<TriangleMesh> welded = welder.Finish(&welded_observed);
    ASSERT_TRUE(welded.ok()) << welded.status();
    EXPECT_EQ(welded->vertices, whole.vertices) << "trial " << trial;
    EXPECT_EQ(welded->triangles, whole.triangles) << "trial " << trial;
    EXPECT_EQ(welded_observed, observed) << "trial " << trial;
    EXPECT_GT(whole.triangles.size(), 100u);
  }
}

TEST(DualContouring, WelderRefusesChunksOutOfOrderOrBelowItsFront) {
  ChunkMesh a;
  a.chunk = ChunkKey(1, 0, 0);
  a.vertex_keys = {MeshVertexKey{{8, 0, 0, 0}}};
  a.vertex_positions = {Eigen::Vector3d::Zero()};
  ChunkMesh b = a;
  b.chunk = ChunkKey(0, 5, 0);
  ChunkMeshWelder out_of_order(8);
  ASSERT_TRUE(out_of_order.Add(a).ok());
  EXPECT_EQ(out_of_order.Add(b).code(), absl::StatusCode::kInvalidArgument);
  // Column 3 welds every key below 3 · 8 − kMargin; a chunk there with a key at x = 0 is not
  // one dual contouring makes.
  ChunkMesh c = a;
  c.chunk = ChunkKey(3, 0, 0);
  c.vertex_keys = {MeshVertexKey{{0, 0, 0, 0}}};
  ChunkMeshWelder below(8);
  ASSERT_TRUE(below.Add(a).ok());
  EXPECT_EQ(below.Add(c).code(), absl::StatusCode::kInternal);
}

}  // namespace
}  // namespace carvemap

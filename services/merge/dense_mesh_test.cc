#include "services/merge/dense_mesh.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>
#include <unordered_map>

#include <gtest/gtest.h>

#include "services/merge/merge_test_util.h"
#include "services/mesh/cube_mesh_testing.h"
#include "services/mesh/mesh_checks.h"
#include "tests/support/carved_preset.h"
#include "tests/support/truth_distance.h"

namespace carvemap {
namespace {

using testing::FreshDir;
using testing::ReadPlyTriangles;
using testing::TruthDistance;

// Random tiles on a 3×2×2 block of chunks (one left out), written to `dir`.
std::vector<TileData> WriteRandomTiles(const std::string& dir, int k, uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<TileData> tiles;
  for (int j = 0; j < 12; ++j) {
    const ChunkKey c(j % 3 - 1, (j / 3) % 2, j / 6);
    if (j == 7) continue;
    tiles.push_back(testing::RandomTile(rng, k, c));
    EXPECT_TRUE(WriteTile(dir, tiles.back()).ok());
  }
  return tiles;
}

// Finest boundary faces of the tiles by brute force (no tile row: exterior).
uint64_t FinestBoundaryFaces(const std::vector<TileData>& tiles, int k) {
  std::unordered_map<uint64_t, bool> in;
  auto key = [](int x, int y, int z) {
    return (uint64_t(uint32_t(x + (1 << 20))) << 42) | (uint64_t(uint32_t(y + (1 << 20))) << 21) |
           uint64_t(uint32_t(z + (1 << 20)));
  };
  const int n = 1 << k;
  for (const TileData& t : tiles) {
    for (const TileLeaf& l : t.leaves) {
      const int s = 1 << (k - l.node.depth);
      const LeafKey lo = t.chunk * n + l.node.local * s;
      for (int z = 0; z < s; ++z)
        for (int y = 0; y < s; ++y)
          for (int x = 0; x < s; ++x) in[key(lo.x() + x, lo.y() + y, lo.z() + z)] = l.stats.interior();
    }
  }
  uint64_t faces = 0;
  for (const TileData& t : tiles) {
    for (const TileLeaf& l : t.leaves) {
      if (!l.stats.interior()) continue;
      const int s = 1 << (k - l.node.depth);
      const LeafKey lo = t.chunk * n + l.node.local * s;
      for (int z = 0; z < s; ++z)
        for (int y = 0; y < s; ++y)
          for (int x = 0; x < s; ++x)
            for (int d = 0; d < 6; ++d) {
              int c[3] = {lo.x() + x, lo.y() + y, lo.z() + z};
              c[d / 2] += (d % 2) ? 1 : -1;
              auto it = in.find(key(c[0], c[1], c[2]));
              faces += (it == in.end() || !it->second);
            }
    }
  }
  return faces;
}

TEST(DenseMesh, TinyCacheGivesTheSameMeshAsALargeOne) {
  const std::string dir = FreshDir();
  const int k = 4;
  const std::vector<TileData> tiles = WriteRandomTiles(dir, k, 11);
  auto big = TileSet::Open(dir, 0, uint64_t{1} << 32);
  auto tiny = TileSet::Open(dir, 0, 1);  // the newest tile only
  ASSERT_TRUE(big.ok() && tiny.ok());
  auto a = BuildDenseMesh(**big);
  auto b = BuildDenseMesh(**tiny);
  ASSERT_TRUE(a.ok()) << a.status();
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_GT((*tiny)->tile_reads(), (*big)->tile_reads());
  EXPECT_LE((*tiny)->cached_bytes(), (*big)->cached_bytes());
  const MeshCheck check = CheckMesh(a->mesh);
  EXPECT_TRUE(check.watertight()) << check.ToString();
  EXPECT_GT(a->mesh.triangles.size(), 1000u);
  EXPECT_EQ(a->mesh.vertices, b->mesh.vertices);
  EXPECT_EQ(a->mesh.triangles, b->mesh.triangles);
  EXPECT_EQ(a->chunks, b->chunks);

  auto fa = CollectBoundaryFaces(**big);
  auto fb = CollectBoundaryFaces(**tiny);
  ASSERT_TRUE(fa.ok() && fb.ok());
  ASSERT_EQ(fa->size(), fb->size());
  double area = 0;
  for (size_t i = 0; i < fa->size(); ++i) {
    EXPECT_EQ((*fa)[i].isosurface(), (*fb)[i].isosurface());
    area += (*fa)[i].area_m2();
  }
  const double res = (*big)->grid().resolution_m();
  EXPECT_NEAR(area, FinestBoundaryFaces(tiles, k) * res * res, 1e-9);
}

TEST(DenseMesh, StreamedIsTheBuiltMeshAndItsSelfIntersections) {
  const std::string dir = FreshDir();
  WriteRandomTiles(dir, 4, 17);
  auto set = TileSet::Open(dir, 0, 1);
  ASSERT_TRUE(set.ok());
  auto built = BuildDenseMesh(**set);
  ASSERT_TRUE(built.ok()) << built.status();
  ASSERT_GT(built->mesh.triangles.size(), 1000u);
  const SelfIntersections whole = CountSelfIntersections(built->mesh);
  for (int threads : {1, 2}) {
    TriangleMesh streamed;
    DenseMeshSink sink;
    sink.vertices = [&](std::span<const Eigen::Vector3f> v) {
      streamed.vertices.insert(streamed.vertices.end(), v.begin(), v.end());
      return absl::OkStatus();
    };
    ChunkKey last = ChunkKey::Zero();
    bool first = true;
    sink.triangles = [&](const ChunkKey& chunk, std::span<const Eigen::Vector3i> t) {
      EXPECT_TRUE(first || !ChunkKeyLess()(chunk, last));  // chunks in order
      first = false;
      last = chunk;
      for (const Eigen::Vector3i& x : t) {
        EXPECT_LT(x.maxCoeff(), int(streamed.vertices.size()));  // named after its vertices
      }
      streamed.triangles.insert(streamed.triangles.end(), t.begin(), t.end());
      return absl::OkStatus();
    };
    auto r = StreamDenseMesh(**set, sink, nullptr, threads);
    ASSERT_TRUE(r.ok()) << r.status();
    EXPECT_EQ(streamed.vertices, built->mesh.vertices);
    EXPECT_EQ(streamed.triangles, built->mesh.triangles);
    EXPECT_EQ(r->vertices, built->mesh.vertices.size());
    EXPECT_EQ(r->triangles, built->mesh.triangles.size());
    EXPECT_EQ(r->chunks, built->chunks);
    EXPECT_EQ(r->self_intersections.pairs, whole.pairs);
    EXPECT_EQ(r->self_intersections.unchecked, whole.unchecked);
  }
  // A sink's error stops the stream.
  DenseMeshSink failing;
  failing.vertices = [](std::span<const Eigen::Vector3f>) {
    return absl::DataLossError("disk full");
  };
  failing.triangles = [](const ChunkKey&, std::span<const Eigen::Vector3i>) {
    return absl::OkStatus();
  };
  EXPECT_EQ(StreamDenseMesh(**set, failing).status().code(), absl::StatusCode::kDataLoss);
}

TEST(DenseMesh, ColumnWindowsCountTheWholeMeshsSelfIntersections) {
  // Cubes overlapping their neighbours along x, in columns 2 m wide (a cube's triangles go to
  // the column of its lowest x), with an empty column at x = 6–8 m.
  TriangleMesh m;
  std::vector<int> column;  // per cube
  for (int i = 0; i < 16; ++i) {
    const float x = 0.7f * i + (i >= 9 ? 2.5f : 0.f);
    testing::AddCube(m, Eigen::Vector3f(x, 0.1f * (i % 3), 0.05f * (i % 2)), 1);
    column.push_back(int(std::floor(x / 2)));
  }
  const SelfIntersections whole = CountSelfIntersections(m);
  ASSERT_GT(whole.pairs, 10u);
  ColumnSelfIntersections windows(2.0, 1);
  windows.AddVertices(m.vertices);
  for (size_t c = 0; c < column.size(); ++c) {
    windows.AddTriangles(ChunkKey(column[c], 0, 0),
                         std::span<const Eigen::Vector3i>(m.triangles).subspan(12 * c, 12));
  }
  const SelfIntersections counted = windows.Finish();
  EXPECT_EQ(counted.pairs, whole.pairs);
  EXPECT_EQ(counted.unchecked, whole.unchecked);
}

TEST(DenseMesh, ThreadsGiveTheSameMeshAndFacesAsOne) {
  const std::string dir = FreshDir();
  WriteRandomTiles(dir, 4, 13);
  auto set = TileSet::Open(dir, 0, 1);  // the newest tile only: batches hold their own
  ASSERT_TRUE(set.ok());
  auto one = BuildDenseMesh(**set);
  auto one_faces = CollectBoundaryFaces(**set);
  ASSERT_TRUE(one.ok() && one_faces.ok());
  ASSERT_GT(one->mesh.triangles.size(), 1000u);
  for (int threads : {2, 3}) {
    uint64_t last = 0;
    auto many = BuildDenseMesh(
        **set,
        [&](uint64_t done, uint64_t) {
          EXPECT_EQ(done, last + 1);  // in chunk order, one call per chunk
          last = done;
          return true;
        },
        threads);
    ASSERT_TRUE(many.ok()) << many.status();
    EXPECT_EQ(last, one->chunks);
    EXPECT_EQ(many->mesh.vertices, one->mesh.vertices) << threads;
    EXPECT_EQ(many->mesh.triangles, one->mesh.triangles) << threads;
    EXPECT_EQ(many->vertex_observed, one->vertex_observed) << threads;
    auto faces = CollectBoundaryFaces(**set, nullptr, threads);
    ASSERT_TRUE(faces.ok()) << faces.status();
    ASSERT_EQ(faces->size(), one_faces->size());
    for (size_t i = 0; i < faces->size(); ++i) {
      ASSERT_EQ((*faces)[i].isosurface(), (*one_faces)[i].isosurface()) << i;
      ASSERT_EQ((*faces)[i].size_m, (*one_faces)[i].size_m) << i;
      ASSERT_EQ((*faces)[i].sign, (*one_faces)[i].sign) << i;
      ASSERT_EQ((*faces)[i].exterior_weight, (*one_faces)[i].exterior_weight) << i;
    }
  }
  // Cancelled in a batch: no later chunk is reported.
  uint64_t calls = 0;
  auto cancelled = BuildDenseMesh(
      **set,
      [&](uint64_t done, uint64_t) {
        ++calls;
        return done < 5;
      },
      2);
  EXPECT_EQ(cancelled.status().code(), absl::StatusCode::kCancelled);
  EXPECT_EQ(calls, 5u);
}

TEST(DenseMesh, ProgressCanCancel) {
  const std::string dir = FreshDir();
  WriteRandomTiles(dir, 3, 5);
  auto set = TileSet::Open(dir, 0, 1 << 20);
  ASSERT_TRUE(set.ok());
  uint64_t calls = 0, total = 0;
  auto r = BuildDenseMesh(**set, [&](uint64_t done, uint64_t all) {
    ++calls;
    total = all;
    return done < 3;
  });
  EXPECT_EQ(r.status().code(), absl::StatusCode::kCancelled);
  EXPECT_EQ(calls, 3u);
  EXPECT_GT(total, 11u);  // tiles and their +1 neighbours
  auto f = CollectBoundaryFaces(**set, [](uint64_t, uint64_t) { return false; });
  EXPECT_EQ(f.status().code(), absl::StatusCode::kCancelled);
}

// ---- Real carved data against ground truth -------------------------------------------------

struct PresetCase {
  const char* preset;
  double walk_s;
};

class CarvedDenseMesh : public ::testing::TestWithParam<PresetCase> {};

TEST_P(CarvedDenseMesh, WatertightAndNearTheTruth) {
  testing::CarvedPresetOptions o;
  o.preset = GetParam().preset;
  o.walk_s = GetParam().walk_s;
  o.rate_hz = 10;
  o.beam_step_deg = 1.0;
  o.drift = false;
  o.threads = 1;
  const auto t0 = std::chrono::steady_clock::now();
  auto carved = testing::CarvePreset(o, FreshDir());
  ASSERT_TRUE(carved.ok()) << carved.status();
  const auto t1 = std::chrono::steady_clock::now();
  auto set = TileSet::Open(carved->tiles_dir, 0, 64 << 20);
  ASSERT_TRUE(set.ok()) << set.status();
  auto dense = BuildDenseMesh(**set);
  ASSERT_TRUE(dense.ok()) << dense.status();
  const auto t2 = std::chrono::steady_clock::now();
  auto faces = CollectBoundaryFaces(**set);
  ASSERT_TRUE(faces.ok()) << faces.status();
  const auto t3 = std::chrono::steady_clock::now();

  const TriangleMesh& mesh = dense->mesh;
  const MeshCheck check = CheckMesh(mesh);
  EXPECT_TRUE(check.watertight()) << check.ToString();
  ASSERT_GT(mesh.triangles.size(), 1000u);

  auto truth = ReadPlyTriangles(carved->gt_dir + "/surfaces.ply");
  auto objects = ReadPlyTriangles(carved->gt_dir + "/objects.ply");
  truth.insert(truth.end(), objects.begin(), objects.end());
  ASSERT_FALSE(truth.empty());
  const double res = carved->grid.resolution_m();
  const TruthDistance distance(std::move(truth), 0.25, 4 * res);
  // All vertices, and those on surfaces the scans saw (exterior side observed). The others
  // close the carved volume against unobserved space (§4.3.2: unobserved is exterior): pockets
  // the short walk never carved, far from any true surface by design.
  std::vector<double> d, d_seen;
  ASSERT_EQ(dense->vertex_observed.size(), mesh.vertices.size());
  const size_t stride = std::max<size_t>(1, mesh.vertices.size() / 40000);
  for (size_t i = 0; i < mesh.vertices.size(); i += stride) {
    d.push_back(distance(mesh.vertices[i].cast<double>()));
    if (dense->vertex_observed[i]) d_seen.push_back(d.back());
  }
  ASSERT_GT(d_seen.size(), 100u);
  std::sort(d.begin(), d.end());
  std::sort(d_seen.begin(), d_seen.end());
  const double median = d_seen[d_seen.size() / 2], p90 = d_seen[d_seen.size() * 9 / 10];
  const double median_all = d[d.size() / 2];
  double face_area = 0;
  for (const BoundaryFace& f : *faces) face_area += f.area_m2();
  auto ms = [](auto a, auto b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };
  std::printf(
      "[%s] tiles %zu, dense chunks %llu, faces %zu (%.1f m²), mesh %zu vertices %zu triangles, "
      "centre vertices %llu; distance to truth of observed-surface vertices (%.0f%%) median %.4f m "
      "p90 %.4f m, of all vertices median %.4f m (capped at %.2f; res %.4f); "
      "carve %.0f ms, mesh %.0f ms (%.2f ms/chunk), faces %.0f ms\n",
      GetParam().preset, (*set)->chunks().size(), (unsigned long long)dense->chunks,
      faces->size(), face_area, mesh.vertices.size(), mesh.triangles.size(),
      (unsigned long long)dense->centre_vertices, 100.0 * d_seen.size() / d.size(), median, p90,
      median_all, 4 * res, res, ms(t0, t1), ms(t1, t2),
      ms(t1, t2) / std::max<uint64_t>(1, dense->chunks), ms(t2, t3));
  EXPECT_LE(median, res);
  EXPECT_GT(faces->size(), 1000u);
}

INSTANTIATE_TEST_SUITE_P(Presets, CarvedDenseMesh,
                         ::testing::Values(PresetCase{"room", 20}, PresetCase{"office", 20}),
                         [](const auto& info) { return std::string(info.param.preset); });

}  // namespace
}  // namespace carvemap

// ChunkOctree: eq 4.8 carving of a synthetic wall scan, §4.3.2 simplification and determinism.
#include "worker/chunk_octree.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <random>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include "geometry/carve_map.h"
#include "geometry/wedge_geometry.h"

namespace carvemap {
namespace {

constexpr double kSigmaM = 0.01;  // σ of the sensor and point Gaussians, isotropic

struct WallScan {
  Eigen::Vector3d sensor = Eigen::Vector3d(-1.0, 1.0, 1.0);  // 2 m in front of x = 1
  double wall_x = 1.0;
  // Grid sensor: rows × cols rays hitting the wall at y, z ∈ [lo, hi].
  int n = 41;
  double lo = 0.4, hi = 1.6;

  [[nodiscard]] Eigen::Vector3d Hit(int i, int j) const {
    const double step = (hi - lo) / (n - 1);
    return {wall_x, lo + step * i, lo + step * j};
  }
  [[nodiscard]] RayModel Ray(int i, int j) const {
    RayModel ray;
    ray.sensor_mean = sensor.cast<float>();
    ray.point_mean = Hit(i, j).cast<float>();
    const float var = float(kSigmaM * kSigmaM);
    ray.sensor_cov = {var, 0, 0, var, 0, var};
    ray.point_cov = {var, 0, 0, var, 0, var};
    return ray;
  }
  // The wedges of neighbouring 2×2 pixels (§4.3.1), row-major.
  [[nodiscard]] std::vector<Wedge> Wedges() const {
    std::vector<Wedge> wedges;
    for (int i = 0; i + 1 < n; ++i) {
      for (int j = 0; j + 1 < n; ++j) {
        Wedge w;
        w.rays = {Ray(i, j), Ray(i + 1, j), Ray(i + 1, j + 1), Ray(i, j + 1)};
        w.num_rays = 4;
        wedges.push_back(w);
      }
    }
    return wedges;
  }
};

ChunkOctree Carve(const OctreeGrid& grid, const std::vector<Wedge>& wedges) {
  ChunkOctree tree(grid, ChunkKey(0, 0, 0));
  EXPECT_TRUE(tree.CarveWedges(wedges).ok());
  return tree;
}

OctreeGrid Grid(int depth) {
  OctreeGrid g;
  g.chunk_depth = depth;
  return g;
}

// The centres of every finest leaf of chunk (0,0,0).
std::vector<Eigen::Vector3d> FinestCentres(const OctreeGrid& grid) {
  std::vector<Eigen::Vector3d> xs;
  const int n = grid.leaves_per_side();
  for (int x = 0; x < n; ++x)
    for (int y = 0; y < n; ++y)
      for (int z = 0; z < n; ++z) xs.push_back(LeafCenter(grid, LeafKey(x, y, z)));
  return xs;
}

class WallTest : public ::testing::TestWithParam<std::tuple<int, double>> {
 protected:
  WallTest() : grid_(Grid(std::get<0>(GetParam()))) { scan_.wall_x = std::get<1>(GetParam()); }
  OctreeGrid grid_;
  WallScan scan_;
};

TEST_P(WallTest, LabelsInteriorBeforeExteriorBehindUnobservedElsewhere) {
  ChunkOctree tree = Carve(grid_, scan_.Wedges());
  const double res = grid_.resolution_m();
  ASSERT_GT(tree.num_leaves(), 0u);
  for (int i = 2; i < scan_.n - 2; i += 5) {
    for (int j = 2; j < scan_.n - 2; j += 5) {
      SCOPED_TRACE(::testing::Message() << "ray " << i << "," << j);
      const Eigen::Vector3d hit = scan_.Hit(i, j);
      const Eigen::Vector3d dir = (hit - scan_.sensor).normalized();
      // Every leaf along the ray inside the chunk, up to one leaf before the wall: interior.
      for (double s = (0.0 - scan_.sensor.x()) / dir.x() + 1e-6;; s += 0.25 * res) {
        const Eigen::Vector3d x = scan_.sensor + s * dir;
        if (x.x() > scan_.wall_x - res) break;
        const LeafStats st = tree.StatsAt(x);
        ASSERT_TRUE(st.observed()) << x.transpose();
        EXPECT_GT(st.p(), 0.5) << x.transpose();
      }
      // The first leaf whose centre is behind the wall (its box starts within the 3σ the hull
      // reaches past the points): observed and exterior.
      const Eigen::Vector3d behind = hit + dir * 1e-4;
      LeafKey key = LeafOf(grid_, behind);
      if (LeafCenter(grid_, key).x() <= scan_.wall_x) key.x() += 1;
      const Eigen::Vector3d c = LeafCenter(grid_, key);
      ASSERT_LT(LeafBox(grid_, key).min().x() - scan_.wall_x, 3 * kSigmaM);
      const LeafStats st = tree.StatsAt(c);
      EXPECT_TRUE(st.observed()) << c.transpose();
      EXPECT_LT(st.p(), 0.5) << c.transpose();
    }
  }
  // Far behind the wall, and beside the fan: never touched, p = 0.5.
  for (const Eigen::Vector3d& x : {Eigen::Vector3d(1.5, 1.0, 1.0), Eigen::Vector3d(1.9, 0.1, 1.9),
                                   Eigen::Vector3d(0.5, 0.05, 1.0), Eigen::Vector3d(0.9, 1.0, 1.95)}) {
    const LeafStats st = tree.StatsAt(x);
    EXPECT_EQ(st.count, 0u) << x.transpose();
    EXPECT_EQ(st.p(), 0.5) << x.transpose();
  }
}

// Fig 4.9: along a row of leaf centres through the fan, the p = 0.5 isosurface interpolated
// between the last interior and the first exterior leaf lies within one leaf of the wall.
TEST_P(WallTest, HalfCrossingWithinOneLeafOfWall) {
  ChunkOctree tree = Carve(grid_, scan_.Wedges());
  const double res = grid_.resolution_m();
  for (const double yz : {0.8, 1.0, 1.3}) {
    SCOPED_TRACE(yz);
    const LeafKey row = LeafOf(grid_, Eigen::Vector3d(0, yz, yz));
    std::vector<std::pair<double, LeafStats>> line;  // (x of centre, stats)
    for (int x = 0; x < grid_.leaves_per_side(); ++x) {
      const Eigen::Vector3d c = LeafCenter(grid_, LeafKey(x, row.y(), row.z()));
      line.emplace_back(c.x(), tree.StatsAt(c));
    }
    int crossings = 0;
    double crossing_x = NAN;
    for (size_t a = 0; a + 1 < line.size(); ++a) {
      const LeafStats& pa = line[a].second;
      const LeafStats& pb = line[a + 1].second;
      if (pa.observed() && pb.observed() && pa.interior() && !pb.interior()) {
        ++crossings;
        crossing_x = line[a].first + (pa.p() - 0.5) / (pa.p() - pb.p()) * res;
      }
    }
    EXPECT_EQ(crossings, 1);
    EXPECT_LE(std::abs(crossing_x - scan_.wall_x), res) << crossing_x;
  }
}

TEST_P(WallTest, SimplifyKeepsEveryLabelAndReducesLeaves) {
  ChunkOctree tree = Carve(grid_, scan_.Wedges());
  const std::vector<Eigen::Vector3d> xs = FinestCentres(grid_);
  std::vector<LeafStats> before;
  before.reserve(xs.size());
  for (const auto& x : xs) before.push_back(tree.StatsAt(x));
  const size_t leaves_before = tree.num_leaves();
  uint64_t count_before = 0;
  double weight_before = 0;
  for (const TileLeaf& l : tree.Leaves()) {
    count_before += l.stats.count;
    weight_before += l.stats.sum_w;
  }

  tree.Simplify();
  const size_t leaves_after = tree.num_leaves();
  EXPECT_LT(leaves_after, leaves_before);
  std::cout << "depth " << grid_.chunk_depth << ": " << leaves_before << " finest leaves -> "
            << leaves_after << " after §4.3.2 simplification\n";
  int coarser = 0;
  for (size_t i = 0; i < xs.size(); ++i) {
    int depth = -1;
    const LeafStats after = tree.StatsAt(xs[i], &depth);
    ASSERT_EQ(after.interior(), before[i].interior()) << xs[i].transpose();
    ASSERT_EQ(after.observed(), before[i].observed()) << xs[i].transpose();
    if (depth >= 0 && depth < grid_.chunk_depth) ++coarser;
  }
  EXPECT_GT(coarser, 0);

  // Merging is exact summation: nothing is lost.
  uint64_t count_after = 0;
  double weight_after = 0;
  const std::vector<TileLeaf> leaves = tree.Leaves();
  for (const TileLeaf& l : leaves) {
    count_after += l.stats.count;
    weight_after += l.stats.sum_w;
  }
  EXPECT_EQ(count_after, count_before);
  EXPECT_NEAR(weight_after, weight_before, 1e-9 * weight_before);

  // Maximal: no 8 siblings left that are all leaves with one label.
  std::map<std::pair<int, uint64_t>, std::vector<bool>> families;
  for (const TileLeaf& l : leaves) {
    if (l.node.depth == 0) continue;
    families[{l.node.depth, MortonCode(l.node.local) >> 3}].push_back(l.stats.interior());
  }
  for (const auto& [family, labels] : families) {
    if (labels.size() < 8) continue;
    EXPECT_FALSE(std::all_of(labels.begin(), labels.end(), [&](bool b) { return b == labels[0]; }))
        << "depth " << family.first << " parent " << family.second;
  }

  // Idempotent.
  tree.Simplify();
  EXPECT_EQ(tree.num_leaves(), leaves_after);
}

// §4.2.3's point voxel set: every scan point counts once, in the finest leaf holding it, and
// simplification keeps those leaves finest.
TEST_P(WallTest, EachScanPointCountsOnceInItsFinestLeaf) {
  ChunkOctree tree = Carve(grid_, scan_.Wedges());
  std::map<uint64_t, uint32_t> expected;  // Morton code of the finest leaf → points
  for (int i = 0; i < scan_.n; ++i)
    for (int j = 0; j < scan_.n; ++j)
      ++expected[MortonCode(LeafOf(grid_, scan_.Ray(i, j).point_mean.cast<double>()))];
  tree.Simplify();
  std::map<uint64_t, uint32_t> counted;
  for (const TileLeaf& l : tree.Leaves()) {
    if (l.stats.points == 0) continue;
    EXPECT_EQ(l.node.depth, grid_.chunk_depth);
    counted[MortonCode(l.node.local)] = l.stats.points;
  }
  EXPECT_EQ(counted, expected);

  // A ray given twice in one payload (WedgePayloadWriter repeats rays of old frames) is one
  // point; a ray whose point lies in another chunk counts there, not here.
  IndexedWedges in;
  in.rays = {scan_.Ray(0, 0), scan_.Ray(0, 1), scan_.Ray(1, 1), scan_.Ray(0, 0)};
  RayModel far = scan_.Ray(1, 0);
  far.point_mean.x() += 2.0f;  // x ≈ 3 m: chunk (1, 0, 0)
  in.rays.push_back(far);
  WedgeRef w;
  w.ray = {0, 1, 2, 4};
  w.num_rays = 4;
  WedgeRef again = w;
  again.ray = {3, 1, 2, 4};
  in.wedges = {w, again};
  ChunkOctree twice(grid_, ChunkKey(0, 0, 0));
  ASSERT_TRUE(twice.CarveIndexed(in).ok());
  uint32_t points = 0;
  for (const TileLeaf& l : twice.Leaves()) points += l.stats.points;
  EXPECT_EQ(points, 3u);
}

INSTANTIATE_TEST_SUITE_P(ResolutionsAndWalls, WallTest,
                         ::testing::Combine(::testing::Values(5, 6),
                                            ::testing::Values(1.0, 1.02)),
                         [](const auto& info) {
                           return "depth" + std::to_string(std::get<0>(info.param)) + "_wall" +
                                  std::to_string(int(std::round(std::get<1>(info.param) * 100)));
                         });

// Same nodes, counts and points, and sums equal (exact) or within 1e−12 relative; or within
// `relative` when given.
bool SameLeaves(const std::vector<TileLeaf>& a, const std::vector<TileLeaf>& b, bool exact,
                double relative = 1e-12) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].node.local != b[i].node.local || a[i].node.depth != b[i].node.depth) return false;
    if (a[i].stats.count != b[i].stats.count || a[i].stats.points != b[i].stats.points) {
      return false;
    }
    const auto close = [&](double x, double y) {
      return exact ? x == y : std::abs(x - y) <= relative * std::max(1.0, std::abs(x));
    };
    if (!close(a[i].stats.sum_w, b[i].stats.sum_w) || !close(a[i].stats.sum_wp, b[i].stats.sum_wp) ||
        !close(a[i].stats.sum_wp2, b[i].stats.sum_wp2)) {
      return false;
    }
  }
  return true;
}

// Both evaluations: kExact to double precision, kFast within single precision's rounding
// (carve_map_float.h: w and p within 5e−6 of eq 4.7's; sums of up to 4 votes).
class EvaluationTest : public ::testing::TestWithParam<CarveEvaluation> {
 protected:
  [[nodiscard]] double Tolerance() const {
    return GetParam() == CarveEvaluation::kExact ? 1e-12 : 1e-5;
  }
};

TEST(ChunkOctreeTest, DeterministicWhateverTheInsertionOrder) {
  const OctreeGrid grid = Grid(5);
  const std::vector<Wedge> wedges = WallScan().Wedges();
  ChunkOctree a = Carve(grid, wedges);
  ChunkOctree b = Carve(grid, wedges);
  EXPECT_TRUE(SameLeaves(a.Leaves(), b.Leaves(), /*exact=*/true));

  // Other wedge orders insert into the hash map in other orders; the output order is the same
  // and the sums agree up to rounding (the sum order per leaf follows the wedge order).
  std::vector<Wedge> shuffled = wedges;
  std::mt19937 rng(301);
  std::shuffle(shuffled.begin(), shuffled.end(), rng);
  ChunkOctree c = Carve(grid, shuffled);
  std::vector<Wedge> reversed(wedges.rbegin(), wedges.rend());
  ChunkOctree d = Carve(grid, reversed);
  EXPECT_TRUE(SameLeaves(a.Leaves(), c.Leaves(), /*exact=*/false));
  EXPECT_TRUE(SameLeaves(a.Leaves(), d.Leaves(), /*exact=*/false));

  const std::vector<TileLeaf> leaves = a.Leaves();
  std::vector<TileLeaf> sorted = leaves;
  std::shuffle(sorted.begin(), sorted.end(), rng);
  SortTileLeaves(grid, sorted);
  EXPECT_TRUE(SameLeaves(leaves, sorted, /*exact=*/true));

  a.Simplify();
  b.Simplify();
  c.Simplify();
  EXPECT_TRUE(SameLeaves(a.Leaves(), b.Leaves(), /*exact=*/true));
  EXPECT_TRUE(SameLeaves(a.Leaves(), c.Leaves(), /*exact=*/false));
}

// §5.6.1's second pass: restricted to a region, the carve is the whole carve's leaves inside
// the region, the same sums (kFast: within float rounding, runs cut at the region's boundary
// start elsewhere), and nothing outside.
TEST_P(EvaluationTest, RestrictedCarvingIsTheWholeCarveInsideTheRegion) {
  const OctreeGrid grid = Grid(5);
  const std::vector<Wedge> wedges = WallScan().Wedges();
  ChunkOctree whole(grid, ChunkKey(0, 0, 0));
  whole.SetEvaluation(GetParam());
  ASSERT_TRUE(whole.CarveWedges(wedges).ok());
  // The octant x < 1 m, y < 1 m, z < 1 m and one 25 cm cell in front of the wall's upper part.
  const ChunkRegion region(3, [] {
    std::vector<Eigen::Vector3i> cells;
    for (int z = 0; z < 4; ++z)
      for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 4; ++x) cells.emplace_back(x, y, z);
    cells.emplace_back(3, 5, 5);
    return cells;
  }());
  ChunkOctree part(grid, ChunkKey(0, 0, 0));
  part.SetEvaluation(GetParam());
  part.RestrictTo(std::make_shared<const ChunkRegion>(region));
  ASSERT_TRUE(part.CarveWedges(wedges).ok());
  std::vector<TileLeaf> expected;
  for (const TileLeaf& leaf : whole.Leaves()) {
    if (region.Intersects(leaf.node)) expected.push_back(leaf);
  }
  ASSERT_GT(expected.size(), 100u);
  ASSERT_LT(expected.size(), whole.Leaves().size() / 2);
  const bool exact = GetParam() == CarveEvaluation::kExact;
  EXPECT_TRUE(SameLeaves(part.Leaves(), expected, exact, 1e-5));
}

TEST_P(EvaluationTest, LeafValuesAreEq48AtTheLeafCentre) {
  const OctreeGrid grid = Grid(5);
  WallScan scan;
  const std::vector<Wedge> wedges = scan.Wedges();
  const Wedge& w = wedges[20 * 40 + 20];
  ChunkOctree tree(grid, ChunkKey(0, 0, 0));
  tree.SetEvaluation(GetParam());
  ASSERT_TRUE(tree.CarveWedge(w).ok());
  ASSERT_GT(tree.num_leaves(), 0u);
  for (const TileLeaf& l : tree.Leaves()) {
    const Eigen::Vector3d c = NodeBox(grid, ChunkKey(0, 0, 0), l.node).center();
    LeafStats expected;
    for (int r = 0; r < 4; ++r) {
      const CarveSample s = EvaluateCarveMap(w.rays[r], c);
      if (s.w >= kMinRayWeight) expected.Add(s.p, s.w);
    }
    EXPECT_EQ(l.stats.count, expected.count);
    EXPECT_NEAR(l.stats.p(), expected.p(), Tolerance());
    EXPECT_NEAR(l.stats.sum_w, expected.sum_w, Tolerance());
  }
  EXPECT_EQ(tree.num_wedges(), 1u);
}

// eq 4.8: S(L) is the set of rays of the wedges touching L. Neighbouring wedges share rays
// (each inner ray of the grid belongs to 4 wedges); in one CarveWedges call a shared ray votes
// once per leaf. Checked against brute force over every leaf of the chunk.
TEST_P(EvaluationTest, EachRayVotesOncePerLeafWhateverHowManyOfItsWedgesTouchIt) {
  const OctreeGrid grid = Grid(5);
  WallScan scan;
  scan.n = 7;  // 6×6 wedges over 49 rays
  const std::vector<Wedge> wedges = scan.Wedges();
  ChunkOctree tree(grid, ChunkKey(0, 0, 0));
  tree.SetEvaluation(GetParam());
  ASSERT_TRUE(tree.CarveWedges(wedges).ok());
  std::vector<WedgeHull> hulls;
  for (const Wedge& w : wedges) hulls.push_back(MakeWedgeHull(w, kWedgeHullSigmas));

  uint64_t leaves_checked = 0, shared_ray_leaves = 0, expected_updates = 0;
  const int n = grid.leaves_per_side();
  for (int x = 0; x < n; ++x)
    for (int y = 0; y < n; ++y)
      for (int z = 0; z < n; ++z) {
        const Eigen::AlignedBox3d box = LeafBox(grid, LeafKey(x, y, z));
        std::map<std::tuple<int, int>, RayModel> rays;  // (i, j) of the grid → ray
        int touching_wedges = 0;
        for (size_t w = 0; w < wedges.size(); ++w) {
          if (!HullIntersectsBox(hulls[w], box)) continue;
          ++touching_wedges;
          const int i = int(w) / (scan.n - 1), j = int(w) % (scan.n - 1);
          for (auto [di, dj] : {std::pair{0, 0}, {1, 0}, {1, 1}, {0, 1}}) {
            rays.emplace(std::tuple{i + di, j + dj}, scan.Ray(i + di, j + dj));
          }
        }
        LeafStats expected;
        for (const auto& [ij, ray] : rays) {
          const CarveSample s = EvaluateCarveMap(ray, box.center());
          if (s.w >= kMinRayWeight) expected.Add(s.p, s.w);
        }
        expected_updates += expected.count;
        int depth = -1;
        const LeafStats got = tree.StatsAt(box.center(), &depth);
        ASSERT_EQ(got.count, expected.count) << x << " " << y << " " << z;
        if (expected.count == 0) continue;
        ++leaves_checked;
        if (touching_wedges > 1 && rays.size() < 4u * touching_wedges) ++shared_ray_leaves;
        EXPECT_NEAR(got.sum_w, expected.sum_w, Tolerance());
        EXPECT_NEAR(got.sum_wp, expected.sum_wp, Tolerance());
      }
  EXPECT_GT(leaves_checked, 50u);
  EXPECT_GT(shared_ray_leaves, 20u);  // the case under test occurs
  EXPECT_EQ(tree.num_leaf_updates(), expected_updates);
  // Counting each wedge's 4 rays would have given more votes than there are distinct rays.
  EXPECT_GT(4 * tree.num_leaf_touches(), tree.num_leaf_updates());
}

INSTANTIATE_TEST_SUITE_P(ExactAndFast, EvaluationTest,
                         ::testing::Values(CarveEvaluation::kExact, CarveEvaluation::kFast),
                         [](const auto& info) {
                           return info.param == CarveEvaluation::kExact ? "exact" : "fast";
                         });

// The carver inlines NodeBox's arithmetic; the boxes (hence the leaves touched) must not differ.
TEST(ChunkOctreeTest, TouchedLeavesAreThoseNodeBoxIntersects) {
  const OctreeGrid grid = Grid(5);
  const ChunkKey chunk(-1, 0, 0);  // negative keys too
  WallScan scan;
  scan.sensor = Eigen::Vector3d(-3.0, 1.0, 1.0);
  scan.wall_x = -1.0;
  const Wedge w = scan.Wedges()[15 * 40 + 22];
  ChunkOctree tree(grid, chunk);
  ASSERT_TRUE(tree.CarveWedge(w).ok());
  const WedgeHull hull = MakeWedgeHull(w, kWedgeHullSigmas);
  size_t touched = 0;
  for (int i = 0; i < 32; ++i)
    for (int j = 0; j < 32; ++j)
      for (int l = 0; l < 32; ++l) {
        ChunkNode node;
        node.local = Eigen::Vector3i(i, j, l);
        node.depth = 5;
        const Eigen::AlignedBox3d box = NodeBox(grid, chunk, node);
        if (!HullIntersectsBox(hull, box)) continue;
        // A touched leaf is stored unless every ray's weight at its centre is negligible.
        bool speaks = false;
        for (int r = 0; r < 4; ++r) speaks |= EvaluateCarveMap(w.rays[r], box.center()).w >= kMinRayWeight;
        if (!speaks) continue;
        ++touched;
        EXPECT_GT(tree.StatsAt(box.center()).count, 0u) << node.local.transpose();
      }
  EXPECT_EQ(touched, tree.num_leaves());  // and no other leaf
  EXPECT_GT(touched, 0u);
}

TEST(ChunkOctreeTest, WedgesMissingTheChunkChangeNothing) {
  ChunkOctree tree(Grid(5), ChunkKey(3, 0, 0));  // x in [6, 8): the wall scan is elsewhere
  for (const Wedge& w : WallScan().Wedges()) ASSERT_TRUE(tree.CarveWedge(w).ok());
  EXPECT_EQ(tree.num_leaves(), 0u);
  EXPECT_EQ(tree.num_leaf_updates(), 0u);
}

TEST(ChunkOctreeTest, RejectsBadWedgesAndCarvingAfterSimplify) {
  ChunkOctree tree(Grid(5), ChunkKey(0, 0, 0));
  Wedge w = WallScan().Wedges()[0];
  w.num_rays = 0;
  EXPECT_EQ(tree.CarveWedge(w).code(), absl::StatusCode::kInvalidArgument);
  w.num_rays = 5;
  EXPECT_EQ(tree.CarveWedge(w).code(), absl::StatusCode::kInvalidArgument);
  w.num_rays = 4;
  w.rays[2].point_mean.x() = NAN;
  EXPECT_EQ(tree.CarveWedge(w).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(tree.num_leaves(), 0u);

  // A single-ray (points sensor) wedge carves along its ray.
  Wedge single = WallScan().Wedges()[0];
  single.num_rays = 1;
  ASSERT_TRUE(tree.CarveWedge(single).ok());
  EXPECT_GT(tree.num_leaves(), 0u);

  tree.Simplify();
  EXPECT_EQ(tree.CarveWedge(single).code(), absl::StatusCode::kFailedPrecondition);
}

TEST(ChunkOctreeTest, TileRoundTripKeepsLeaves) {
  ChunkOctree tree = Carve(Grid(5), WallScan().Wedges());
  tree.Simplify();
  const std::string dir =
      (std::filesystem::path(::testing::TempDir()) / "chunk_octree_test_tile").string();
  std::filesystem::create_directories(dir);
  auto path = WriteTile(dir, tree.ToTile("job-1"));
  ASSERT_TRUE(path.ok()) << path.status();
  auto tile = ReadTile(*path);
  ASSERT_TRUE(tile.ok()) << tile.status();
  EXPECT_TRUE(SameLeaves(tile->leaves, tree.Leaves(), /*exact=*/true));
  EXPECT_EQ(tile->params.num_wedges, tree.num_wedges());
  EXPECT_TRUE(tile->params.simplified);
  std::filesystem::remove_all(dir);
}

// Not a pass/fail test: the carving rate on the wall scan at 6.25 cm, for the report.
TEST(ChunkOctreeTest, CarveSpeed) {
  const std::vector<Wedge> wedges = WallScan().Wedges();
  const auto t0 = std::chrono::steady_clock::now();
  uint64_t n_wedges = 0, updates = 0;
  size_t leaves = 0;
  for (int rep = 0; rep < 5; ++rep) {
    ChunkOctree tree = Carve(Grid(5), wedges);
    n_wedges += tree.num_wedges();
    updates += tree.num_leaf_updates();
    leaves = tree.num_leaves();
  }
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::cout << "carve 6.25 cm wall: " << n_wedges / s << " wedges/s, " << updates / s
            << " leaf updates/s (" << double(updates) / n_wedges << " updates/wedge, " << leaves
            << " leaves)\n";
  EXPECT_GT(updates, 0u);
}

}  // namespace
}  // namespace carvemap

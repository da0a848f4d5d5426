#include "services/levels/level_regions.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <span>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include "services/mesh/voxel_faces_testing.h"

namespace carvemap {
namespace {

using Eigen::Vector3d;
using Eigen::Vector3i;

constexpr double kRes = 0.0625;
OctreeGrid Grid() { return OctreeGrid{5}; }  // 6.25 cm

// Two rooms of 4 × 3 m stacked with a 0.5 m slab between (floors at 0 and 3 m, ceilings at 2.5
// m and, sloping by 1.1° so that the carved ceiling has steps, 5.5–5.42 m), a table top at
// 0.5–0.75 m in the lower room and a shelf board at 4.19–4.31 m in the upper one; free space > 0.
double TwoLevelRooms(const Vector3d& p) {
  auto box = [&p](const Vector3d& lo, const Vector3d& hi) {
    return std::min({p.x() - lo.x(), hi.x() - p.x(), p.y() - lo.y(), hi.y() - p.y(), p.z() - lo.z(),
                     hi.z() - p.z()});
  };
  const double upper = std::min(box({0, 0, 3.0}, {4, 3, 6.0}), 5.5 - 0.02 * p.x() - p.z());
  const double rooms = std::max(box({0, 0, 0}, {4, 3, 2.5}), upper);
  const double table = box({1, 1, 0.5}, {2, 2, 0.75});
  const double shelf = box({0, 0, 4.1875}, {1, 3, 4.3125});
  return std::min({rooms, -table, -shelf});
}

std::vector<BoundaryFace> Faces(double jitter_cells) {
  return VoxelFaces(kRes, Vector3i(-1, -1, -1), Vector3i(65, 49, 90), TwoLevelRooms, jitter_cells,
                    7);
}

std::vector<BoundaryFace> SortedFaces(double jitter_cells) {
  std::vector<BoundaryFace> faces = Faces(jitter_cells);
  EXPECT_TRUE(SortFacesByHeight(faces).ok());
  return faces;
}

// A region as the levels read it: normal, height, area, and their order-free key.
using RegionKey = std::tuple<double, double, double, double, double>;
std::vector<RegionKey> Keys(const std::vector<PlanarRegion>& regions) {
  std::vector<RegionKey> k;
  for (const PlanarRegion& r : regions) {
    k.emplace_back(r.centroid.z(), r.area_m2, r.normal.z(), r.centroid.x(), r.centroid.y());
  }
  std::sort(k.begin(), k.end());
  return k;
}

// The near-horizontal regions (within 5°, as §5.2 reads them) of `regions`.
std::vector<PlanarRegion> NearHorizontal(const std::vector<PlanarRegion>& regions) {
  std::vector<PlanarRegion> out;
  for (const PlanarRegion& r : regions) {
    if (std::abs(r.normal.z()) >= std::cos(5 * M_PI / 180)) out.push_back(r);
  }
  return out;
}

void ExpectSameRegions(const std::vector<PlanarRegion>& a, const std::vector<PlanarRegion>& b) {
  const std::vector<RegionKey> ka = Keys(a), kb = Keys(b);
  ASSERT_EQ(ka.size(), kb.size());
  for (size_t i = 0; i < ka.size(); ++i) {
    EXPECT_NEAR(std::get<0>(ka[i]), std::get<0>(kb[i]), 1e-9) << i;
    EXPECT_NEAR(std::get<1>(ka[i]), std::get<1>(kb[i]), 1e-9) << i;
    EXPECT_NEAR(std::get<2>(ka[i]), std::get<2>(kb[i]), 1e-9) << i;
    EXPECT_NEAR(std::get<3>(ka[i]), std::get<3>(kb[i]), 1e-9) << i;
    EXPECT_NEAR(std::get<4>(ka[i]), std::get<4>(kb[i]), 1e-9) << i;
  }
}

TEST(LevelRegions, SlabBySlabGivesTheHorizontalRegionsOfTheWholeFit) {
  for (double jitter : {0.0, 0.3}) {
    SCOPED_TRACE(jitter);
    // The whole fit in the faces' own order; the slabs in height order.
    const std::vector<BoundaryFace> faces = Faces(jitter);
    const std::vector<BoundaryFace> sorted = SortedFaces(jitter);
    absl::StatusOr<PlanarRegionSet> whole_set = FitPlanarRegions(faces, Grid(), {});
    ASSERT_TRUE(whole_set.ok()) << whole_set.status();
    const std::vector<PlanarRegion> whole = NearHorizontal(whole_set->regions);
    // Floors at 0 and 3, ceilings at 2.5 and (stepped, one region) 5.5, the table's top and
    // underside, the shelf's two sides.
    EXPECT_EQ(whole.size(), 8u);
    // One slab; slabs of one height each (a floor has 4 × 3 m / kRes² = 3,072 faces); slabs
    // of a few heights.
    for (size_t slab : {size_t{1} << 20, size_t{1}, size_t{5000}}) {
      SCOPED_TRACE(slab);
      absl::StatusOr<std::vector<PlanarRegion>> by_slab = LevelRegions(sorted, Grid(), {}, slab);
      ASSERT_TRUE(by_slab.ok()) << by_slab.status();
      ExpectSameRegions(whole, NearHorizontal(*by_slab));
      for (size_t i = 0; i < by_slab->size(); ++i) {
        EXPECT_EQ((*by_slab)[i].id, static_cast<int>(i));
        EXPECT_TRUE((*by_slab)[i].faces.empty());
      }
    }
  }
}

TEST(LevelRegions, HorizontalFacesAloneWouldSplitASteppedCeiling) {
  // Why the slabs keep every face: fitted without its risers, the sloping ceiling falls apart
  // at its steps, and §5.2's histogram would see pieces instead of one ceiling.
  const std::vector<BoundaryFace> faces = Faces(0);
  std::vector<BoundaryFace> horizontal;
  for (const BoundaryFace& f : faces) {
    if (f.axis == 2) horizontal.push_back(f);
  }
  absl::StatusOr<PlanarRegionSet> alone = FitPlanarRegions(horizontal, Grid(), {});
  ASSERT_TRUE(alone.ok());
  EXPECT_GT(NearHorizontal(alone->regions).size(), 8u);
}

TEST(LevelRegions, LevelsAreThoseOfTheWholeFit) {
  absl::StatusOr<PlanarRegionSet> whole = FitPlanarRegions(Faces(0.3), Grid(), {});
  ASSERT_TRUE(whole.ok()) << whole.status();
  absl::StatusOr<std::vector<PlanarRegion>> by_slab = LevelRegions(SortedFaces(0.3), Grid(), {}, 1);
  ASSERT_TRUE(by_slab.ok()) << by_slab.status();
  absl::StatusOr<std::vector<Level>> a = SplitLevelsFromRegions(whole->regions);
  absl::StatusOr<std::vector<Level>> b = SplitLevelsFromRegions(*by_slab);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->size(), 2u);
  ASSERT_EQ(b->size(), 2u);
  for (size_t k = 0; k < 2; ++k) {
    EXPECT_NEAR((*a)[k].floor_z, (*b)[k].floor_z, 1e-9);
    EXPECT_NEAR((*a)[k].ceiling_z, (*b)[k].ceiling_z, 1e-9);
    EXPECT_NEAR((*a)[k].dominant_ceiling_z, (*b)[k].dominant_ceiling_z, 1e-9);
    EXPECT_NEAR((*a)[k].split_z_low, (*b)[k].split_z_low, 1e-9);
    EXPECT_NEAR((*a)[k].split_z_high, (*b)[k].split_z_high, 1e-9);
  }
  EXPECT_NEAR((*b)[0].floor_z, 0.0, kRes);
  EXPECT_NEAR((*b)[1].floor_z, 3.0, kRes);
}

TEST(LevelRegions, BandHoldsTheFacesOfTheLevelAndItsMargin) {
  const std::vector<BoundaryFace> faces = SortedFaces(0);
  absl::StatusOr<FaceHeights> heights = HeightsOf(faces, Grid());
  ASSERT_TRUE(heights.ok()) << heights.status();
  Level level;
  level.split_z_low = 2.75;
  level.split_z_high = 6.0;
  const auto [begin, end] = LevelBand(*heights, level, 0.5);
  const std::span<const BoundaryFace> band = std::span(faces).subspan(begin, end - begin);
  size_t expected = 0;
  for (const BoundaryFace& f : faces) expected += f.center.z() >= 2.25 && f.center.z() < 6.5;
  EXPECT_EQ(band.size(), expected);
  EXPECT_LT(band.size(), faces.size());
  for (const BoundaryFace& f : band) {
    EXPECT_GE(f.center.z(), 2.25);
    EXPECT_LT(f.center.z(), 6.5);
  }
  // The lower room's ceiling (2.5 m) is within the margin; its floor is not.
  EXPECT_TRUE(std::any_of(band.begin(), band.end(), [](const BoundaryFace& f) {
    return f.axis == 2 && std::abs(f.center.z() - 2.5) < 1e-9;
  }));
  EXPECT_FALSE(std::any_of(band.begin(), band.end(), [](const BoundaryFace& f) {
    return f.axis == 2 && std::abs(f.center.z()) < 1e-9;
  }));
}

TEST(LevelRegions, ReadErrorsArePassedOn) {
  const std::vector<BoundaryFace> faces = SortedFaces(0);
  absl::StatusOr<FaceHeights> heights = HeightsOf(faces, Grid());
  ASSERT_TRUE(heights.ok());
  const ReadFacesFn failing = [](uint64_t, uint64_t) -> absl::StatusOr<std::vector<BoundaryFace>> {
    return absl::DataLossError("faces file truncated");
  };
  EXPECT_EQ(LevelRegions(*heights, failing, Grid()).status().code(), absl::StatusCode::kDataLoss);
}

TEST(LevelRegions, RejectsBadSlabs) {
  const std::vector<BoundaryFace> faces = SortedFaces(0);
  EXPECT_EQ(LevelRegions(faces, Grid(), {}, 0).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(LevelRegions(faces, Grid(), {}, 100, -1).status().code(),
            absl::StatusCode::kInvalidArgument);
  std::vector<BoundaryFace> bad = faces;
  bad[10].center.z() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(LevelRegions(bad, Grid()).status().code(), absl::StatusCode::kInvalidArgument);
  // Faces out of height order are refused, not fitted in wrong slabs.
  std::vector<BoundaryFace> unsorted = faces;
  std::swap(unsorted.front(), unsorted.back());
  EXPECT_EQ(LevelRegions(unsorted, Grid()).status().code(), absl::StatusCode::kInvalidArgument);
  absl::StatusOr<std::vector<PlanarRegion>> none = LevelRegions({}, Grid());
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(none->empty());
}

}  // namespace
}  // namespace carvemap

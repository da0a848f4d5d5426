#include "services/mesh/sorted_faces.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

OctreeGrid Grid() { return OctreeGrid{5}; }  // 6.25 cm
constexpr double kRes = 0.0625;

// Faces on a few lattice heights (horizontal faces on cell planes, vertical ones half-way up a
// cell), in a shuffled order.
std::vector<BoundaryFace> Shuffled(uint32_t seed) {
  std::vector<BoundaryFace> faces;
  for (int i = 0; i < 40; ++i) {
    for (int axis = 0; axis < 3; ++axis) {
      BoundaryFace f;
      f.axis = static_cast<int8_t>(axis);
      f.sign = static_cast<int8_t>(i % 2 ? 1 : -1);
      f.size_m = kRes;
      const double z = (i % 7) * kRes + (axis == 2 ? 0.0 : kRes / 2);
      f.center = Eigen::Vector3d((i % 5) * kRes, (i / 5) * kRes, z);
      faces.push_back(f);
    }
  }
  std::mt19937 rng(seed);
  std::shuffle(faces.begin(), faces.end(), rng);
  return faces;
}

TEST(SortedFaces, SortIsATotalOrder) {
  // Whatever order the chunks' faces come in, the sorted faces are the same.
  std::vector<BoundaryFace> a = Shuffled(1), b = Shuffled(2);
  ASSERT_TRUE(SortFacesByHeight(a).ok());
  ASSERT_TRUE(SortFacesByHeight(b).ok());
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].center, b[i].center) << i;
    ASSERT_EQ(a[i].axis, b[i].axis) << i;
    ASSERT_EQ(a[i].sign, b[i].sign) << i;
    if (i > 0) ASSERT_LE(a[i - 1].center.z(), a[i].center.z()) << i;
  }
  std::vector<BoundaryFace> bad = Shuffled(3);
  bad[5].center.x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(SortFacesByHeight(bad).code(), absl::StatusCode::kInvalidArgument);
}

TEST(SortedFaces, HeightsIndexTheRangesOfHeights) {
  std::vector<BoundaryFace> faces = Shuffled(4);
  ASSERT_TRUE(SortFacesByHeight(faces).ok());
  absl::StatusOr<FaceHeights> heights = HeightsOf(faces, Grid());
  ASSERT_TRUE(heights.ok()) << heights.status();
  EXPECT_EQ(heights->size(), faces.size());
  // 7 cell planes and the 7 half-way heights above them.
  EXPECT_EQ(heights->keys.size(), 14u);
  ASSERT_EQ(heights->starts.size(), heights->keys.size() + 1);
  for (double lo : {-1.0, 0.0, 0.03, 0.0625, 0.1, 0.2, 0.5}) {
    for (double hi : {0.0, 0.05, 0.1875, 0.3, 1.0, std::numeric_limits<double>::infinity()}) {
      const auto [begin, end] = heights->Range(lo, hi);
      size_t expected_begin = 0, expected_count = 0;
      for (const BoundaryFace& f : faces) {
        expected_begin += f.center.z() < lo;
        expected_count += f.center.z() >= lo && f.center.z() < hi;
      }
      EXPECT_EQ(begin, expected_begin) << lo << " " << hi;
      EXPECT_EQ(end - begin, expected_count) << lo << " " << hi;
    }
  }
  const auto [all_begin, all_end] = heights->Range(-std::numeric_limits<double>::infinity(),
                                                   std::numeric_limits<double>::infinity());
  EXPECT_EQ(all_begin, 0u);
  EXPECT_EQ(all_end, faces.size());
  absl::StatusOr<std::vector<BoundaryFace>> read = ReadFromSpan(faces)(3, 9);
  ASSERT_TRUE(read.ok());
  ASSERT_EQ(read->size(), 6u);
  EXPECT_EQ((*read)[0].center, faces[3].center);
  EXPECT_EQ(ReadFromSpan(faces)(3, faces.size() + 1).status().code(),
            absl::StatusCode::kOutOfRange);
}

TEST(SortedFaces, HeightsRefuseUnsortedOrNonFiniteFaces) {
  std::vector<BoundaryFace> faces = Shuffled(5);  // not sorted
  EXPECT_EQ(HeightsOf(faces, Grid()).status().code(), absl::StatusCode::kInvalidArgument);
  ASSERT_TRUE(SortFacesByHeight(faces).ok());
  faces.back().center.z() = std::numeric_limits<double>::infinity();
  EXPECT_EQ(HeightsOf(faces, Grid()).status().code(), absl::StatusCode::kInvalidArgument);
  FaceHeights empty;
  empty.half_cell_m = kRes / 2;
  EXPECT_EQ(empty.size(), 0u);
  EXPECT_EQ(empty.Range(0, 1), (std::pair<uint64_t, uint64_t>{0, 0}));
}

}  // namespace
}  // namespace carvemap

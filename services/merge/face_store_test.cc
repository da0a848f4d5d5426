#include "services/merge/face_store.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "services/mesh/voxel_faces_testing.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

OctreeGrid Grid() { return OctreeGrid{5}; }  // 6.25 cm
constexpr double kRes = 0.0625;

// A 3 × 2 m room 4.5 m tall with a 1 m box in it: faces over five 1 m buckets, some coarse
// (jitter off, so they sit on the lattice).
std::vector<BoundaryFace> RoomFaces() {
  auto room = [](const Eigen::Vector3d& p) {
    auto box = [&p](const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
      return std::min({p.x() - lo.x(), hi.x() - p.x(), p.y() - lo.y(), hi.y() - p.y(),
                       p.z() - lo.z(), hi.z() - p.z()});
    };
    return std::min(box({0, 0, 0}, {3, 2, 4.5}), -box({1, 0.5, 0}, {2, 1.5, 1}));
  };
  return VoxelFaces(kRes, Eigen::Vector3i(-1, -1, -1), Eigen::Vector3i(49, 33, 73), room);
}

fs::path Scratch() {
  const fs::path dir = fs::path(::testing::TempDir()) / "face_store_test";
  fs::create_directories(dir);
  return dir;
}

void ExpectSame(const std::vector<BoundaryFace>& a, const std::vector<BoundaryFace>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].center, b[i].center) << i;
    ASSERT_EQ(a[i].size_m, b[i].size_m) << i;
    ASSERT_EQ(a[i].isosurface_m, b[i].isosurface_m) << i;
    ASSERT_EQ(a[i].exterior_weight, b[i].exterior_weight) << i;
    ASSERT_EQ(a[i].axis, b[i].axis) << i;
    ASSERT_EQ(a[i].sign, b[i].sign) << i;
    ASSERT_EQ(a[i].exterior_observed, b[i].exterior_observed) << i;
  }
}

TEST(FaceStore, GivesTheFacesSortedWhateverTheirOrder) {
  std::vector<BoundaryFace> faces = RoomFaces();
  for (size_t i = 0; i < faces.size(); ++i) {
    faces[i].exterior_weight = static_cast<float>(i % 13);
    faces[i].exterior_observed = i % 3 == 0;
  }
  std::vector<BoundaryFace> shuffled = faces;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(5));
  std::vector<BoundaryFace> sorted = faces;
  ASSERT_TRUE(SortFacesByHeight(sorted).ok());
  absl::StatusOr<FaceHeights> heights = HeightsOf(sorted, Grid());
  ASSERT_TRUE(heights.ok());

  const fs::path path = Scratch() / "sorted";
  {
    absl::StatusOr<std::unique_ptr<FaceStore>> store = FaceStore::Create(path.string(), Grid());
    ASSERT_TRUE(store.ok()) << store.status();
    // Chunk by chunk, as the merge adds them.
    for (size_t at = 0; at < shuffled.size(); at += 1000) {
      const size_t n = std::min<size_t>(1000, shuffled.size() - at);
      ASSERT_TRUE((*store)->Add(std::span(shuffled).subspan(at, n)).ok());
    }
    EXPECT_EQ((*store)->Read(0, 1).status().code(), absl::StatusCode::kOutOfRange);  // unsorted
    ASSERT_TRUE((*store)->Finish().ok());
    EXPECT_EQ((*store)->size(), faces.size());
    EXPECT_EQ((*store)->heights().keys, heights->keys);
    EXPECT_EQ((*store)->heights().starts, heights->starts);
    absl::StatusOr<std::vector<BoundaryFace>> all = (*store)->Read(0, faces.size());
    ASSERT_TRUE(all.ok()) << all.status();
    ExpectSame(*all, sorted);
    // A range is the same range of the sorted faces.
    const auto [begin, end] = (*store)->heights().Range(1.0, 2.5);
    absl::StatusOr<std::vector<BoundaryFace>> band = (*store)->Reader()(begin, end);
    ASSERT_TRUE(band.ok());
    ExpectSame(*band, std::vector<BoundaryFace>(sorted.begin() + begin, sorted.begin() + end));
    EXPECT_GT(band->size(), 0u);
    EXPECT_EQ((*store)->Read(0, faces.size() + 1).status().code(), absl::StatusCode::kOutOfRange);
    EXPECT_EQ((*store)->Add(faces).code(), absl::StatusCode::kFailedPrecondition);
    // What the merge reads beside the faces.
    double area = 0, max_size = 0;
    for (const BoundaryFace& f : faces) {
      area += f.area_m2();
      max_size = std::max(max_size, f.size_m);
    }
    EXPECT_NEAR((*store)->area_m2(), area, 1e-6);
    EXPECT_EQ((*store)->max_size_m(), max_size);
    // The walls' faces at x = 0 and y = 2 m reach half a cell past them.
    EXPECT_NEAR((*store)->xy_min().x(), -kRes / 2, 1e-9);
    EXPECT_NEAR((*store)->xy_max().y(), 2.0 + kRes / 2, 1e-9);
    // Only the sorted file is left while the store lives.
    size_t files = 0;
    for ([[maybe_unused]] const auto& e : fs::directory_iterator(Scratch())) ++files;
    EXPECT_EQ(files, 1u);
  }
  // The store removes its file.
  EXPECT_FALSE(fs::exists(path));
}

TEST(FaceStore, ATruncatedFileIsDataLossNamingIt) {
  const fs::path path = Scratch() / "truncated";
  absl::StatusOr<std::unique_ptr<FaceStore>> store = FaceStore::Create(path.string(), Grid());
  ASSERT_TRUE(store.ok());
  const std::vector<BoundaryFace> faces = RoomFaces();
  ASSERT_TRUE((*store)->Add(faces).ok());
  ASSERT_TRUE((*store)->Finish().ok());
  fs::resize_file(path, fs::file_size(path) / 2);
  const absl::Status s = (*store)->Read(0, faces.size()).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(s.message().find(path.string()), std::string::npos) << s;
}

TEST(FaceStore, RefusesFacesThatAreNotFiniteAndFoldersThatDoNotExist) {
  absl::StatusOr<std::unique_ptr<FaceStore>> store =
      FaceStore::Create((Scratch() / "nan").string(), Grid());
  ASSERT_TRUE(store.ok());
  BoundaryFace f;
  f.center = Eigen::Vector3d(0, std::nan(""), 1);
  EXPECT_EQ((*store)->Add(std::vector<BoundaryFace>{f}).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(FaceStore::Create((Scratch() / "no" / "such").string(), Grid()).status().code(),
            absl::StatusCode::kUnavailable);
}

}  // namespace
}  // namespace carvemap

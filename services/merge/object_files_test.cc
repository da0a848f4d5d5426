#include "services/merge/object_files.h"

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/test_meshes.h"

namespace carvemap {
namespace {

using testing::ReadFileBytes;
using testing::Tetrahedron;

namespace fs = std::filesystem;

class ObjectFilesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(::testing::TempDir()) / "object_files_test";
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "mesh" / "objects");
    // A stale object of an earlier merge, which must go.
    std::ofstream(dir_ / "mesh" / "objects" / "7.ply") << "stale";
  }
  fs::path dir_;
};

// Pieces stored by key as a stream would finish them (out of object order), objects made of
// one or several: each object's file is its pieces appended in key order, and objects.ply and
// combined.ply are WritePly's bytes of the objects (and the building) joined with their ids.
TEST_F(ObjectFilesTest, ObjectsAreTheirPiecesJoinedAndTheJoinedFilesTheirConcatenation) {
  const TriangleMesh a = Tetrahedron({0, 0, 0}, 1), b = Tetrahedron({0, 0, 2}, 0.5f),
                     c = Tetrahedron({3, 0, 0}, 1), building = Tetrahedron({-5, -5, -5}, 20);
  absl::StatusOr<std::unique_ptr<ObjectPieceFile>> pieces =
      ObjectPieceFile::Create((dir_ / "pieces").string());
  ASSERT_TRUE(pieces.ok()) << pieces.status();
  ASSERT_TRUE((*pieces)->Add(40, c).ok());
  ASSERT_TRUE((*pieces)->Add(12, b).ok());
  ASSERT_TRUE((*pieces)->Add(3, a).ok());
  EXPECT_EQ((*pieces)->Add(3, a).code(), absl::StatusCode::kInvalidArgument);
  ASSERT_TRUE((*pieces)->FinishWriting().ok());
  EXPECT_EQ((*pieces)->bytes(), 3u * 8u * 12u);

  ObjectLayout layout;
  layout.objects.resize(2);
  layout.objects[0].id = 0;
  layout.objects[1].id = 1;
  layout.pieces = {{3, 12}, {40}};
  absl::StatusOr<ObjectFilesResult> result =
      WriteObjectFiles(layout, **pieces, building, dir_, /*threads=*/2);
  ASSERT_TRUE(result.ok()) << result.status();

  TriangleMesh first = a;
  first.Append(b);
  ASSERT_TRUE(WritePly((dir_ / "expect_0.ply").string(), first).ok());
  ASSERT_TRUE(WritePly((dir_ / "expect_1.ply").string(), c).ok());
  EXPECT_EQ(ReadFileBytes(dir_ / "mesh/objects/0.ply"), ReadFileBytes(dir_ / "expect_0.ply"));
  EXPECT_EQ(ReadFileBytes(dir_ / "mesh/objects/1.ply"), ReadFileBytes(dir_ / "expect_1.ply"));
  EXPECT_FALSE(fs::exists(dir_ / "mesh/objects/7.ply"));
  EXPECT_EQ(result->triangles, (std::vector<uint64_t>{8, 4}));
  ASSERT_EQ(result->crossings.size(), 2u);
  EXPECT_EQ(result->crossings[0].pairs, 0u);

  TriangleMesh objects = first;
  objects.Append(c);
  const std::vector<int> ids = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1};
  ASSERT_TRUE(WritePly((dir_ / "expect_objects.ply").string(), objects, &ids, "object").ok());
  EXPECT_EQ(ReadFileBytes(dir_ / "mesh/objects.ply"), ReadFileBytes(dir_ / "expect_objects.ply"));
  TriangleMesh combined = building;
  combined.Append(objects);
  std::vector<int> with_building = {-1, -1, -1, -1};
  with_building.insert(with_building.end(), ids.begin(), ids.end());
  ASSERT_TRUE(
      WritePly((dir_ / "expect_combined.ply").string(), combined, &with_building, "object").ok());
  EXPECT_EQ(ReadFileBytes(dir_ / "mesh/combined.ply"), ReadFileBytes(dir_ / "expect_combined.ply"));
}

// A scratch file cut short (a full disk) or a key never stored is an error naming the file,
// and no joined file is left as if complete.
TEST_F(ObjectFilesTest, TruncatedScratchOrMissingPieceIsAnError) {
  absl::StatusOr<std::unique_ptr<ObjectPieceFile>> pieces =
      ObjectPieceFile::Create((dir_ / "pieces").string());
  ASSERT_TRUE(pieces.ok()) << pieces.status();
  ASSERT_TRUE((*pieces)->Add(0, Tetrahedron({0, 0, 0}, 1)).ok());
  ASSERT_TRUE((*pieces)->Add(5, Tetrahedron({2, 0, 0}, 1)).ok());
  ASSERT_TRUE((*pieces)->FinishWriting().ok());
  const std::vector<uint64_t> missing = {9};
  EXPECT_EQ((*pieces)->Read(missing).status().code(), absl::StatusCode::kNotFound);

  fs::resize_file(dir_ / "pieces", 100);
  const std::vector<uint64_t> second = {5};
  const absl::Status cut = (*pieces)->Read(second).status();
  EXPECT_EQ(cut.code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(cut.message().find((dir_ / "pieces").string()), std::string::npos) << cut;

  ObjectLayout layout;
  layout.objects.resize(1);
  layout.pieces = {{5}};
  const absl::StatusOr<ObjectFilesResult> result =
      WriteObjectFiles(layout, **pieces, TriangleMesh{}, dir_, 1);
  EXPECT_EQ(result.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_FALSE(fs::exists(dir_ / "mesh/objects.ply"));
  EXPECT_FALSE(fs::exists(dir_ / "mesh/combined.ply"));
  // The scratch file goes with its owner.
  *pieces = nullptr;
  EXPECT_FALSE(fs::exists(dir_ / "pieces"));
}

}  // namespace
}  // namespace carvemap

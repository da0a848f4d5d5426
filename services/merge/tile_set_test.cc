#include "services/merge/tile_set.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "services/merge/merge_test_util.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using testing::FreshDir;
using testing::Leaf;

TEST(ParseTileFileName, AcceptsOnlyCanonicalNames) {
  ChunkKey key;
  ASSERT_TRUE(ParseTileFileName("c_-3_7_-1.h5", key));
  EXPECT_EQ(key, ChunkKey(-3, 7, -1));
  ASSERT_TRUE(ParseTileFileName(TileFileName(ChunkKey(12, 0, -40)), key));
  EXPECT_EQ(key, ChunkKey(12, 0, -40));
  for (const char* bad : {"c_1_2_3.h5.partial", "c_1_2.h5", "c_1_2_3_4.h5", "c_01_2_3.h5",
                          "c_+1_2_3.h5", "x_1_2_3.h5", "c_1_2_3.h6", "c__2_3.h5", "c_1_2_3"}) {
    EXPECT_FALSE(ParseTileFileName(bad, key)) << bad;
  }
}

TEST(TileSet, MissingDirIsNotFound) {
  auto set = TileSet::Open("/nonexistent/tiles", 0, 0);
  EXPECT_EQ(set.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(set.status().message().find("/nonexistent/tiles"), std::string::npos);
}

class TileSetTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = FreshDir();
    TileData a;  // k = 5: 6.25 cm
    a.chunk = ChunkKey(-1, 0, 0);
    a.leaves = {Leaf(1, Eigen::Vector3i(0, 0, 0), 0.9),   // 1 m node at the chunk's corner
                Leaf(5, Eigen::Vector3i(31, 31, 31), 0.2)};  // finest, at the far corner
    TileData b;
    b.chunk = ChunkKey(0, 0, 0);
    b.leaves = {Leaf(0, Eigen::Vector3i::Zero(), 0.3)};  // the whole chunk
    ASSERT_TRUE(WriteTile(dir_, a).ok());
    ASSERT_TRUE(WriteTile(dir_, b).ok());
    std::ofstream(dir_ + "/c_5_5_5.h5.partial") << "garbage from a crashed writer";
    std::ofstream(dir_ + "/README") << "not a tile";
  }
  std::string dir_;
};

TEST_F(TileSetTest, IndexesNamesAndLearnsTheGrid) {
  auto set = TileSet::Open(dir_, 0, 1 << 20);
  ASSERT_TRUE(set.ok()) << set.status();
  EXPECT_EQ((*set)->grid().chunk_depth, 5);
  ASSERT_EQ((*set)->chunks().size(), 2u);
  EXPECT_EQ((*set)->chunks()[0], ChunkKey(-1, 0, 0));
  EXPECT_TRUE((*set)->Contains(ChunkKey(0, 0, 0)));
  EXPECT_FALSE((*set)->Contains(ChunkKey(5, 5, 5)));
}

TEST_F(TileSetTest, QueriesFindTheCoveringLeafAcrossChunks) {
  auto set = TileSet::Open(dir_, 0, 1 << 20);
  ASSERT_TRUE(set.ok());
  TileSet& s = **set;
  auto q = s.Query(Eigen::Vector3d(-1.5, 0.5, 0.9));  // inside a's 1 m node
  ASSERT_TRUE(q.ok());
  EXPECT_TRUE(q->stored);
  EXPECT_EQ(q->node.depth, 1);
  EXPECT_NEAR(q->stats.p(), 0.9, 1e-12);
  q = s.Query(Eigen::Vector3d(-0.03, 1.97, 1.97));  // a's finest corner leaf
  ASSERT_TRUE(q.ok());
  EXPECT_TRUE(q->stored);
  EXPECT_EQ(q->node.depth, 5);
  q = s.Query(Eigen::Vector3d(-0.5, 0.5, 0.5));  // in a, but no row: unobserved
  ASSERT_TRUE(q.ok());
  EXPECT_FALSE(q->stored);
  EXPECT_FALSE(q->stats.observed());
  q = s.Query(Eigen::Vector3d(1.99, 0.01, 1.0));  // b is one leaf
  ASSERT_TRUE(q.ok());
  EXPECT_TRUE(q->stored);
  EXPECT_EQ(q->node.depth, 0);
  q = s.Query(Eigen::Vector3d(9, 9, 9));  // no tile
  ASSERT_TRUE(q.ok());
  EXPECT_FALSE(q->stored);
  EXPECT_EQ(q->chunk, ChunkKey(4, 4, 4));
}

TEST_F(TileSetTest, CacheIsBoundedAndLru) {
  auto small = TileSet::Open(dir_, 0, 0);  // holds only the newest tile
  ASSERT_TRUE(small.ok());
  for (const ChunkKey& c : {ChunkKey(-1, 0, 0), ChunkKey(0, 0, 0), ChunkKey(-1, 0, 0)}) {
    ASSERT_TRUE((*small)->Get(c).ok());
  }
  EXPECT_EQ((*small)->tile_reads(), 3u);

  auto big = TileSet::Open(dir_, 0, 1 << 20);
  ASSERT_TRUE(big.ok());
  auto first = (*big)->Get(ChunkKey(-1, 0, 0));
  ASSERT_TRUE(first.ok());
  for (const ChunkKey& c : {ChunkKey(0, 0, 0), ChunkKey(-1, 0, 0), ChunkKey(0, 0, 0)}) {
    ASSERT_TRUE((*big)->Get(c).ok());
  }
  EXPECT_EQ((*big)->tile_reads(), 2u);
  EXPECT_GT((*big)->cached_bytes(), 0u);
  EXPECT_EQ((*first)->leaves.size(), 2u);  // still valid
  EXPECT_EQ((*big)->Get(ChunkKey(7, 7, 7)).status().code(), absl::StatusCode::kNotFound);

  (*big)->ReleaseCache();
  EXPECT_EQ((*big)->cached_bytes(), 0u);
  EXPECT_EQ((*first)->leaves.size(), 2u);  // still valid
  ASSERT_TRUE((*big)->Get(ChunkKey(-1, 0, 0)).ok());
  EXPECT_EQ((*big)->tile_reads(), 3u);  // read again
}

TEST_F(TileSetTest, CorruptOrMisnamedOrForeignTilesAreRejectedNamingTheFile) {
  std::ofstream(dir_ + "/c_3_0_0.h5") << "not an hdf5 file";
  fs::copy_file(dir_ + "/c_0_0_0.h5", dir_ + "/c_4_0_0.h5");
  TileData fine;
  fine.grid.chunk_depth = 6;
  fine.chunk = ChunkKey(6, 0, 0);
  ASSERT_TRUE(WriteTile(dir_, fine).ok());
  auto set = TileSet::Open(dir_, 0.0625, 0);
  ASSERT_TRUE(set.ok());
  auto bad = (*set)->Get(ChunkKey(3, 0, 0));
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(bad.status().message().find("c_3_0_0.h5"), std::string::npos);
  auto misnamed = (*set)->Get(ChunkKey(4, 0, 0));
  EXPECT_EQ(misnamed.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(misnamed.status().message().find("c_4_0_0.h5"), std::string::npos);
  auto foreign = (*set)->Get(ChunkKey(6, 0, 0));
  EXPECT_EQ(foreign.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(foreign.status().message().find("c_6_0_0.h5"), std::string::npos);
}

}  // namespace
}  // namespace carvemap

#include "services/merge/octomap_writer.h"

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <optional>
#include <random>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include "services/merge/merge_test_util.h"
#include "services/merge/tile_set.h"
#include "storage/atomic_file.h"
#include "storage/tile_store.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using testing::FreshDir;
using testing::Leaf;
using testing::RandomTile;

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string BodyAfterData(const std::string& bt) {
  const size_t at = bt.find("\ndata\n");
  return at == std::string::npos ? std::string() : bt.substr(at + 6);
}

// Builds the same tree with liboctomap itself: every finest cell of every leaf that has a value
// set to it (lazily; the callers then make the inner nodes and prune, as OctoMap's own tools
// would leave the tree).
void FillOctomap(const TileData& tile, octomap::OcTree& tree,
                 const std::function<std::optional<float>(const LeafStats&)>& value_of) {
  const int k = tile.grid.chunk_depth;
  const int n = 1 << k;
  for (const TileLeaf& leaf : tile.leaves) {
    const std::optional<float> value = value_of(leaf.stats);
    if (!value) continue;
    const int side = 1 << (k - leaf.node.depth);
    const Eigen::Vector3i lo = tile.chunk * n + leaf.node.local * side;
    for (int x = 0; x < side; ++x) {
      for (int y = 0; y < side; ++y) {
        for (int z = 0; z < side; ++z) {
          const octomap::OcTreeKey key(lo.x() + x + kOctomapKeyOffset,
                                       lo.y() + y + kOctomapKeyOffset,
                                       lo.z() + z + kOctomapKeyOffset);
          tree.setNodeValue(key, *value, true);
        }
      }
    }
  }
}

// .bt: a log-odds by label.
std::optional<float> LabelValue(const LeafStats& stats) {
  const BtLabel label = BtLabelOf(stats);
  if (label == BtLabel::kUnknown) return std::nullopt;
  return label == BtLabel::kOccupied ? 2.0f : -2.0f;
}

// .ot: the leaf's own log-odds.
std::optional<float> LogOddsValue(const LeafStats& stats) {
  if (!stats.observed()) return std::nullopt;
  return OtLogOddsOf(stats);
}

// Chunks around the origin and apart, of every sign.
const std::vector<ChunkKey> kChunks = {{0, 0, 0},  {1, 0, 0},  {-1, 0, 0}, {-1, -1, -1},
                                       {3, -2, 1}, {0, 1, -1}, {-5, 7, 2}, {1, 1, 1}};

class OctreeBtWriterTest : public ::testing::TestWithParam<int> {};

TEST_P(OctreeBtWriterTest, RandomTilesRoundTripThroughLiboctomap) {
  const int k = GetParam();
  const std::string dir = FreshDir();
  const std::string tiles_dir = dir + "/tiles";
  fs::create_directories(tiles_dir);
  std::mt19937 rng(301 + k);
  const std::vector<ChunkKey>& keys = kChunks;
  octomap::OcTree reference(2.0 / (1 << k));
  for (const ChunkKey& key : keys) {
    TileData tile = RandomTile(rng, k, key);
    ASSERT_TRUE(WriteTile(tiles_dir, tile).ok());
    FillOctomap(tile, reference, LabelValue);
  }
  reference.updateInnerOccupancy();
  reference.prune();

  auto tiles = TileSet::Open(tiles_dir, 0, 1 << 20);
  ASSERT_TRUE(tiles.ok()) << tiles.status();
  const std::string path = dir + "/octree.bt";
  int visited = 0;
  auto stats = WriteOctomapFiles(**tiles, path, "", [&](const TileData&) {
    ++visited;
    return absl::OkStatus();
  });
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(visited, int(keys.size()));
  EXPECT_EQ(stats->num_tiles, keys.size());
  EXPECT_FALSE(fs::exists(PartialPath(path)));
  EXPECT_EQ(fs::file_size(path), stats->bt.bytes);

  // Byte for byte the tree liboctomap writes for the same content (after the header).
  std::stringstream ref_bytes;
  ASSERT_TRUE(reference.writeBinaryConst(ref_bytes));
  const std::string ours = ReadAll(path);
  EXPECT_EQ(BodyAfterData(ours), BodyAfterData(ref_bytes.str()));
  EXPECT_EQ(stats->bt.num_nodes, reference.size());

  octomap::OcTree tree(0.1);
  ASSERT_TRUE(tree.readBinary(path));
  EXPECT_EQ(tree.size(), stats->bt.num_nodes);
  EXPECT_DOUBLE_EQ(tree.getResolution(), (*tiles)->grid().resolution_m());

  // Many points: occupancy and unknown-ness agree with the tiles.
  std::uniform_real_distribution<double> ux(-12, 10), uy(-6, 16), uz(-4, 8);
  int known = 0, occupied = 0;
  for (int i = 0; i < 20000; ++i) {
    const Eigen::Vector3d x(ux(rng), uy(rng), uz(rng));
    absl::StatusOr<LeafQuery> q = (*tiles)->Query(x);
    ASSERT_TRUE(q.ok()) << q.status();
    const BtLabel expected = BtLabelOf(q->stats);
    const octomap::OcTreeNode* node = tree.search(x.x(), x.y(), x.z());
    if (expected == BtLabel::kUnknown) {
      EXPECT_EQ(node, nullptr) << x.transpose();
      continue;
    }
    ++known;
    ASSERT_NE(node, nullptr) << x.transpose();
    EXPECT_EQ(tree.isNodeOccupied(node), expected == BtLabel::kOccupied) << x.transpose();
    occupied += expected == BtLabel::kOccupied;
  }
  EXPECT_GT(known, 100);
  EXPECT_GT(occupied, 10);
  EXPECT_LT(occupied, known);

  if (fs::exists("/usr/bin/bt2vrml")) {
    const std::string cmd = "/usr/bin/bt2vrml '" + path + "' > '" + dir + "/bt2vrml.log' 2>&1";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << ReadAll(dir + "/bt2vrml.log");
    EXPECT_TRUE(fs::exists(path + ".wrl"));
  }
}

INSTANTIATE_TEST_SUITE_P(ChunkDepths, OctreeBtWriterTest, ::testing::Values(1, 2, 3, 4, 5));

class OctreeOtWriterTest : public ::testing::TestWithParam<int> {};

TEST_P(OctreeOtWriterTest, RandomTilesRoundTripThroughLiboctomap) {
  const int k = GetParam();
  const std::string dir = FreshDir();
  const std::string tiles_dir = dir + "/tiles";
  fs::create_directories(tiles_dir);
  std::mt19937 rng(307 + k);
  const std::vector<ChunkKey>& keys = kChunks;
  octomap::OcTree reference(2.0 / (1 << k));
  // setNodeValue clamps to these; ours stay within ±13.8 (kOtMinProbability).
  reference.setClampingThresMin(1e-7);
  reference.setClampingThresMax(1 - 1e-7);
  for (const ChunkKey& key : keys) {
    TileData tile = RandomTile(rng, k, key);
    // Runs of one value, so that some siblings prune: every third leaf takes its
    // predecessor's stats.
    for (size_t i = 1; i < tile.leaves.size(); ++i) {
      if (i % 3 == 0) tile.leaves[i].stats = tile.leaves[i - 1].stats;
    }
    ASSERT_TRUE(WriteTile(tiles_dir, tile).ok());
    FillOctomap(tile, reference, LogOddsValue);
  }
  reference.updateInnerOccupancy();
  reference.prune();

  auto tiles = TileSet::Open(tiles_dir, 0, 1 << 20);
  ASSERT_TRUE(tiles.ok()) << tiles.status();
  const std::string path = dir + "/octree.ot";
  auto stats = WriteOctomapFiles(**tiles, "", path);
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(stats->num_tiles, keys.size());
  EXPECT_FALSE(fs::exists(PartialPath(path)));
  EXPECT_EQ(fs::file_size(path), stats->ot.bytes);

  // Byte for byte the tree liboctomap writes for the same content (after the header).
  std::stringstream ref_bytes;
  ASSERT_TRUE(reference.write(ref_bytes));
  EXPECT_EQ(BodyAfterData(ReadAll(path)), BodyAfterData(ref_bytes.str()));
  EXPECT_EQ(stats->ot.num_nodes, reference.size());

  // Read by liboctomap's generic reader, as octovis and OctoMap's tools open .ot files.
  std::unique_ptr<octomap::AbstractOcTree> read(octomap::AbstractOcTree::read(path));
  ASSERT_NE(read, nullptr);
  auto* tree = dynamic_cast<octomap::OcTree*>(read.get());
  ASSERT_NE(tree, nullptr) << read->getTreeType();
  EXPECT_EQ(tree->size(), stats->ot.num_nodes);
  EXPECT_DOUBLE_EQ(tree->getResolution(), (*tiles)->grid().resolution_m());
  std::uniform_real_distribution<double> ux(-12, 10), uy(-6, 16), uz(-4, 8);
  int known = 0;
  for (int i = 0; i < 20000; ++i) {
    const Eigen::Vector3d x(ux(rng), uy(rng), uz(rng));
    absl::StatusOr<LeafQuery> q = (*tiles)->Query(x);
    ASSERT_TRUE(q.ok()) << q.status();
    const octomap::OcTreeNode* node = tree->search(x.x(), x.y(), x.z());
    if (!q->stats.observed()) {
      EXPECT_EQ(node, nullptr) << x.transpose();
      continue;
    }
    ++known;
    ASSERT_NE(node, nullptr) << x.transpose();
    EXPECT_EQ(node->getLogOdds(), OtLogOddsOf(q->stats)) << x.transpose();
    // The .bt's label is the sign of the log-odds (OctoMap's default threshold, p = 0.5).
    EXPECT_EQ(tree->isNodeOccupied(node), BtLabelOf(q->stats) == BtLabel::kOccupied);
  }
  EXPECT_GT(known, 100);
}

INSTANTIATE_TEST_SUITE_P(ChunkDepths, OctreeOtWriterTest, ::testing::Values(1, 2, 3, 4, 5));

TEST(OctreeOtWriter, LogOddsOfOccupancyFromTheCarveMapsProbability) {
  LeafStats open, solid, even, sure;
  open.Add(0.8, 1.0);   // p(open) 0.8: occupancy 0.2
  solid.Add(0.1, 2.0);  // occupancy 0.9
  even.Add(0.5, 1.0);
  sure.Add(1.0, 1.0);  // every ray agreed: clamped, finite
  EXPECT_NEAR(OtLogOddsOf(open), std::log(0.2 / 0.8), 1e-6);
  EXPECT_NEAR(OtLogOddsOf(solid), std::log(0.9 / 0.1), 1e-6);
  EXPECT_EQ(OtLogOddsOf(even), 0.0f);
  EXPECT_NEAR(OtLogOddsOf(sure), std::log(kOtMinProbability / (1 - kOtMinProbability)), 1e-4);
}

TEST(OctreeBtWriter, EightEqualChunksPruneIntoOneLeaf) {
  const std::string dir = FreshDir();
  fs::create_directories(dir + "/tiles");
  const int k = 5;
  for (int i = 0; i < 8; ++i) {
    TileData tile;
    tile.grid.chunk_depth = k;
    tile.chunk = ChunkKey(i & 1, (i >> 1) & 1, (i >> 2) & 1);
    tile.leaves = {Leaf(0, Eigen::Vector3i::Zero(), 0.9)};
    ASSERT_TRUE(WriteTile(dir + "/tiles", tile).ok());
  }
  auto tiles = TileSet::Open(dir + "/tiles", 0, 0);
  ASSERT_TRUE(tiles.ok());
  auto stats = WriteOctomapFiles(**tiles, dir + "/octree.bt", "");
  ASSERT_TRUE(stats.ok()) << stats.status();
  // The root, one inner node per depth down to 15 − k, and there the 4 m leaf.
  EXPECT_EQ(stats->bt.num_nodes, uint64_t(kOctomapTreeDepth - k));
  octomap::OcTree tree(dir + "/octree.bt");
  EXPECT_EQ(tree.size(), stats->bt.num_nodes);
  const octomap::OcTreeNode* node = tree.search(3.9, 0.1, 2.0);
  ASSERT_NE(node, nullptr);
  EXPECT_FALSE(tree.isNodeOccupied(node));
  EXPECT_EQ(tree.search(4.1, 0.1, 2.0), nullptr);
}

TEST(OctreeBtWriter, EmptyTilesGiveAnEmptyTreeOctomapReads) {
  const std::string dir = FreshDir();
  fs::create_directories(dir + "/tiles");
  TileData tile;  // no leaves at all
  ASSERT_TRUE(WriteTile(dir + "/tiles", tile).ok());
  auto tiles = TileSet::Open(dir + "/tiles", 0, 0);
  ASSERT_TRUE(tiles.ok());
  auto stats = WriteOctomapFiles(**tiles, dir + "/octree.bt", "");
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(stats->bt.num_nodes, 0u);
  EXPECT_EQ(BodyAfterData(ReadAll(dir + "/octree.bt")), "");
  octomap::OcTree tree(0.1);
  EXPECT_TRUE(tree.readBinary(dir + "/octree.bt"));
  EXPECT_EQ(tree.size(), 0u);
}

TEST(OctreeBtWriter, ChunkBeyondOctomapKeySpaceIsOutOfRange) {
  const std::string dir = FreshDir();
  fs::create_directories(dir + "/tiles");
  TileData tile;
  tile.grid.chunk_depth = 5;  // keys in [-1024, 1024)
  tile.chunk = ChunkKey(1024, 0, 0);
  tile.leaves = {Leaf(0, Eigen::Vector3i::Zero(), 0.9)};
  ASSERT_TRUE(WriteTile(dir + "/tiles", tile).ok());
  auto tiles = TileSet::Open(dir + "/tiles", 0, 0);
  ASSERT_TRUE(tiles.ok());
  auto stats = WriteOctomapFiles(**tiles, dir + "/octree.bt", "");
  EXPECT_EQ(stats.status().code(), absl::StatusCode::kOutOfRange);
  EXPECT_NE(stats.status().message().find("c_1024_0_0.h5"), std::string::npos);
  EXPECT_FALSE(fs::exists(dir + "/octree.bt"));
}

TEST(OctreeBtWriter, CorruptTileIsDataLossNamingItAndLeavesNoFile) {
  const std::string dir = FreshDir();
  fs::create_directories(dir + "/tiles");
  TileData tile;
  tile.leaves = {Leaf(1, Eigen::Vector3i(1, 0, 1), 0.9)};
  ASSERT_TRUE(WriteTile(dir + "/tiles", tile).ok());
  std::ofstream(dir + "/tiles/c_2_0_0.h5") << "not an hdf5 file";
  auto tiles = TileSet::Open(dir + "/tiles", 0.0625, 0);
  ASSERT_TRUE(tiles.ok());
  auto stats = WriteOctomapFiles(**tiles, dir + "/octree.bt", dir + "/octree.ot");
  EXPECT_EQ(stats.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(stats.status().message().find("c_2_0_0.h5"), std::string::npos);
  for (const char* name : {"/octree.bt", "/octree.ot"}) {
    EXPECT_FALSE(fs::exists(dir + name));
    EXPECT_FALSE(fs::exists(PartialPath(dir + name)));
  }
}

TEST(OctreeBtWriter, VisitorErrorStopsTheWrite) {
  const std::string dir = FreshDir();
  fs::create_directories(dir + "/tiles");
  TileData tile;
  tile.leaves = {Leaf(1, Eigen::Vector3i(1, 0, 1), 0.9)};
  ASSERT_TRUE(WriteTile(dir + "/tiles", tile).ok());
  auto tiles = TileSet::Open(dir + "/tiles", 0, 0);
  ASSERT_TRUE(tiles.ok());
  auto stats = WriteOctomapFiles(**tiles, dir + "/octree.bt", dir + "/octree.ot",
                                 [](const TileData&) { return absl::CancelledError("stop"); });
  EXPECT_EQ(stats.status().code(), absl::StatusCode::kCancelled);
  EXPECT_FALSE(fs::exists(dir + "/octree.bt"));
  EXPECT_FALSE(fs::exists(dir + "/octree.ot"));
}

}  // namespace
}  // namespace carvemap

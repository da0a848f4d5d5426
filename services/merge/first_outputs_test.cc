#include "services/merge/first_outputs.h"

#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <random>

#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include "services/merge/merge_test_util.h"
#include "storage/png_io.h"
#include "storage/tile_store.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using testing::FreshDir;
using testing::Leaf;

class FirstOutputsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = FreshDir();
    tiles_dir_ = dir_ + "/tiles";
    fs::create_directories(tiles_dir_);
    // k = 4 (12.5 cm): a 2 m interior chunk, a 1 m exterior node, and random tiles.
    TileData open;
    open.grid.chunk_depth = 4;
    open.chunk = ChunkKey(0, 0, 0);
    open.leaves = {Leaf(0, {0, 0, 0}, 0.8)};
    TileData solid;
    solid.grid.chunk_depth = 4;
    solid.chunk = ChunkKey(-1, 0, 0);
    solid.leaves = {Leaf(1, {1, 1, 0}, 0.1)};
    ASSERT_TRUE(WriteTile(tiles_dir_, open).ok());
    ASSERT_TRUE(WriteTile(tiles_dir_, solid).ok());
    std::mt19937 rng(7);
    ASSERT_TRUE(WriteTile(tiles_dir_, testing::RandomTile(rng, 4, ChunkKey(-3, 2, -1))).ok());
  }
  FirstOutputsOptions Options() const {
    FirstOutputsOptions o;
    o.tiles_dir = tiles_dir_;
    o.output_dir = dir_ + "/out";
    o.job = {{"job_id", "j42"}, {"counts", {{"frames", 1000}}}, {"outputs", {"scan.h5"}}};
    return o;
  }
  std::string dir_, tiles_dir_;
};

TEST_F(FirstOutputsTest, MergeTimeCountsTheStagesBeforeIt) {
  FirstOutputsOptions o = Options();
  o.job["stage_seconds"] = {{"carve", 5.0}, {"merge", 0.0}};
  o.seconds_before = 40.0;
  auto summary = MergeFirstOutputs(o, nullptr);
  ASSERT_TRUE(summary.ok()) << summary.status();
  const nlohmann::json& t = summary->job["timings_s"];
  EXPECT_DOUBLE_EQ(t["merge.total"].get<double>(), 40.0 + t["merge.first_outputs"].get<double>());
  EXPECT_DOUBLE_EQ(summary->job["stage_seconds"]["merge"].get<double>(),
                   t["merge.total"].get<double>());
  EXPECT_DOUBLE_EQ(summary->job["stage_seconds"]["carve"].get<double>(), 5.0);
}

TEST_F(FirstOutputsTest, WritesAllOutputs) {
  std::vector<std::string> stages;
  auto summary = MergeFirstOutputs(Options(), [&](const MergeProgress& p) {
    if (stages.empty() || stages.back() != p.stage) stages.push_back(p.stage);
    return true;
  });
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(stages, (std::vector<std::string>{"index", "octree_bt", "topdown_png", "job_json"}));
  const std::string out = dir_ + "/out";
  EXPECT_EQ(summary->num_tiles, 3u);
  EXPECT_DOUBLE_EQ(summary->resolution_m, 0.125);
  EXPECT_GE(summary->interior_volume_m3, 8.0);
  EXPECT_GE(summary->exterior_observed_volume_m3, 1.0);
  EXPECT_DOUBLE_EQ(summary->observed_volume_m3,
                   summary->interior_volume_m3 + summary->exterior_observed_volume_m3);

  octomap::OcTree tree(out + "/octree.bt");
  EXPECT_EQ(tree.size(), summary->num_bt_nodes);
  EXPECT_DOUBLE_EQ(tree.getResolution(), 0.125);
  const octomap::OcTreeNode* free_node = tree.search(1.0, 1.0, 1.0);
  ASSERT_NE(free_node, nullptr);
  EXPECT_FALSE(tree.isNodeOccupied(free_node));
  const octomap::OcTreeNode* solid_node = tree.search(-0.5, 1.5, 0.5);
  ASSERT_NE(solid_node, nullptr);
  EXPECT_TRUE(tree.isNodeOccupied(solid_node));
  EXPECT_EQ(tree.search(-1.5, 0.5, 0.5), nullptr);
  // octree.ot: the same places, with their log-odds.
  std::unique_ptr<octomap::AbstractOcTree> read(octomap::AbstractOcTree::read(out + "/octree.ot"));
  auto* ot = dynamic_cast<octomap::OcTree*>(read.get());
  ASSERT_NE(ot, nullptr);
  EXPECT_EQ(ot->size(), summary->num_ot_nodes);
  ASSERT_NE(ot->search(1.0, 1.0, 1.0), nullptr);
  EXPECT_LT(ot->search(1.0, 1.0, 1.0)->getLogOdds(), 0);
  ASSERT_NE(ot->search(-0.5, 1.5, 0.5), nullptr);
  EXPECT_GT(ot->search(-0.5, 1.5, 0.5)->getLogOdds(), 0);
  EXPECT_EQ(ot->search(-1.5, 0.5, 0.5), nullptr);

  auto png = ReadPngGray8(out + "/level_0/topdown.png");
  ASSERT_TRUE(png.ok()) << png.status();
  EXPECT_EQ(png->width, summary->topdown_width);
  EXPECT_EQ(png->height, summary->topdown_height);
  EXPECT_TRUE(fs::exists(out + "/level_0/topdown.json"));

  nlohmann::json job = nlohmann::json::parse(std::ifstream(out + "/job.json"));
  EXPECT_EQ(job, summary->job);
  EXPECT_EQ(job["job_id"], "j42");
  EXPECT_EQ(job["counts"]["frames"], 1000);  // the caller's counts are kept
  EXPECT_EQ(job["counts"]["tiles"], 3);
  EXPECT_EQ(job["counts"]["octree_bt_nodes"], summary->num_bt_nodes);
  EXPECT_EQ(job["counts"]["octree_ot_nodes"], summary->num_ot_nodes);
  EXPECT_EQ(job["versions"]["tile_format"], "carvemap-tile/2");
  EXPECT_TRUE(job["versions"].contains("carvemap"));
  EXPECT_DOUBLE_EQ(job["parameters"]["merge"]["resolution_m"].get<double>(), 0.125);
  for (const char* t : {"merge.index", "merge.octree_bt", "merge.topdown_png",
                        "merge.first_outputs", "merge.total"}) {
    EXPECT_TRUE(job["timings_s"].contains(t)) << t;
  }
  EXPECT_EQ(job["outputs"], (nlohmann::json{"scan.h5", "octree.bt", "octree.ot", "job.json",
                                            "level_0/topdown.json", "level_0/topdown.png",
                                            "index.html"}));
  for (const auto& entry : fs::recursive_directory_iterator(out)) {
    EXPECT_EQ(entry.path().string().find(".partial"), std::string::npos) << entry.path();
  }
}

TEST_F(FirstOutputsTest, CancelStopsWithoutOutputs) {
  auto summary = MergeFirstOutputs(Options(), [](const MergeProgress& p) {
    return !(p.stage == "octree_bt" && p.done == 1);
  });
  EXPECT_EQ(summary.status().code(), absl::StatusCode::kCancelled);
  EXPECT_FALSE(fs::exists(dir_ + "/out/octree.bt"));
  EXPECT_FALSE(fs::exists(dir_ + "/out/job.json"));
}

TEST_F(FirstOutputsTest, CorruptTileIsDataLossNamingIt) {
  std::ofstream(tiles_dir_ + "/c_0_0_1.h5") << "truncated";
  auto summary = MergeFirstOutputs(Options());
  EXPECT_EQ(summary.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(summary.status().message().find("c_0_0_1.h5"), std::string::npos);
  EXPECT_FALSE(fs::exists(dir_ + "/out/job.json"));
}

TEST_F(FirstOutputsTest, WrongResolutionIsInvalidArgument) {
  FirstOutputsOptions o = Options();
  o.resolution_m = 0.0625;
  auto summary = MergeFirstOutputs(o);
  EXPECT_EQ(summary.status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(FirstOutputsOptions, Validate) {
  FirstOutputsOptions o;
  EXPECT_EQ(o.Validate().code(), absl::StatusCode::kInvalidArgument);
  o.tiles_dir = "t";
  o.output_dir = "o";
  EXPECT_TRUE(o.Validate().ok());
  o.resolution_m = 0.1;
  EXPECT_EQ(o.Validate().code(), absl::StatusCode::kInvalidArgument);
  o.resolution_m = 0;
  o.job = nlohmann::json::array();
  EXPECT_EQ(o.Validate().code(), absl::StatusCode::kInvalidArgument);
  o.job = nullptr;
  o.topdown_max_height_m = 0;
  EXPECT_EQ(o.Validate().code(), absl::StatusCode::kInvalidArgument);
}

TEST(MergeFirstOutputs, MissingTilesDirIsNotFound) {
  FirstOutputsOptions o;
  o.tiles_dir = "/nonexistent/tiles";
  o.output_dir = FreshDir();
  EXPECT_EQ(MergeFirstOutputs(o).status().code(), absl::StatusCode::kNotFound);
}

// A throughput check, not run by default:
//   first_outputs_test --gtest_also_run_disabled_tests --gtest_filter=*Large*
TEST(MergeFirstOutputs, DISABLED_LargeSyntheticSet) {
  const std::string dir = FreshDir();
  fs::create_directories(dir + "/tiles");
  const int k = 6;  // 3.125 cm; leaves at depth 5 (6.25 cm), 32768 per chunk
  std::mt19937 rng(11);
  uint64_t leaves = 0;
  for (int c = 0; c < 64; ++c) {
    TileData tile;
    tile.grid.chunk_depth = k;
    tile.chunk = ChunkKey(c % 4 - 2, (c / 4) % 4 - 2, c / 16 - 1);
    for (uint64_t code = 0; code < 32768; ++code) {
      tile.leaves.push_back(Leaf(k - 1, MortonDecode(code), (rng() % 100) / 99.0));
    }
    leaves += tile.leaves.size();
    ASSERT_TRUE(WriteTile(dir + "/tiles", tile).ok());
  }
  FirstOutputsOptions o;
  o.tiles_dir = dir + "/tiles";
  o.output_dir = dir + "/out";
  o.cache_budget_bytes = 8 << 20;
  auto summary = MergeFirstOutputs(o);
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(summary->num_leaves, leaves);
  std::cout << leaves << " leaves in " << summary->num_tiles << " tiles: "
            << summary->job["timings_s"].dump() << ", octree.bt "
            << fs::file_size(summary->octree_bt_path) << " bytes, " << summary->num_bt_nodes
            << " nodes\n";
  octomap::OcTree tree(summary->octree_bt_path);
  EXPECT_EQ(tree.size(), summary->num_bt_nodes);
}

}  // namespace
}  // namespace carvemap

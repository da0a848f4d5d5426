// IngestScan on a small simulated scan: counts add up, spill files hold what the result says,
// progress is reported, and bad input gives errors that name the file.
#include "coordinator/scan_ingest.h"

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "coordinator/chunk_binning.h"
#include "services/sim/simulator.h"
#include "tests/support/thin_room_scan.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

class ScanIngestTest : public ::testing::Test {
 protected:
  // One thinned `room` scan for the whole suite (simulating is the slow part).
  static void SetUpTestSuite() {
    root_ = new std::string(fs::path(::testing::TempDir()) / "scan_ingest_test");
    fs::remove_all(*root_);
    absl::StatusOr<std::string> scan = testing::SimulateThinRoomScan(*root_ + "/sim", 2);
    ASSERT_TRUE(scan.ok()) << scan.status();
    scan_ = new std::string(*scan);
  }
  static void TearDownTestSuite() {
    delete root_;
    delete scan_;
  }
  static std::string* root_;
  static std::string* scan_;
};
std::string* ScanIngestTest::root_ = nullptr;
std::string* ScanIngestTest::scan_ = nullptr;

TEST_F(ScanIngestTest, IngestsAndCountsAddUp) {
  IngestOptions o;
  o.scan_path = *scan_;
  o.spill_dir = *root_ + "/spill";
  o.memory_budget_bytes = 1 << 20;  // small: forces several flushes
  int reports = 0;
  IngestProgress last;
  absl::StatusOr<IngestResult> r = IngestScan(o, [&](const IngestProgress& p) {
    ++reports;
    last = p;
  });
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_GT(r->frames, 0u);
  EXPECT_GT(r->rays, 0u);
  EXPECT_GT(r->returns, 0u);
  EXPECT_LE(r->returns, r->rays);
  EXPECT_GT(r->wedges, r->single_ray_wedges);
  EXPECT_GE(r->wedge_chunk_pairs, r->wedges);
  EXPECT_FALSE(r->default_covariance);  // the simulator writes /path_cov
  ASSERT_FALSE(r->chunks.empty());
  EXPECT_FALSE(r->bounds.isEmpty());
  EXPECT_GT(r->bounds.sizes().minCoeff(), 1.0);  // a room: metres in every direction

  uint64_t sum = 0;
  for (size_t i = 0; i < r->chunks.size(); ++i) {
    const SpilledChunk& c = r->chunks[i];
    sum += c.wedge_count;
    EXPECT_EQ(fs::file_size(c.path), c.file_bytes) << c.path;
    absl::StatusOr<ChunkSpillFile> f = ReadChunkSpillFile(c.path);
    ASSERT_TRUE(f.ok()) << f.status();
    EXPECT_EQ(f->wedge_count, c.wedge_count);
    EXPECT_EQ(f->chunk, c.chunk);
    if (i > 0) {
      EXPECT_TRUE(ChunkKeyLess{}(r->chunks[i - 1].chunk, c.chunk));
    }
  }
  EXPECT_EQ(sum, r->wedge_chunk_pairs);

  // The final report always comes, with every frame done.
  EXPECT_GE(reports, 1);
  EXPECT_EQ(last.frames_done, last.frames_total);
  EXPECT_EQ(last.frames_done, r->frames);
}

TEST_F(ScanIngestTest, SameScanSameSpillBytes) {
  IngestOptions o;
  o.scan_path = *scan_;
  o.spill_dir = *root_ + "/spill_a";
  absl::StatusOr<IngestResult> a = IngestScan(o);
  o.spill_dir = *root_ + "/spill_b";
  o.memory_budget_bytes = 256 << 10;  // flush pattern differs; the files must not
  absl::StatusOr<IngestResult> b = IngestScan(o);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->chunks.size(), b->chunks.size());
  for (size_t i = 0; i < a->chunks.size(); ++i) {
    absl::StatusOr<ChunkSpillFile> fa = ReadChunkSpillFile(a->chunks[i].path);
    absl::StatusOr<ChunkSpillFile> fb = ReadChunkSpillFile(b->chunks[i].path);
    ASSERT_TRUE(fa.ok() && fb.ok());
    EXPECT_EQ(fa->payload, fb->payload) << a->chunks[i].path;
  }
}

TEST_F(ScanIngestTest, GarbageFileErrorNamesFile) {
  const std::string bad = *root_ + "/garbage_scan.h5";
  std::ofstream(bad) << "this is not an HDF5 file";
  IngestOptions o;
  o.scan_path = bad;
  o.spill_dir = *root_ + "/spill_bad";
  absl::StatusOr<IngestResult> r = IngestScan(o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("garbage_scan.h5"), std::string::npos) << r.status();
}

TEST_F(ScanIngestTest, TruncatedScanErrorNamesFile) {
  const std::string bad = *root_ + "/truncated_scan.h5";
  fs::copy_file(*scan_, bad, fs::copy_options::overwrite_existing);
  fs::resize_file(bad, fs::file_size(bad) / 2);
  IngestOptions o;
  o.scan_path = bad;
  o.spill_dir = *root_ + "/spill_truncated";
  absl::StatusOr<IngestResult> r = IngestScan(o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("truncated_scan.h5"), std::string::npos) << r.status();
}

TEST_F(ScanIngestTest, MissingFileAndBadOptions) {
  IngestOptions o;
  o.scan_path = *root_ + "/does_not_exist.h5";
  o.spill_dir = *root_ + "/spill_missing";
  absl::StatusOr<IngestResult> r = IngestScan(o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("does_not_exist.h5"), std::string::npos) << r.status();
  o.scan_path = *scan_;
  o.spill_dir.clear();
  EXPECT_EQ(IngestScan(o).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace carvemap

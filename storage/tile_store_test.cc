// Tiles (storage/TILE_FORMAT.md): round trip, byte-identical output, the .partial protocol and
// clear errors for damaged tiles.
#include "storage/tile_store.h"

#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <fstream>
#include <iterator>
#include <random>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace carvemap {
namespace {

using ::testing::HasSubstr;

class TileStoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::path(::testing::TempDir()) /
           ("tile_store_test_" + std::string(::testing::UnitTest::GetInstance()
                                                 ->current_test_info()
                                                 ->name()));
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  std::string Dir(const std::string& sub = "") const {
    auto d = sub.empty() ? dir_ : dir_ / sub;
    std::filesystem::create_directories(d);
    return d.string();
  }

  std::filesystem::path dir_;
};

// A tile of `n` non-overlapping leaves at mixed depths of a depth-5 chunk, from a seeded RNG:
// the first cells of 8 depth-5 leaves, a depth-4 sibling block, and so on, in shuffled order.
TileData MakeTile(int n, uint32_t seed) {
  TileData tile;
  tile.chunk = ChunkKey(-3, 7, -1);
  tile.grid.chunk_depth = 5;
  tile.params.job_id = "job-42";
  tile.params.num_wedges = 1234;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  // Depth-3 nodes are 8 × 8 depth-4 ... use depth 2 blocks (64 of them): each block holds
  // either one depth-2 leaf, eight depth-3 leaves, or 8 depth-5 leaves in its first corner.
  int made = 0;
  for (uint64_t block = 0; block < 64 && made < n; ++block) {
    const Eigen::Vector3i b = MortonDecode(block);
    const int kind = static_cast<int>(block % 3);
    auto add = [&](const Eigen::Vector3i& local, int depth) {
      TileLeaf leaf;
      leaf.node.local = local;
      leaf.node.depth = depth;
      const int rays = 1 + static_cast<int>(u(rng) * 20);
      for (int r = 0; r < rays; ++r) leaf.stats.Add(u(rng), 1e-3 + u(rng));
      if (depth == 5) leaf.stats.points = static_cast<uint32_t>(u(rng) * 4);
      tile.leaves.push_back(leaf);
      ++made;
    };
    if (kind == 0) {
      add(b, 2);
    } else if (kind == 1) {
      for (uint64_t c = 0; c < 8; ++c) add(b * 2 + MortonDecode(c), 3);
    } else {
      for (uint64_t c = 0; c < 8; ++c) add(b * 8 + MortonDecode(c), 5);
    }
  }
  std::shuffle(tile.leaves.begin(), tile.leaves.end(), rng);
  return tile;
}

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

void EditTile(const std::string& path, const std::function<void(hid_t)>& edit) {
  hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  edit(file);
  H5Fclose(file);
}

TEST_F(TileStoreTest, FileNameKeepsNegativeKeys) {
  EXPECT_EQ(TileFileName(ChunkKey(-3, 7, -1)), "c_-3_7_-1.h5");
  EXPECT_EQ(TileFileName(ChunkKey(0, 0, 0)), "c_0_0_0.h5");
}

TEST_F(TileStoreTest, RoundTripIsExact) {
  TileData tile = MakeTile(400, 1);
  auto path = WriteTile(Dir(), tile);
  ASSERT_TRUE(path.ok()) << path.status();
  EXPECT_EQ(std::filesystem::path(*path).filename(), "c_-3_7_-1.h5");
  EXPECT_FALSE(std::filesystem::exists(*path + ".partial"));
  for (const auto& entry : std::filesystem::directory_iterator(Dir())) {
    EXPECT_EQ(entry.path().extension(), ".h5") << entry.path();
  }

  auto read = ReadTile(*path);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->chunk, tile.chunk);
  EXPECT_EQ(read->grid.chunk_depth, 5);
  EXPECT_EQ(read->params.job_id, "job-42");
  EXPECT_EQ(read->params.num_wedges, 1234u);
  EXPECT_EQ(read->params.hull_sigmas, 3.0);
  EXPECT_EQ(read->params.min_weight, 1e-6);
  EXPECT_TRUE(read->params.simplified);

  std::vector<TileLeaf> expected = tile.leaves;
  SortTileLeaves(tile.grid, expected);
  ASSERT_EQ(read->leaves.size(), expected.size());
  for (size_t i = 0; i < expected.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(read->leaves[i].node.local, expected[i].node.local);
    EXPECT_EQ(read->leaves[i].node.depth, expected[i].node.depth);
    // The sums are stored as f64: exact, so tiles merge exactly later.
    EXPECT_EQ(read->leaves[i].stats.sum_w, expected[i].stats.sum_w);
    EXPECT_EQ(read->leaves[i].stats.sum_wp, expected[i].stats.sum_wp);
    EXPECT_EQ(read->leaves[i].stats.sum_wp2, expected[i].stats.sum_wp2);
    EXPECT_EQ(read->leaves[i].stats.count, expected[i].stats.count);
    EXPECT_EQ(read->leaves[i].stats.points, expected[i].stats.points);
  }
}

TEST_F(TileStoreTest, EmptyTileRoundTrips) {
  TileData tile;
  tile.chunk = ChunkKey(1, 2, 3);
  tile.grid.chunk_depth = 7;
  auto path = WriteTile(Dir(), tile);
  ASSERT_TRUE(path.ok()) << path.status();
  auto read = ReadTile(*path);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_TRUE(read->leaves.empty());
  EXPECT_EQ(read->grid.chunk_depth, 7);
}

TEST_F(TileStoreTest, IdenticalContentGivesIdenticalBytes) {
  // More rows than one HDF5 chunk (16384), so a partial last chunk is covered too.
  TileData big;
  big.grid.chunk_depth = 6;
  for (uint64_t code = 0; code < 20000; ++code) {
    TileLeaf leaf;
    leaf.node.local = MortonDecode(code * 13 % (uint64_t{1} << 18));
    leaf.node.depth = 6;
    leaf.stats.Add(0.25 + 0.5 * double(code % 7) / 7.0, 0.5);
    big.leaves.push_back(leaf);
  }
  for (const TileData& tile : {MakeTile(400, 2), big}) {
    TileData shuffled = tile;
    std::mt19937 rng(3);
    std::shuffle(shuffled.leaves.begin(), shuffled.leaves.end(), rng);
    auto a = WriteTile(Dir("a"), tile);
    auto b = WriteTile(Dir("b"), shuffled);  // same content, other order
    auto c = WriteTile(Dir("a"), tile);      // rewrite in place
    ASSERT_TRUE(a.ok() && b.ok() && c.ok()) << a.status() << b.status() << c.status();
    const std::string bytes = ReadBytes(*a);
    EXPECT_GT(bytes.size(), 0u);
    EXPECT_TRUE(bytes == ReadBytes(*b));
  }
}

TEST_F(TileStoreTest, CompressesColumns) {
  TileData tile;
  tile.grid.chunk_depth = 6;
  for (uint64_t code = 0; code < 50000; ++code) {
    TileLeaf leaf;
    leaf.node.local = MortonDecode(code);
    leaf.node.depth = 6;
    leaf.stats.Add(code < 25000 ? 0.9 : 0.1, 1.0);
    tile.leaves.push_back(leaf);
  }
  auto path = WriteTile(Dir(), tile);
  ASSERT_TRUE(path.ok()) << path.status();
  // Uncompressed: 50000 × (8+1+4+8+4+4+8+8) = 2.25 MB.
  EXPECT_LT(std::filesystem::file_size(*path), 400000u);
}

// A tile over several HDF5 chunks (16384 rows each) with a partial last one.
TileData MakeBigTile(uint64_t leaves) {
  TileData big;
  big.chunk = ChunkKey(-3, 7, -1);
  big.grid.chunk_depth = 6;
  for (uint64_t code = 0; code < leaves; ++code) {
    TileLeaf leaf;
    leaf.node.local = MortonDecode(code * 13 % (uint64_t{1} << 18));
    leaf.node.depth = 6;
    leaf.stats.Add(0.25 + 0.5 * double(code % 7) / 7.0, 0.5 + double(code % 5));
    leaf.stats.points = static_cast<uint32_t>(code % 3);
    big.leaves.push_back(leaf);
  }
  return big;
}

void ExpectSameLeaves(const TileData& read, TileData expected) {
  SortTileLeaves(expected.grid, expected.leaves);
  ASSERT_EQ(read.leaves.size(), expected.leaves.size());
  for (size_t i = 0; i < expected.leaves.size(); ++i) {
    SCOPED_TRACE(i);
    ASSERT_EQ(read.leaves[i].node.local, expected.leaves[i].node.local);
    ASSERT_EQ(read.leaves[i].node.depth, expected.leaves[i].node.depth);
    ASSERT_EQ(read.leaves[i].stats.sum_w, expected.leaves[i].stats.sum_w);
    ASSERT_EQ(read.leaves[i].stats.sum_wp, expected.leaves[i].stats.sum_wp);
    ASSERT_EQ(read.leaves[i].stats.sum_wp2, expected.leaves[i].stats.sum_wp2);
    ASSERT_EQ(read.leaves[i].stats.count, expected.leaves[i].stats.count);
    ASSERT_EQ(read.leaves[i].stats.points, expected.leaves[i].stats.points);
  }
}

// The writer compresses each stored chunk itself (outside HDF5's lock): HDF5 must read back
// what its own filters would, and the reader must read what HDF5's filters and other layouts
// write, so tiles of other writers still load.
TEST_F(TileStoreTest, ChunksAreThoseOfHdf5sOwnFilters) {
  const TileData tile = MakeBigTile(40000);  // three chunks, the last partial
  auto path = WriteTile(Dir(), tile);
  ASSERT_TRUE(path.ok()) << path.status();
  std::vector<TileLeaf> sorted = tile.leaves;
  SortTileLeaves(tile.grid, sorted);

  // HDF5 reads our chunks through its filters.
  hid_t file = H5Fopen(path->c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  std::vector<double> weight(sorted.size());
  std::vector<uint64_t> key(sorted.size());
  hid_t d = H5Dopen2(file, "/leaves/weight", H5P_DEFAULT);
  ASSERT_GE(H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, weight.data()), 0);
  H5Dclose(d);
  d = H5Dopen2(file, "/leaves/key", H5P_DEFAULT);
  ASSERT_GE(H5Dread(d, H5T_NATIVE_UINT64, H5S_ALL, H5S_ALL, H5P_DEFAULT, key.data()), 0);
  H5Dclose(d);
  H5Fclose(file);
  for (size_t i = 0; i < sorted.size(); ++i) {
    ASSERT_EQ(weight[i], sorted[i].stats.sum_w) << i;
    ASSERT_EQ(key[i], MortonCode(sorted[i].node.local)) << i;
  }

  // Columns rewritten by HDF5 itself: weight through its shuffle and deflate filters at
  // another level and chunk size, count contiguous and unfiltered, sum_wp big-endian.
  EditTile(*path, [&](hid_t f) {
    const hsize_t n = sorted.size(), chunk = 5000;
    std::vector<uint32_t> count(n);
    std::vector<double> sum_wp(n);
    for (size_t i = 0; i < n; ++i) {
      count[i] = sorted[i].stats.count;
      sum_wp[i] = sorted[i].stats.sum_wp;
    }
    hid_t space = H5Screate_simple(1, &n, nullptr);
    const auto rewrite = [&](const char* name, hid_t file_type, hid_t mem_type, const void* v,
                             bool filtered) {
      ASSERT_GE(H5Ldelete(f, name, H5P_DEFAULT), 0);
      hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
      if (filtered) {
        H5Pset_chunk(dcpl, 1, &chunk);
        H5Pset_shuffle(dcpl);
        H5Pset_deflate(dcpl, 9);
      }
      hid_t ds = H5Dcreate2(f, name, file_type, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
      ASSERT_GE(ds, 0);
      ASSERT_GE(H5Dwrite(ds, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, v), 0);
      H5Dclose(ds);
      H5Pclose(dcpl);
    };
    rewrite("/leaves/weight", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, weight.data(), true);
    rewrite("/leaves/count", H5T_STD_U32LE, H5T_NATIVE_UINT32, count.data(), false);
    rewrite("/leaves/sum_wp", H5T_IEEE_F64BE, H5T_NATIVE_DOUBLE, sum_wp.data(), true);
    H5Sclose(space);
  });
  auto read = ReadTile(*path);
  ASSERT_TRUE(read.ok()) << read.status();
  ExpectSameLeaves(*read, tile);
}

TEST_F(TileStoreTest, EncodedAndRawStepsAreWriteTileAndReadTile) {
  const TileData tile = MakeBigTile(20000);
  auto encoded = EncodeTile(Dir("a"), tile);
  ASSERT_TRUE(encoded.ok()) << encoded.status();
  auto a = WriteEncodedTile(*encoded);
  auto b = WriteTile(Dir("b"), tile);
  ASSERT_TRUE(a.ok() && b.ok()) << a.status() << b.status();
  EXPECT_TRUE(ReadBytes(*a) == ReadBytes(*b));
  auto raw = ReadRawTile(*a);
  ASSERT_TRUE(raw.ok()) << raw.status();
  EXPECT_EQ(raw->rows, 20000u);
  auto decoded = DecodeTile(*std::move(raw));
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  ExpectSameLeaves(*decoded, tile);

  TileData bad = tile;
  bad.leaves[3].node.depth = 9;
  auto refused = EncodeTile(Dir("c"), bad);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(refused.status().message(), HasSubstr("c_-3_7_-1.h5"));
}

// A damaged stored chunk is found when it is decompressed, naming the file, the column and
// the chunk; so is one whose stream inflates to the wrong size.
TEST_F(TileStoreTest, DamagedChunkIsDataLossNamingColumnAndRow) {
  auto path = WriteTile(Dir(), MakeBigTile(40000));
  ASSERT_TRUE(path.ok()) << path.status();
  for (const std::string& bytes :
       {std::string(300, '\x5a'), std::string("\x78\x9c\x03\x00\x00\x00\x00\x01")}) {
    EditTile(*path, [&](hid_t f) {
      hid_t d = H5Dopen2(f, "/leaves/sum_wp2", H5P_DEFAULT);
      ASSERT_GE(d, 0);
      const hsize_t offset[1] = {16384};
      ASSERT_GE(H5Dwrite_chunk(d, H5P_DEFAULT, 0, offset, bytes.size(), bytes.data()), 0);
      H5Dclose(d);
    });
    auto read = ReadTile(*path);
    ASSERT_FALSE(read.ok());
    EXPECT_EQ(read.status().code(), absl::StatusCode::kDataLoss);
    EXPECT_THAT(read.status().message(), HasSubstr("c_-3_7_-1.h5"));
    EXPECT_THAT(read.status().message(), HasSubstr("/leaves/sum_wp2: the chunk at row 16384"));
  }
}

TEST_F(TileStoreTest, TruncatedTileIsDataLossNamingTheFile) {
  auto path = WriteTile(Dir(), MakeTile(400, 4));
  ASSERT_TRUE(path.ok()) << path.status();
  const std::string bytes = ReadBytes(*path);
  for (size_t keep : {size_t{0}, size_t{100}, bytes.size() / 2, bytes.size() - 100}) {
    SCOPED_TRACE(keep);
    const std::string cut = Dir() + "/c_9_9_9.h5";
    {
      std::ofstream out(cut, std::ios::binary | std::ios::trunc);
      out.write(bytes.data(), static_cast<std::streamsize>(keep));
    }
    auto read = ReadTile(cut);
    ASSERT_FALSE(read.ok());
    EXPECT_EQ(read.status().code(), absl::StatusCode::kDataLoss) << read.status();
    EXPECT_THAT(read.status().message(), HasSubstr("c_9_9_9.h5"));
  }
}

TEST_F(TileStoreTest, MissingTileIsNotFound) {
  auto read = ReadTile(Dir() + "/c_1_1_1.h5");
  EXPECT_EQ(read.status().code(), absl::StatusCode::kNotFound);
}

// Opens a written tile for editing with the C API, as a damaged or foreign writer would.
TEST_F(TileStoreTest, MissingColumnNamesFileAndDataset) {
  auto path = WriteTile(Dir(), MakeTile(100, 5));
  ASSERT_TRUE(path.ok()) << path.status();
  EditTile(*path, [](hid_t file) { ASSERT_GE(H5Ldelete(file, "/leaves/sum_wp", H5P_DEFAULT), 0); });
  auto read = ReadTile(*path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr("c_-3_7_-1.h5"));
  EXPECT_THAT(read.status().message(), HasSubstr("/leaves/sum_wp"));
  EXPECT_THAT(read.status().message(), HasSubstr("missing"));
}

// Version 1 (before /leaves/points) still reads, with no points; a version 2 tile without
// the column is damaged.
TEST_F(TileStoreTest, VersionOneTilesReadWithoutPoints) {
  const TileData tile = MakeTile(100, 6);
  uint64_t points = 0;
  for (const TileLeaf& l : tile.leaves) points += l.stats.points;
  ASSERT_GT(points, 0u);
  auto path = WriteTile(Dir(), tile);
  ASSERT_TRUE(path.ok()) << path.status();
  EditTile(*path, [](hid_t file) { ASSERT_GE(H5Ldelete(file, "/leaves/points", H5P_DEFAULT), 0); });
  auto damaged = ReadTile(*path);
  ASSERT_FALSE(damaged.ok());
  EXPECT_THAT(damaged.status().message(), HasSubstr("/leaves/points"));
  EditTile(*path, [](hid_t file) {
    hid_t attr = H5Aopen(file, "version", H5P_DEFAULT);
    ASSERT_GE(attr, 0);
    const int64_t one = 1;
    ASSERT_GE(H5Awrite(attr, H5T_NATIVE_INT64, &one), 0);
    H5Aclose(attr);
  });
  auto v1 = ReadTile(*path);
  ASSERT_TRUE(v1.ok()) << v1.status();
  ASSERT_EQ(v1->leaves.size(), tile.leaves.size());
  for (const TileLeaf& l : v1->leaves) EXPECT_EQ(l.stats.points, 0u);
  EditTile(*path, [](hid_t file) {
    hid_t attr = H5Aopen(file, "version", H5P_DEFAULT);
    const int64_t three = 3;
    ASSERT_GE(H5Awrite(attr, H5T_NATIVE_INT64, &three), 0);
    H5Aclose(attr);
  });
  auto future = ReadTile(*path);
  ASSERT_FALSE(future.ok());
  EXPECT_THAT(future.status().message(), HasSubstr("unsupported version 3"));
}

// Found by tests/fuzz (tile_reader): a column declaring 2^33 rows that were never written
// (HDF5 reads them as fill values) made ReadTile allocate 8 × 2^33 bytes per column.
TEST_F(TileStoreTest, RowsDeclaredButNeverWrittenAreDataLoss) {
  auto path = WriteTile(Dir(), MakeTile(100, 5));
  ASSERT_TRUE(path.ok()) << path.status();
  EditTile(*path, [](hid_t file) {
    ASSERT_GE(H5Ldelete(file, "/leaves/key", H5P_DEFAULT), 0);
    const hsize_t dims[1] = {hsize_t{1} << 33}, chunk[1] = {1024};
    hid_t space = H5Screate_simple(1, dims, nullptr);
    hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
    H5Pset_chunk(dcpl, 1, chunk);
    hid_t d = H5Dcreate2(file, "/leaves/key", H5T_STD_U64LE, space, H5P_DEFAULT, dcpl,
                         H5P_DEFAULT);
    ASSERT_GE(d, 0);
    H5Dclose(d);
    H5Pclose(dcpl);
    H5Sclose(space);
  });
  auto read = ReadTile(*path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr("c_-3_7_-1.h5"));
  EXPECT_THAT(read.status().message(), HasSubstr("/leaves/key: declares 8589934592 rows"));
}

// Found by tests/fuzz (the scan reader's twin): HDF5 1.10 converts a float whose exponent
// overlaps another field out of bounds. A damaged type message in /leaves/p, the first f32
// column (offset 0, precision 32, exponent at 23 of 8 bits, mantissa at 0 of 23, bias 127).
TEST_F(TileStoreTest, DamagedColumnTypeIsDataLoss) {
  auto path = WriteTile(Dir(), MakeTile(100, 5));
  ASSERT_TRUE(path.ok()) << path.status();
  std::string bytes;
  {
    std::ifstream in(*path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  const std::string f32("\0\0\x20\0\x17\x08\0\x17\x7f\0\0\0", 12);
  const size_t at = bytes.find(f32);
  ASSERT_NE(at, std::string::npos);
  bytes[at + 4] = 0x18;  // the exponent now covers the sign bit
  std::ofstream(*path, std::ios::binary | std::ios::trunc) << bytes;
  auto read = ReadTile(*path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr("/leaves/p: a float whose fields do not fit"));
}

TEST_F(TileStoreTest, BadValuesNameTheDataset) {
  struct Case {
    const char* dataset;
    hid_t mem_type;
    double value;  // written into row 3
    const char* expect;
  };
  const Case cases[] = {
      {"p", H5T_NATIVE_DOUBLE, 1.5, "/leaves/p[3]"},
      {"p", H5T_NATIVE_DOUBLE, NAN, "/leaves/p[3]"},
      {"depth", H5T_NATIVE_DOUBLE, 6, "/leaves/depth[3]"},
      {"weight", H5T_NATIVE_DOUBLE, INFINITY, "/leaves/weight[3]"},
      {"key", H5T_NATIVE_DOUBLE, 1e12, "/leaves/key[3]"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.dataset);
    auto path = WriteTile(Dir(), MakeTile(100, 6));
    ASSERT_TRUE(path.ok()) << path.status();
    EditTile(*path, [&](hid_t file) {
      const std::string name = std::string("/leaves/") + c.dataset;
      hid_t ds = H5Dopen2(file, name.c_str(), H5P_DEFAULT);
      hid_t space = H5Dget_space(ds);
      const hsize_t start[1] = {3}, count[1] = {1};
      H5Sselect_hyperslab(space, H5S_SELECT_SET, start, nullptr, count, nullptr);
      hid_t mem = H5Screate_simple(1, count, nullptr);
      // Conversion of out-of-range values is what a bad writer would produce; allow it.
      hid_t xfer = H5Pcreate(H5P_DATASET_XFER);
      ASSERT_GE(H5Dwrite(ds, c.mem_type, mem, space, xfer, &c.value), 0);
      H5Pclose(xfer);
      H5Sclose(mem);
      H5Sclose(space);
      H5Dclose(ds);
    });
    auto read = ReadTile(*path);
    ASSERT_FALSE(read.ok());
    EXPECT_EQ(read.status().code(), absl::StatusCode::kDataLoss);
    EXPECT_THAT(read.status().message(), HasSubstr("c_-3_7_-1.h5"));
    EXPECT_THAT(read.status().message(), HasSubstr(c.expect)) << read.status();
  }
}

TEST_F(TileStoreTest, WrongFormatAttributeIsRejected) {
  auto path = WriteTile(Dir(), MakeTile(10, 7));
  ASSERT_TRUE(path.ok()) << path.status();
  EditTile(*path, [](hid_t file) { ASSERT_GE(H5Adelete(file, "version"), 0); });
  auto read = ReadTile(*path);
  EXPECT_EQ(read.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr("version"));
}

TEST_F(TileStoreTest, WriterRejectsBadLeavesAndLeavesNoPartial) {
  TileData overlap = MakeTile(50, 8);
  TileLeaf parent;
  parent.node.local = overlap.leaves[0].node.local / 2;
  parent.node.depth = overlap.leaves[0].node.depth - 1;
  parent.stats.Add(0.7, 1.0);
  overlap.leaves.push_back(parent);
  auto a = WriteTile(Dir(), overlap);
  EXPECT_EQ(a.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(a.status().message(), HasSubstr("overlaps"));

  TileData deep = MakeTile(10, 9);
  deep.leaves[2].node.depth = 6;
  auto b = WriteTile(Dir(), deep);
  EXPECT_EQ(b.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(b.status().message(), HasSubstr("depth 6"));

  TileData nan = MakeTile(10, 10);
  nan.leaves[1].stats.sum_wp = NAN;
  EXPECT_EQ(WriteTile(Dir(), nan).status().code(), absl::StatusCode::kInvalidArgument);

  EXPECT_TRUE(std::filesystem::is_empty(Dir()));
}

TEST_F(TileStoreTest, UnwritableDirectoryFailsWithoutPartial) {
  auto path = WriteTile(Dir() + "/does/not/exist", MakeTile(10, 11));
  ASSERT_FALSE(path.ok());
  EXPECT_THAT(path.status().message(), HasSubstr("c_-3_7_-1.h5.partial"));
}

}  // namespace
}  // namespace carvemap

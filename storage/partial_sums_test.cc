#include "storage/partial_sums.h"

#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "storage/crc32c.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

std::string TempPath(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / "partial_sums_test";
  fs::create_directories(dir);
  return (dir / name).string();
}

std::vector<TileLeaf> RandomLeaves(std::mt19937& rng, int depth, int n) {
  std::vector<TileLeaf> out;
  std::uniform_int_distribution<int> c(0, (1 << depth) - 1);
  std::uniform_real_distribution<double> u(0, 10);
  std::set<std::tuple<int, int, int>> used;
  while (int(out.size()) < n) {
    TileLeaf l;
    l.node.depth = depth;
    l.node.local = Eigen::Vector3i(c(rng), c(rng), c(rng));
    if (!used.insert({l.node.local.x(), l.node.local.y(), l.node.local.z()}).second) continue;
    l.stats.sum_w = u(rng);
    l.stats.sum_wp = u(rng);
    l.stats.sum_wp2 = u(rng);
    l.stats.count = uint32_t(rng() % 1000);
    l.stats.points = uint32_t(rng() % 7);
    out.push_back(l);
  }
  return out;
}

bool SameStats(const LeafStats& a, const LeafStats& b) {
  return a.sum_w == b.sum_w && a.sum_wp == b.sum_wp && a.sum_wp2 == b.sum_wp2 &&
         a.count == b.count && a.points == b.points;
}

TEST(PartialSumsTest, SectionsComeBackBitForBitSortedByPlace) {
  std::mt19937 rng(3);
  const std::string path = TempPath("slice_7.part");
  auto w = PartialSumsWriter::Create(path, 5, 7);
  ASSERT_TRUE(w.ok()) << w.status();
  const std::vector<ChunkKey> chunks = {ChunkKey(-1, 2, 0), ChunkKey(3, 0, -4), ChunkKey(-1, 2, 0)};
  std::vector<std::vector<TileLeaf>> written;
  for (size_t i = 0; i < chunks.size(); ++i) {
    written.push_back(RandomLeaves(rng, 5, i == 1 ? 0 : 500));
    ASSERT_TRUE((*w)->AddSection(chunks[i], 100 + i, written.back()).ok());
  }
  EXPECT_FALSE(fs::exists(path));  // only the .tmp until Finish
  absl::StatusOr<uint64_t> bytes = (*w)->Finish();
  ASSERT_TRUE(bytes.ok()) << bytes.status();
  EXPECT_EQ(*bytes, fs::file_size(path));
  EXPECT_FALSE(fs::exists(path + ".tmp"));

  absl::StatusOr<PartialSumsIndex> index = ReadPartialIndex(path);
  ASSERT_TRUE(index.ok()) << index.status();
  EXPECT_EQ(index->chunk_depth, 5);
  EXPECT_EQ(index->slice, 7u);
  ASSERT_EQ(index->sections.size(), 3u);
  for (size_t i = 0; i < chunks.size(); ++i) {
    const PartialSection& s = index->sections[i];
    EXPECT_EQ(s.chunk, chunks[i]);
    EXPECT_EQ(s.wedges, 100 + i);
    std::vector<TileLeaf> got;
    ASSERT_TRUE(ReadPartialSection(path, *index, s, got).ok());
    ASSERT_EQ(got.size(), written[i].size());
    std::map<std::tuple<int, int, int>, LeafStats> want;
    for (const TileLeaf& l : written[i]) want[{l.node.local.x(), l.node.local.y(), l.node.local.z()}] = l.stats;
    for (size_t k = 0; k < got.size(); ++k) {
      const Eigen::Vector3i& l = got[k].node.local;
      EXPECT_EQ(got[k].node.depth, 5);
      ASSERT_TRUE(want.count({l.x(), l.y(), l.z()}));
      EXPECT_TRUE(SameStats(got[k].stats, want[{l.x(), l.y(), l.z()}]));
      if (k > 0) {  // sorted by z, then y, then x
        const Eigen::Vector3i& p = got[k - 1].node.local;
        EXPECT_LT(std::tuple(p.z(), p.y(), p.x()), std::tuple(l.z(), l.y(), l.x()));
      }
    }
  }
}

// Version 1 files (leaf records as they are, before sections were compressed) still read:
// one written here byte by byte from PARTIAL_FORMAT.md's layout, two sections.
TEST(PartialSumsTest, VersionOneFilesStillRead) {
  std::string file;
  const auto u32 = [](std::string& out, uint32_t v) {
    for (int i = 0; i < 4; ++i) out.push_back(char(v >> (8 * i)));
  };
  const auto u64 = [](std::string& out, uint64_t v) {
    for (int i = 0; i < 8; ++i) out.push_back(char(v >> (8 * i)));
  };
  const auto f64 = [&](std::string& out, double v) {
    uint64_t bits;
    std::memcpy(&bits, &v, 8);
    u64(out, bits);
  };
  file = "CMPARTL1";
  u32(file, 1);  // version
  u32(file, 4);  // chunk depth
  u32(file, 9);  // slice
  file.append(8, '\0');
  u32(file, Crc32c(file));
  struct Leaf {
    int x, y, z;
    uint32_t count, points;
    double w, wp, wp2;
  };
  const std::vector<std::vector<Leaf>> sections = {
      {{1, 0, 0, 3, 1, 0.5, 0.25, 0.125}, {2, 3, 1, 7, 0, 1.5, 1.0, 0.75}},
      {{15, 15, 15, 1, 2, 2, 1, 0.5}}};
  std::string index;
  for (size_t k = 0; k < sections.size(); ++k) {
    std::string records;
    for (const Leaf& l : sections[k]) {
      u32(records, uint32_t(l.x) | uint32_t(l.y) << 10 | uint32_t(l.z) << 20);
      u32(records, l.count);
      u32(records, l.points);
      f64(records, l.w);
      f64(records, l.wp);
      f64(records, l.wp2);
    }
    for (int a : {int(k), -2, 5}) u32(index, uint32_t(a));
    u64(index, 10 + k);              // wedges
    u64(index, sections[k].size());  // leaves
    u64(index, file.size());         // offset
    u32(index, Crc32c(records));
    file += records;
  }
  std::string trailer;
  u64(trailer, file.size());
  u64(trailer, sections.size());
  u32(trailer, Crc32c(index));
  u32(trailer, Crc32c(trailer));
  file += index + trailer;
  const std::string path = TempPath("v1.part");
  std::ofstream(path, std::ios::binary) << file;

  absl::StatusOr<PartialSumsIndex> read = ReadPartialIndex(path);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->version, 1u);
  EXPECT_EQ(read->slice, 9u);
  ASSERT_EQ(read->sections.size(), 2u);
  for (size_t k = 0; k < 2; ++k) {
    EXPECT_EQ(read->sections[k].chunk, ChunkKey(int(k), -2, 5));
    EXPECT_EQ(read->sections[k].wedges, 10 + k);
    std::vector<TileLeaf> leaves;
    ASSERT_TRUE(ReadPartialSection(path, *read, read->sections[k], leaves).ok());
    ASSERT_EQ(leaves.size(), sections[k].size());
    for (size_t i = 0; i < leaves.size(); ++i) {
      const Leaf& l = sections[k][i];
      EXPECT_EQ(leaves[i].node.local, Eigen::Vector3i(l.x, l.y, l.z));
      EXPECT_EQ(leaves[i].node.depth, 4);
      EXPECT_EQ(leaves[i].stats.count, l.count);
      EXPECT_EQ(leaves[i].stats.points, l.points);
      EXPECT_EQ(leaves[i].stats.sum_w, l.w);
      EXPECT_EQ(leaves[i].stats.sum_wp, l.wp);
      EXPECT_EQ(leaves[i].stats.sum_wp2, l.wp2);
    }
  }
}

// Sections are stored compressed: a file of many leaves takes fewer bytes than their records.
TEST(PartialSumsTest, SectionsAreStoredCompressed) {
  std::mt19937 rng(5);
  const std::string path = TempPath("slice_2.part");
  auto w = PartialSumsWriter::Create(path, 6, 2);
  ASSERT_TRUE(w.ok()) << w.status();
  // Sums of a few votes of equal weight, as a slice's free space mostly holds.
  std::vector<TileLeaf> leaves = RandomLeaves(rng, 6, 5000);
  for (TileLeaf& l : leaves) {
    l.stats.count = 1 + l.stats.count % 4;
    l.stats.sum_w = 0.5 * l.stats.count;
    l.stats.sum_wp = 0.05 * l.stats.count;
    l.stats.sum_wp2 = 0.005 * l.stats.count;
  }
  ASSERT_TRUE((*w)->AddSection(ChunkKey(0, 0, 0), 1, leaves).ok());
  absl::StatusOr<uint64_t> bytes = (*w)->Finish();
  ASSERT_TRUE(bytes.ok()) << bytes.status();
  EXPECT_LT(*bytes, 5000u * 36 / 4);
  absl::StatusOr<PartialSumsIndex> index = ReadPartialIndex(path);
  ASSERT_TRUE(index.ok()) << index.status();
  EXPECT_EQ(index->version, 2u);
  std::vector<TileLeaf> got;
  ASSERT_TRUE(ReadPartialSection(path, *index, index->sections[0], got).ok());
  EXPECT_EQ(got.size(), leaves.size());
}

TEST(PartialSumsTest, DamageIsDetectedAndNamesTheFile) {
  std::mt19937 rng(4);
  const std::string path = TempPath("slice_1.part");
  {
    auto w = PartialSumsWriter::Create(path, 6, 1);
    ASSERT_TRUE(w.ok());
    ASSERT_TRUE((*w)->AddSection(ChunkKey(0, 0, 0), 1, RandomLeaves(rng, 6, 300)).ok());
    ASSERT_TRUE((*w)->Finish().ok());
  }
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  const auto write = [&](const std::string& name, const std::string& content) {
    const std::string p = TempPath(name);
    std::ofstream(p, std::ios::binary) << content;
    return p;
  };
  // Truncated anywhere: the trailer no longer checks out.
  for (size_t cut : {size_t(0), size_t(20), bytes.size() / 2, bytes.size() - 1}) {
    const std::string p = write("cut.part", bytes.substr(0, cut));
    absl::StatusOr<PartialSumsIndex> index = ReadPartialIndex(p);
    ASSERT_FALSE(index.ok()) << cut;
    EXPECT_EQ(index.status().code(), absl::StatusCode::kDataLoss) << cut;
    EXPECT_NE(index.status().message().find(p), std::string::npos);
  }
  // One byte of a leaf changed: the index reads, the section does not.
  std::string flipped = bytes;
  flipped[32 + 36 * 10 + 15] ^= 0x40;
  const std::string p = write("flipped.part", flipped);
  absl::StatusOr<PartialSumsIndex> index = ReadPartialIndex(p);
  ASSERT_TRUE(index.ok()) << index.status();
  std::vector<TileLeaf> leaves;
  const absl::Status s = ReadPartialSection(p, *index, index->sections[0], leaves);
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(s.message().find("chunk 0,0,0"), std::string::npos) << s;
  EXPECT_EQ(ReadPartialIndex(TempPath("none.part")).status().code(), absl::StatusCode::kNotFound);
}

TEST(PartialSumsTest, UnfinishedWriterLeavesNothingAndBadLeavesAreRefused) {
  const std::string path = TempPath("unfinished.part");
  {
    auto w = PartialSumsWriter::Create(path, 5, 0);
    ASSERT_TRUE(w.ok());
    TileLeaf coarse;
    coarse.node.depth = 4;
    EXPECT_EQ((*w)->AddSection(ChunkKey(0, 0, 0), 1, {&coarse, 1}).code(),
              absl::StatusCode::kInvalidArgument);
    TileLeaf outside;
    outside.node.depth = 5;
    outside.node.local = Eigen::Vector3i(32, 0, 0);
    EXPECT_EQ((*w)->AddSection(ChunkKey(0, 0, 0), 1, {&outside, 1}).code(),
              absl::StatusCode::kInvalidArgument);
  }  // destroyed without Finish
  EXPECT_FALSE(fs::exists(path));
  EXPECT_FALSE(fs::exists(path + ".tmp"));
}

TEST(PartialSumsTest, RegionsFileRoundTripAndDamage) {
  // Not in ChunkKeyLess order: the file is, whatever order the writer is given.
  const std::vector<RecarveChunk> regions = {
      RecarveChunk::Of(ChunkKey(0, 0, 0), ChunkRegion(5, {{31, 0, 0}})),
      RecarveChunk::Of(ChunkKey(-3, 0, 7), ChunkRegion(3, {{1, 2, 3}, {7, 7, 7}}))};
  const std::string path = TempPath("regions.bin");
  ASSERT_TRUE(WriteRegionsFile(path, regions).ok());
  absl::StatusOr<RecarveRegionMap> back = ReadRegionsFile(path);
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->size(), 2u);
  for (const RecarveChunk& c : regions) {
    ASSERT_TRUE(back->count(c.chunk));
    EXPECT_EQ(back->at(c.chunk).depth, c.depth);
    EXPECT_EQ(back->at(c.chunk).cells, c.cells);
    absl::StatusOr<ChunkRegion> decoded = back->at(c.chunk).Decode();
    ASSERT_TRUE(decoded.ok()) << decoded.status();
    EXPECT_EQ(decoded->Encode(), c.cells);
  }
  {
    const std::string reversed = TempPath("regions_reversed.bin");
    const std::vector<RecarveChunk> backwards(regions.rbegin(), regions.rend());
    ASSERT_TRUE(WriteRegionsFile(reversed, backwards).ok());
    std::ifstream a(path, std::ios::binary), b(reversed, std::ios::binary);
    EXPECT_EQ(std::string(std::istreambuf_iterator<char>(a), {}),
              std::string(std::istreambuf_iterator<char>(b), {}));
  }
  // What the writer refuses: a chunk twice, and bits of the wrong size for their depth.
  const std::string refused = TempPath("regions_refused.bin");
  std::vector<RecarveChunk> twice = {regions[0], regions[1], regions[0]};
  absl::Status s = WriteRegionsFile(refused, twice);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), testing::HasSubstr("chunk 0,0,0 is listed twice"));
  std::vector<RecarveChunk> short_bits = {regions[1]};
  short_bits[0].cells.pop_back();
  s = WriteRegionsFile(refused, short_bits);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), testing::HasSubstr("chunk -3,0,7"));
  EXPECT_FALSE(fs::exists(refused));
  {
    // A file listing a chunk twice (its CRC right) is damaged: which region counts is not
    // for the reader to guess.
    const std::string one = TempPath("regions_one.bin");
    ASSERT_TRUE(WriteRegionsFile(one, std::vector<RecarveChunk>{regions[1]}).ok());
    std::ifstream in(one, std::ios::binary);
    const std::string bytes(std::istreambuf_iterator<char>(in), {});
    const std::string record = bytes.substr(12, bytes.size() - 16);  // after magic and count
    std::string twice = bytes.substr(0, 8) + std::string("\x02\0\0\0", 4) + record + record;
    const uint32_t crc = Crc32c(twice);
    for (int i = 0; i < 4; ++i) twice.push_back(char((crc >> (8 * i)) & 0xff));
    const std::string doubled = TempPath("regions_doubled.bin");
    std::ofstream(doubled, std::ios::binary) << twice;
    absl::Status read = ReadRegionsFile(doubled).status();
    EXPECT_EQ(read.code(), absl::StatusCode::kDataLoss) << read;
    EXPECT_THAT(std::string(read.message()), testing::HasSubstr("chunk -3,0,7 listed twice"));
  }
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  for (size_t cut : {size_t(3), bytes.size() / 2, bytes.size() - 1}) {
    std::ofstream(path, std::ios::binary) << bytes.substr(0, cut);
    EXPECT_EQ(ReadRegionsFile(path).status().code(), absl::StatusCode::kDataLoss) << cut;
  }
  EXPECT_EQ(ReadRegionsFile(TempPath("no_regions.bin")).status().code(),
            absl::StatusCode::kNotFound);
}

}  // namespace
}  // namespace carvemap

#include "coordinator/chunk_spill.h"


#include <array>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "coordinator/chunk_binning.h"
#include "storage/wedge_codec.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

// Under ::testing::TempDir(), which is private to this test process and removed at exit
// (tests/test_main.cc).
fs::path TempDir(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / name;
  fs::remove_all(dir);
  return dir;
}

SymCov3f Iso(float sigma) { return {sigma * sigma, 0, 0, sigma * sigma, 0, sigma * sigma}; }

// A walk along x with a line sensor sweeping a vertical fan: neighbouring rays of successive
// frames make the wedges, as the wedge builder would; every 9th is a single ray.
std::vector<Wedge> ScanWedges(int frames, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> range(1.0f, 6.0f);
  std::vector<Wedge> out;
  for (int f = 0; f < frames; ++f) {
    const Eigen::Vector3f s0(0.05f * f - 3.0f, 0.3f, 1.5f), s1 = s0 + Eigen::Vector3f(0.05f, 0, 0);
    for (int j = 0; j < 40; ++j) {
      const float a0 = 0.15f * j, a1 = a0 + 0.15f;
      auto ray = [&](const Eigen::Vector3f& s, float a) {
        const float r = range(rng);
        return RayModel{s, s + r * Eigen::Vector3f(0.1f, std::cos(a), std::sin(a)), Iso(0.005f),
                        Iso(0.01f * r)};
      };
      Wedge w;
      w.rays = {ray(s0, a0), ray(s0, a1), ray(s1, a1), ray(s1, a0)};
      w.num_rays = (f * 40 + j) % 9 == 0 ? 1 : 4;
      out.push_back(w);
    }
  }
  return out;
}

absl::StatusOr<std::vector<SpilledChunk>> Spill(const std::vector<Wedge>& wedges,
                                                const fs::path& dir, size_t budget,
                                                uint64_t* flushes = nullptr) {
  auto spiller = ChunkSpiller::Create({dir.string(), budget});
  if (!spiller.ok()) return spiller.status();
  size_t peak = 0;
  for (const Wedge& w : wedges) {
    if (absl::Status s = (*spiller)->Add(w); !s.ok()) return s;
    peak = std::max(peak, (*spiller)->buffered_bytes());
  }
  // Memory stays bounded: after each Add the buffers are within the budget.
  EXPECT_LE(peak, budget);
  if (flushes) *flushes = (*spiller)->flushes();
  return (*spiller)->Finish();
}

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

bool SameRecords(const std::vector<Wedge>& a, const std::vector<Wedge>& b) {
  return EncodeWedges(a) == EncodeWedges(b);
}

TEST(ChunkSpillTest, CompleteAndInOrder) {
  const std::vector<Wedge> wedges = ScanWedges(60, 1);
  const fs::path dir = TempDir("complete");
  auto chunks = Spill(wedges, dir, 64u << 20);
  ASSERT_TRUE(chunks.ok()) << chunks.status();
  ASSERT_GT(chunks->size(), 10u);

  // Expected bins, computed directly.
  std::map<std::array<int, 3>, std::vector<Wedge>> want;
  for (const Wedge& w : wedges) {
    for (const ChunkKey& c : ChunksOfWedge(w)) want[{c.x(), c.y(), c.z()}].push_back(w);
  }
  ASSERT_EQ(chunks->size(), want.size());
  size_t i = 0;
  for (const auto& [key, expected] : want) {
    const SpilledChunk& got = (*chunks)[i++];
    EXPECT_EQ(got.chunk, ChunkKey(key[0], key[1], key[2]));  // sorted by ChunkKeyLess
    EXPECT_EQ(got.wedge_count, expected.size());
    EXPECT_EQ(got.path, ChunkSpillPath(dir.string(), got.chunk));
    EXPECT_EQ(got.file_bytes, fs::file_size(got.path));
    EXPECT_FALSE(fs::exists(got.path + ".tmp"));
    auto read = ReadChunkWedges(dir.string(), got.chunk);
    ASSERT_TRUE(read.ok()) << read.status();
    EXPECT_TRUE(SameRecords(*read, expected)) << got.chunk.transpose();
  }
  fs::remove_all(dir);
}

TEST(ChunkSpillTest, TinyBudgetGivesTheSameBytes) {
  const std::vector<Wedge> wedges = ScanWedges(80, 2);
  const fs::path big = TempDir("big"), tiny = TempDir("tiny");
  uint64_t big_flushes = 0, tiny_flushes = 0;
  auto a = Spill(wedges, big, 1u << 30, &big_flushes);
  auto b = Spill(wedges, tiny, 4096, &tiny_flushes);
  ASSERT_TRUE(a.ok()) << a.status();
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(big_flushes, 0u);
  EXPECT_GT(tiny_flushes, 5 * a->size());  // many appends per chunk
  ASSERT_EQ(a->size(), b->size());
  for (size_t i = 0; i < a->size(); ++i) {
    EXPECT_EQ((*a)[i].chunk, (*b)[i].chunk);
    EXPECT_EQ((*a)[i].wedge_count, (*b)[i].wedge_count);
    EXPECT_EQ((*a)[i].file_bytes, (*b)[i].file_bytes);
    EXPECT_EQ(ReadBytes((*a)[i].path), ReadBytes((*b)[i].path)) << (*a)[i].chunk.transpose();
  }
  fs::remove_all(big);
  fs::remove_all(tiny);
}

TEST(ChunkSpillTest, Deterministic) {
  const std::vector<Wedge> wedges = ScanWedges(40, 3);
  const fs::path d1 = TempDir("det1"), d2 = TempDir("det2");
  auto a = Spill(wedges, d1, 20000);
  auto b = Spill(wedges, d2, 20000);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->size(), b->size());
  for (size_t i = 0; i < a->size(); ++i) {
    EXPECT_EQ(ReadBytes((*a)[i].path), ReadBytes((*b)[i].path));
  }
  // Re-spilling into the same directory (a restarted coordinator) replaces the files.
  auto c = Spill(wedges, d1, 1u << 20);
  ASSERT_TRUE(c.ok());
  for (size_t i = 0; i < a->size(); ++i) {
    EXPECT_EQ(ReadBytes((*c)[i].path), ReadBytes((*b)[i].path));
  }
  fs::remove_all(d1);
  fs::remove_all(d2);
}

TEST(ChunkSpillTest, CorruptFilesGiveClearErrors) {
  const fs::path dir = TempDir("corrupt");
  auto chunks = Spill(ScanWedges(10, 4), dir, 1u << 20);
  ASSERT_TRUE(chunks.ok());
  const SpilledChunk& c = chunks->front();
  const std::string good = ReadBytes(c.path);
  auto rewrite = [&](const std::string& bytes) {
    std::ofstream(c.path, std::ios::binary | std::ios::trunc) << bytes;
  };
  auto expect_error = [&](const std::string& what) {
    auto r = ReadChunkWedges(dir.string(), c.chunk);
    ASSERT_FALSE(r.ok()) << what;
    EXPECT_EQ(r.status().code(), absl::StatusCode::kDataLoss) << what;
    EXPECT_THAT(r.status().message(), HasSubstr(c.path)) << what;
    EXPECT_THAT(r.status().message(), HasSubstr(what));
  };

  rewrite(good.substr(0, good.size() - 100));
  expect_error("header says");
  rewrite(good.substr(0, 20));
  expect_error("truncated header");
  std::string bad = good;
  bad[0] = 'X';
  rewrite(bad);
  expect_error("bad magic");
  bad = good;
  bad[60] ^= 0x40;
  rewrite(bad);
  expect_error("payload checksum");
  bad = good;
  bad[30] ^= 1;  // wedge count
  rewrite(bad);
  expect_error("header checksum");
  rewrite(good + "xyz");
  expect_error("header says");
  // A file of another chunk under this chunk's name.
  std::filesystem::copy_file((*chunks)[1].path, c.path, fs::copy_options::overwrite_existing);
  expect_error("holds chunk");

  auto missing = ReadChunkWedges(dir.string(), ChunkKey(1000, 0, 0));
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(missing.status().message(), HasSubstr("chunk_1000_0_0.wedges"));
  fs::remove_all(dir);
}

// A walk's frame pairs with the wedge builder's ray ids: each ray of a chunk is stored once
// however many of its wedges the chunk holds, and reads back as the same wedges.
TEST(ChunkSpillTest, SharedRaysAreStoredOncePerChunk) {
  constexpr int kFrames = 30, kBeams = 40;
  std::vector<std::vector<RayModel>> frames;
  for (int f = 0; f < kFrames; ++f) {
    const Eigen::Vector3f s(0.05f * f - 1.0f, 0.3f, 1.5f);
    std::vector<RayModel> rays;
    for (int j = 0; j < kBeams; ++j) {
      const float a = 0.04f * j;
      rays.push_back(RayModel{s, s + 3.0f * Eigen::Vector3f(0.1f, std::cos(a), std::sin(a)),
                              Iso(0.005f), Iso(0.01f + 0.001f * j)});
    }
    frames.push_back(rays);
  }
  const fs::path dir = TempDir("shared");
  auto spiller = ChunkSpiller::Create({dir.string(), 1u << 20});
  ASSERT_TRUE(spiller.ok());
  std::map<std::array<int, 3>, std::vector<Wedge>> want;
  for (int f = 0; f + 1 < kFrames; ++f) {
    for (int j = 0; j + 1 < kBeams; ++j) {
      Wedge w;
      w.rays = {frames[f][j], frames[f][j + 1], frames[f + 1][j], frames[f + 1][j + 1]};
      const std::array<RayId, 4> ids = {RayId{0, uint64_t(f), uint32_t(j)},
                                        RayId{0, uint64_t(f), uint32_t(j + 1)},
                                        RayId{0, uint64_t(f + 1), uint32_t(j)},
                                        RayId{0, uint64_t(f + 1), uint32_t(j + 1)}};
      ASSERT_TRUE((*spiller)->Add(w, ids).ok());
      for (const ChunkKey& c : ChunksOfWedge(w)) want[{c.x(), c.y(), c.z()}].push_back(w);
    }
  }
  auto chunks = (*spiller)->Finish();
  ASSERT_TRUE(chunks.ok()) << chunks.status();
  ASSERT_EQ(chunks->size(), want.size());
  uint64_t bytes = 0, pairs = 0;
  for (const SpilledChunk& c : *chunks) {
    auto file = ReadChunkSpillFile(c.path);
    ASSERT_TRUE(file.ok()) << file.status();
    auto decoded = DecodeWedgePayload(file->payload);
    ASSERT_TRUE(decoded.ok()) << decoded.status();
    // No ray twice: as many rays as distinct rays among the chunk's wedges.
    std::set<std::vector<float>> distinct;
    const std::vector<Wedge>& expected = want.at({c.chunk.x(), c.chunk.y(), c.chunk.z()});
    for (const Wedge& w : expected) {
      for (const RayModel& r : w.rays) {
        distinct.insert({r.point_mean.x(), r.point_mean.y(), r.point_mean.z(), r.sensor_mean.x()});
      }
    }
    EXPECT_EQ(decoded->rays.size(), distinct.size());
    auto read = ReadChunkWedges(dir.string(), c.chunk);
    ASSERT_TRUE(read.ok());
    EXPECT_TRUE(SameRecords(*read, expected));
    bytes += c.file_bytes;
    pairs += c.wedge_count;
  }
  // Version 1 stored 289 bytes per wedge and chunk; with each ray once it is a fifth of that.
  EXPECT_LT(bytes, pairs * 60);
  fs::remove_all(dir);
}

TEST(ChunkSpillTest, OlderVersionsAreRejectedByName) {
  const fs::path dir = TempDir("version");
  auto chunks = Spill(ScanWedges(5, 6), dir, 1u << 20);
  ASSERT_TRUE(chunks.ok());
  const SpilledChunk& c = chunks->front();
  std::string bytes = ReadBytes(c.path);
  ASSERT_EQ(bytes[8], char(kChunkSpillVersion));
  bytes[8] = 1;  // a version-1 file, header checksum valid
  const uint32_t crc = Crc32c(std::string_view(bytes.data(), 44));
  for (int i = 0; i < 4; ++i) bytes[44 + i] = char(crc >> (8 * i));
  std::ofstream(c.path, std::ios::binary | std::ios::trunc) << bytes;
  auto r = ReadChunkSpillFile(c.path);
  EXPECT_EQ(r.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(r.status().message(), HasSubstr("unsupported version 1 (this build reads 2"));
  EXPECT_THAT(r.status().message(), HasSubstr("ingest the scan again"));
  EXPECT_EQ(Crc32c("123456789"), 0xe3069283u);  // the check value WEDGE_FORMAT.md gives
  fs::remove_all(dir);
}

TEST(ChunkSpillTest, RejectsBadInputAndMisuse) {
  EXPECT_FALSE(ChunkSpiller::Create({"", 100}).ok());
  EXPECT_FALSE(ChunkSpiller::Create({"/tmp/x", 0}).ok());
  const fs::path dir = TempDir("misuse");
  auto spiller = ChunkSpiller::Create({dir.string(), 1000});
  ASSERT_TRUE(spiller.ok());
  Wedge w = ScanWedges(1, 5)[1];
  Wedge bad = w;
  bad.rays[1].point_mean.x() = std::nanf("");
  EXPECT_EQ((*spiller)->Add(bad).code(), absl::StatusCode::kInvalidArgument);
  bad = w;
  bad.num_rays = 0;
  EXPECT_EQ((*spiller)->Add(bad).code(), absl::StatusCode::kInvalidArgument);
  bad = w;
  bad.rays[0].point_mean.x() = 5e6f;
  EXPECT_EQ((*spiller)->Add(bad).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE((*spiller)->Add(w).ok());
  EXPECT_TRUE((*spiller)->Finish().ok());
  EXPECT_EQ((*spiller)->Add(w).code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ((*spiller)->Finish().status().code(), absl::StatusCode::kFailedPrecondition);
  fs::remove_all(dir);
  // An unwritable directory names the path.
  auto blocked = ChunkSpiller::Create({"/proc/no_such_dir/spill", 1000});
  EXPECT_FALSE(blocked.ok());
}

}  // namespace
}  // namespace carvemap

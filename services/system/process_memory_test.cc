#include "services/system/process_memory.h"

#include <gtest/gtest.h>
#include <sys/resource.h>

#include <array>
#include <cstring>
#include <memory>
#include <vector>

namespace carvemap {
namespace {

TEST(ProcessStatus, ResidentGrowsWithTouchedMemoryAndPeakHoldsIt) {
  const ProcessStatus before = ReadProcessStatus();
  ASSERT_GT(before.resident_bytes, 0u);
  EXPECT_GE(before.peak_resident_bytes, before.resident_bytes);
  {
    std::vector<char> block(size_t{64} << 20);
    std::memset(block.data(), 1, block.size());  // touched: resident
    const ProcessStatus during = ReadProcessStatus();
    EXPECT_GE(during.resident_bytes, before.resident_bytes + (size_t{60} << 20));
    EXPECT_GE(during.peak_resident_bytes, during.resident_bytes);
  }
  const ProcessStatus after = ReadProcessStatus();
  EXPECT_GE(after.peak_resident_bytes, before.resident_bytes + (size_t{60} << 20));
}

TEST(ProcessStatus, FreedLargeBuffersLeaveTheResidentSet) {
  ASSERT_TRUE(MapLargeBuffersAlone());
  // A 24 MiB buffer freed would have raised glibc's threshold above the 8 MiB one below, which
  // would then have come from the heap and stayed resident once freed.
  { std::vector<char> big(size_t{24} << 20, 1); }
  uint64_t with = 0;
  {
    std::vector<char> block(size_t{8} << 20, 1);
    with = ReadProcessStatus().resident_bytes;
  }
  const uint64_t without = ReadProcessStatus().resident_bytes;
  EXPECT_GE(with, without + (size_t{7} << 20));
}

TEST(ProcessStatus, ABufferFreedAtTheHeapTopStaysForTheNextOne) {
  ASSERT_TRUE(MapLargeBuffersAlone());
  const auto faults = [] {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return usage.ru_minflt;
  };
  // Below the 1 MiB threshold: from the heap. glibc's default 128 KiB trim threshold would give
  // its 128 pages back when freed, and the same buffer again would fault them all in.
  { std::vector<char> first(size_t{512} << 10, 1); }
  const long before = faults();
  { std::vector<char> again(size_t{512} << 10, 1); }
  EXPECT_LT(faults() - before, 16);
}

TEST(ProcessStatus, FreedSmallBlocksGoBackWhenAsked) {
  // 64 MiB in 64-byte blocks, then all freed but every 4096th (one per ~256 KiB): glibc keeps
  // the free pages between the survivors resident until ReturnFreedMemory.
  std::vector<std::unique_ptr<std::array<char, 64>>> blocks(size_t{1} << 20);
  for (auto& b : blocks) {
    b = std::make_unique<std::array<char, 64>>();
    b->fill(1);
  }
  for (size_t i = 0; i < blocks.size(); ++i) {
    if (i % 4096 != 0) blocks[i].reset();
  }
  const uint64_t freed = ReadProcessStatus().resident_bytes;
  ReturnFreedMemory();
  const uint64_t returned = ReadProcessStatus().resident_bytes;
  EXPECT_GE(freed, returned + (size_t{32} << 20));
}

TEST(ProcessStatus, StatusText) {
  const ProcessStatus m = ParseProcessStatus(
      "Name:\tcarvemap\nVmPeak:\t 900000 kB\nVmHWM:\t  812344 kB\nVmRSS:\t  402112 kB\n"
      "Threads:\t7\n");
  EXPECT_EQ(m.resident_bytes, uint64_t{402112} << 10);
  EXPECT_EQ(m.peak_resident_bytes, uint64_t{812344} << 10);
  EXPECT_EQ(m.threads, 7);
  const ProcessStatus none = ParseProcessStatus("Name:\tx\nVmRSS: lots\n");
  EXPECT_EQ(none.resident_bytes, 0u);
  EXPECT_EQ(none.peak_resident_bytes, 0u);
}

TEST(ProcessStatus, MemoryMaxTexts) {
  EXPECT_EQ(BytesOfMemoryMax("max\n"), std::nullopt);                  // v2: no limit
  EXPECT_EQ(BytesOfMemoryMax("4294967296\n"), 4294967296u);            // a 4 GiB pod
  EXPECT_EQ(BytesOfMemoryMax("9223372036854771712\n"), std::nullopt);  // v1: no limit
  EXPECT_EQ(BytesOfMemoryMax(""), std::nullopt);
  EXPECT_EQ(BytesOfMemoryMax("12 GiB"), std::nullopt);
  EXPECT_EQ(BytesOfMemoryMax("-1"), std::nullopt);
}

}  // namespace
}  // namespace carvemap

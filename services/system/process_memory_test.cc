#include "services/system/process_memory.h"

#include <cstring>
#include <vector>

#include <gtest/gtest.h>

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

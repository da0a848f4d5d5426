#include "services/system/usable_cpus.h"

#include <sched.h>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

TEST(UsableCpus, CgroupV2CpuMax) {
  EXPECT_FALSE(CpusOfCpuMax("max 100000\n").has_value());
  EXPECT_DOUBLE_EQ(CpusOfCpuMax("150000 100000\n").value(), 1.5);
  EXPECT_DOUBLE_EQ(CpusOfCpuMax("200000 100000").value(), 2.0);
  EXPECT_FALSE(CpusOfCpuMax("").has_value());
  EXPECT_FALSE(CpusOfCpuMax("garbage").has_value());
  EXPECT_FALSE(CpusOfCpuMax("0 100000").has_value());
}

TEST(UsableCpus, CgroupV1Quota) {
  EXPECT_FALSE(CpusOfCfsQuota("-1\n", "100000\n").has_value());
  EXPECT_DOUBLE_EQ(CpusOfCfsQuota("50000\n", "100000\n").value(), 0.5);
  EXPECT_FALSE(CpusOfCfsQuota("50000", "0").has_value());
}

// The affinity mask bounds the count: pinned to one CPU, one CPU is usable.
TEST(UsableCpus, FollowsTheAffinityMask) {
  cpu_set_t saved;
  ASSERT_EQ(sched_getaffinity(0, sizeof(saved), &saved), 0);
  const int before = UsableCpus();
  EXPECT_GE(before, 1);
  EXPECT_LE(before, CPU_COUNT(&saved));
  int first = 0;
  while (!CPU_ISSET(first, &saved)) ++first;
  cpu_set_t one;
  CPU_ZERO(&one);
  CPU_SET(first, &one);
  ASSERT_EQ(sched_setaffinity(0, sizeof(one), &one), 0);
  EXPECT_EQ(UsableCpus(), 1);
  ASSERT_EQ(sched_setaffinity(0, sizeof(saved), &saved), 0);
  EXPECT_EQ(UsableCpus(), before);
}

}  // namespace
}  // namespace carvemap

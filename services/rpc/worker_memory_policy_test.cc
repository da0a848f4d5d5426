#include "services/rpc/worker_memory_policy.h"

#include <gtest/gtest.h>

namespace carvemap {
namespace {

TEST(FreedMemoryPolicy, SlicesGiveBackCombinesKeepUntilIdle) {
  FreedMemoryPolicy policy;
  EXPECT_FALSE(policy.WhenIdle());  // nothing kept yet
  EXPECT_TRUE(policy.AfterTask(/*slice=*/true));
  EXPECT_FALSE(policy.WhenIdle());  // the slice gave it back already
  // A run of combines keeps their buffers for one another.
  EXPECT_FALSE(policy.AfterTask(/*slice=*/false));
  EXPECT_FALSE(policy.AfterTask(/*slice=*/false));
  // Idle after them: given back once, not on every idle poll.
  EXPECT_TRUE(policy.WhenIdle());
  EXPECT_FALSE(policy.WhenIdle());
}

TEST(FreedMemoryPolicy, ASliceAfterCombinesGivesBackWithoutWaitingForIdle) {
  FreedMemoryPolicy policy;
  EXPECT_FALSE(policy.AfterTask(/*slice=*/false));
  EXPECT_TRUE(policy.AfterTask(/*slice=*/true));
  EXPECT_FALSE(policy.WhenIdle());
}

}  // namespace
}  // namespace carvemap

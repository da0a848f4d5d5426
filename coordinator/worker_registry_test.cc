#include "coordinator/worker_registry.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace carvemap {
namespace {

using ::testing::ElementsAre;
using ::testing::IsEmpty;
using ::testing::Pair;

TEST(WorkerRegistryTest, IdsAreUniqueAndNameTheInstance) {
  WorkerRegistry r("ab12");
  EXPECT_EQ(r.Register(0), "w-ab12-1");
  EXPECT_EQ(r.Register(0), "w-ab12-2");
  EXPECT_EQ(r.size(), 2u);
  EXPECT_THAT(r.Ids(), ElementsAre("w-ab12-1", "w-ab12-2"));
  // Another instance's ids are not this one's, even with the same counter.
  WorkerRegistry other("cd34");
  EXPECT_EQ(other.Register(0), "w-cd34-1");
  EXPECT_FALSE(r.Known("w-cd34-1"));
}

TEST(WorkerRegistryTest, TouchKnowsOnlyRegisteredWorkers) {
  WorkerRegistry r("x");
  const std::string id = r.Register(1000);
  EXPECT_TRUE(r.Touch(id, 2000));
  EXPECT_FALSE(r.Touch("w-x-99", 2000));
  EXPECT_FALSE(r.Known("w-x-99"));
}

TEST(WorkerRegistryTest, SilentWorkersAreRemovedAfterTheTimeout) {
  WorkerRegistry r("x");
  const std::string a = r.Register(0), b = r.Register(0);
  r.Touch(b, 4000);
  // Silent for exactly the timeout: still there.
  EXPECT_THAT(r.RemoveSilent(5000, 5000), IsEmpty());
  EXPECT_THAT(r.RemoveSilent(5001, 5000), ElementsAre(Pair(a, 5001)));
  EXPECT_FALSE(r.Known(a));
  EXPECT_TRUE(r.Known(b));
  EXPECT_FALSE(r.Touch(a, 6000));  // lost: it must register again
  EXPECT_THAT(r.RemoveSilent(9001, 5000), ElementsAre(Pair(b, 5001)));
  EXPECT_EQ(r.size(), 0u);
}

TEST(WorkerRegistryTest, TheJobOfTheLatestLeaseGoesWithTheWorker) {
  WorkerRegistry r("x");
  const std::string a = r.Register(0);
  EXPECT_EQ(r.JobOf(a), "");
  r.SetJob(a, "j-1");
  r.SetJob(a, "j-2");
  EXPECT_EQ(r.JobOf(a), "j-2");
  r.SetJob("w-x-7", "j-1");  // unknown: not recorded
  EXPECT_EQ(r.JobOf("w-x-7"), "");
  r.RemoveSilent(10'000, 1000);
  EXPECT_EQ(r.JobOf(a), "");
  // A worker registering later under a new id starts with no job.
  EXPECT_EQ(r.JobOf(r.Register(10'000)), "");
}

TEST(WorkerRegistryTest, LatenessIsCreditedUpToNow) {
  WorkerRegistry r("x");
  const std::string a = r.Register(0), b = r.Register(9000);
  // The sweep ran 3 s late at 10 s: a's silence counts 7 s, b's is capped at now.
  r.CreditLateness(3000, 10'000);
  EXPECT_THAT(r.RemoveSilent(10'000, 6999), ElementsAre(Pair(a, 7000)));
  EXPECT_TRUE(r.Known(b));
  EXPECT_THAT(r.RemoveSilent(10'000, 0), IsEmpty());  // b at now: silent 0 ms
  r.CreditLateness(-5, 10'000);                       // not late: nothing changes
  EXPECT_THAT(r.RemoveSilent(10'001, 0), ElementsAre(Pair(b, 1)));
}

}  // namespace
}  // namespace carvemap

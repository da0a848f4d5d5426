#include "services/merge/parallel_for.h"

#include <atomic>
#include <mutex>
#include <set>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

TEST(ParallelFor, EveryIndexOnceOnAtMostTheThreadsGiven) {
  for (int threads : {1, 3, 16}) {
    for (size_t n : {size_t{0}, size_t{1}, size_t{5}, size_t{1000}}) {
      std::vector<std::atomic<int>> calls(n);
      std::mutex mu;
      std::set<std::thread::id> ran_on;
      ParallelFor(n, threads, [&](size_t i) {
        ++calls[i];
        std::lock_guard<std::mutex> lock(mu);
        ran_on.insert(std::this_thread::get_id());
      });
      for (size_t i = 0; i < n; ++i) EXPECT_EQ(calls[i], 1) << threads << " " << n << " " << i;
      EXPECT_LE(ran_on.size(), size_t(threads));
      if (n > 0 && threads == 1) EXPECT_TRUE(ran_on.count(std::this_thread::get_id()));
    }
  }
}

}  // namespace
}  // namespace carvemap

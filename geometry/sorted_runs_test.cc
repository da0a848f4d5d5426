#include "geometry/sorted_runs.h"

#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace carvemap {
namespace {

using ::testing::ElementsAre;
using ::testing::Pair;

TEST(ForEachRun, GivesEachRunOfEqualKeysOnceInOrder) {
  const std::vector<std::pair<int, char>> items = {{1, 'a'}, {1, 'b'}, {2, 'c'},
                                                   {5, 'd'}, {5, 'e'}, {5, 'f'}};
  std::vector<std::pair<size_t, size_t>> runs;
  ForEachRun(items, [](const auto& x) { return x.first; },
             [&](size_t b, size_t e) { runs.emplace_back(b, e); });
  EXPECT_THAT(runs, ElementsAre(Pair(0, 2), Pair(2, 3), Pair(3, 6)));
}

TEST(ForEachRun, ARunReturningFalseStopsTheWalk) {
  const std::vector<int> items = {1, 1, 2, 3, 3};
  std::vector<size_t> begins;
  ForEachRun(items, [](int x) { return x; }, [&](size_t b, size_t) {
    begins.push_back(b);
    return items[b] != 2;
  });
  EXPECT_THAT(begins, ElementsAre(0, 2));
}

TEST(ForEachRun, NoItemsNoRuns) {
  int calls = 0;
  ForEachRun(std::vector<int>{}, [](int x) { return x; }, [&](size_t, size_t) { ++calls; });
  EXPECT_EQ(calls, 0);
}

}  // namespace
}  // namespace carvemap

#include "services/merge/memory_budget.h"

#include <string>

#include <gtest/gtest.h>

#include "services/mesh/planar_mesh.h"

namespace carvemap {
namespace {

TEST(CheckPlanarMemory, PassesUnderTheBudgetAndWithoutOne) {
  const uint64_t need = 1500 * kPlanarBytesPerFace;
  EXPECT_TRUE(CheckPlanarMemory("x", 1500, 1 << 20, 0).ok());  // no budget
  EXPECT_TRUE(CheckPlanarMemory("x", 1500, 1 << 20, (1 << 20) + need).ok());
  const absl::Status over = CheckPlanarMemory("x", 1500, 1 << 20, (1 << 20) + need - 1);
  EXPECT_EQ(over.code(), absl::StatusCode::kResourceExhausted) << over;
}

TEST(CheckPlanarMemory, NamesTheStageTheEstimateAndTheBudget) {
  const absl::Status s = CheckPlanarMemory("level 1's part of the building's planar mesh", 5007,
                                           uint64_t{3} << 29, uint64_t{1} << 30);
  ASSERT_EQ(s.code(), absl::StatusCode::kResourceExhausted);
  const std::string m(s.message());
  EXPECT_NE(m.find("level 1's part of the building's planar mesh: 5007 boundary faces need about"),
            std::string::npos)
      << m;
  EXPECT_NE(m.find("on top of the 1.50 GiB the merge holds"), std::string::npos) << m;
  EXPECT_NE(m.find("memory budget of 1.00 GiB"), std::string::npos) << m;
  EXPECT_NE(m.find("--memory-mb"), std::string::npos) << m;
  EXPECT_NE(std::string(CheckPlanarMemory("x", 2500000, 0, 1000).message()).find("2.50 M"),
            std::string::npos);
}

// Work beside the stage (the dense mesh) that holds memory is waited for once before the check
// gives up; a stage that still does not fit fails as before; without a budget nothing is read.
TEST(CheckPlanarMemory, WaitsOnceForWorkBesideItBeforeFailing) {
  const uint64_t need = 1000 * kPlanarBytesPerFace, budget = (uint64_t{1} << 20) + need;
  uint64_t held = uint64_t{3} << 20;  // the stage's 1 MiB and 2 MiB of the dense mesh
  int settled = 0, read = 0;
  const auto reading = [&] { return ++read, held; };
  const auto settle = [&] { ++settled, held = uint64_t{1} << 20; };
  EXPECT_TRUE(CheckPlanarMemory("x", 1000, reading, budget, settle).ok());
  EXPECT_EQ(settled, 1);
  EXPECT_EQ(read, 2);
  EXPECT_TRUE(CheckPlanarMemory("x", 1000, reading, budget, settle).ok());  // fits at once
  EXPECT_EQ(settled, 1);
  held = uint64_t{3} << 20;
  EXPECT_EQ(CheckPlanarMemory("x", 1000, reading, budget, nullptr).code(),
            absl::StatusCode::kResourceExhausted);
  const auto settle_frees_nothing = [&] { ++settled; };
  EXPECT_EQ(CheckPlanarMemory("x", 1000, reading, budget, settle_frees_nothing).code(),
            absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(settled, 2);
  read = 0;
  EXPECT_TRUE(CheckPlanarMemory("x", 1000, reading, 0, settle).ok());
  EXPECT_EQ(read, 0);
  EXPECT_EQ(settled, 2);
}

}  // namespace
}  // namespace carvemap

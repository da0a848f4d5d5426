#include "coordinator/rate_window.h"

#include <gtest/gtest.h>

namespace carvemap {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;

TEST(RateWindowTest, SteadyIncrementsGiveTheirRate) {
  RateWindow r(10.0);
  const RateWindow::Time t0{};
  EXPECT_EQ(r.Rate(t0), 0);
  // 1000 units every second (a worker's heartbeat), for a minute.
  for (int i = 1; i <= 60; ++i) {
    r.Add(t0 + seconds(i), 1000);
    EXPECT_NEAR(r.Rate(t0 + seconds(i)), 1000, 1e-9) << i;
  }
  EXPECT_EQ(r.total(), 60000);
  // Between heartbeats the rate holds roughly; once nothing comes for a window it is 0.
  EXPECT_NEAR(r.Rate(t0 + seconds(60) + milliseconds(500)), 9000 / 9.5, 1e-9);
  EXPECT_EQ(r.Rate(t0 + seconds(71)), 0);
}

TEST(RateWindowTest, FollowsAChangeWithinAWindow) {
  RateWindow r(5.0);
  const RateWindow::Time t0{};
  for (int i = 1; i <= 20; ++i) r.Add(t0 + seconds(i), 100);
  // A second worker joins: 400 a second from then on.
  r.Add(t0 + seconds(21), 400);
  r.Add(t0 + seconds(22), 400);
  // The window (17, 22]: after the increment at 17 came 3 × 100 and 2 × 400 in 5 s.
  EXPECT_NEAR(r.Rate(t0 + seconds(22)), (3 * 100 + 2 * 400) / 5.0, 1e-9);
  for (int i = 23; i <= 40; ++i) r.Add(t0 + seconds(i), 400);
  EXPECT_NEAR(r.Rate(t0 + seconds(40)), 400, 1e-9);
}

TEST(RateWindowTest, ASingleIncrementCountsOverAtLeastASecond) {
  RateWindow r(10.0);
  const RateWindow::Time t0{};
  r.Add(t0 + seconds(3), 500);
  EXPECT_NEAR(r.Rate(t0 + seconds(3)), 500, 1e-9);
  EXPECT_NEAR(r.Rate(t0 + seconds(8)), 100, 1e-9);
  r.Add(t0 + seconds(4), 0);  // nothing done: not an increment
  EXPECT_EQ(r.total(), 500);
}

}  // namespace
}  // namespace carvemap

#include "services/rpc/job_client.h"

#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace carvemap {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

WatchUpdate Carving() {
  WatchUpdate u;
  u.state = "CARVING";
  u.chunks_total = 9;
  u.chunks_done = 2;
  u.rays_total = 9'500'000;
  u.rays_done = 3'800'000;
  u.rays_per_s = 80'000;
  u.active_workers = 2;
  u.eta_s = 69;
  u.stage = "carve";
  u.stage_elapsed_s = 70;
  return u;
}

TEST(FormatProgress, CarvingShowsRaysTheirRateAndTheEta) {
  const std::string line = FormatProgress(Carving());
  EXPECT_THAT(line, HasSubstr("2/9 tasks  3.8/9.5 M rays  0.08 M rays/s  2 worker(s)  ETA 1:09"));
  EXPECT_THAT(line, HasSubstr("(carve 70 s)"));
}

// Once every ray is carved the combines remain: no rays/s falling to zero, their own ETA.
TEST(FormatProgress, AllRaysCarvedShowsTheCombines) {
  WatchUpdate u = Carving();
  u.chunks_total = 815;
  u.chunks_done = 588;
  u.rays_done = u.rays_total;
  u.rays_per_s = 0;
  u.eta_s = 12;
  const std::string line = FormatProgress(u);
  EXPECT_THAT(line, HasSubstr("588/815 tasks  9.5 M rays carved, combining chunks  2 worker(s)  "
                              "ETA 0:12"));
  EXPECT_THAT(line, Not(HasSubstr("rays/s")));
  u.eta_s = -1;  // no combine finished within the window yet
  EXPECT_THAT(FormatProgress(u), HasSubstr("combining chunks  2 worker(s)  ETA --:--"));
}

TEST(FormatProgress, MergingShowsTheStagesCounts) {
  WatchUpdate u;
  u.state = "MERGING";
  u.chunks_total = u.chunks_done = 815;
  u.stage_done = 529;
  u.stage_total = 806;
  u.eta_s = 6;
  u.stage = "merge/segmentation";
  u.stage_elapsed_s = 11;
  EXPECT_EQ(FormatProgress(u),
            "MERGING   [########################] 815/815 tasks  529/806  ETA 0:06  "
            "(merge/segmentation 11 s)");
}

}  // namespace
}  // namespace carvemap

#include "coordinator/scan_slices.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "services/sim/simulator.h"

namespace carvemap {
namespace {

std::vector<FrameRecord> Frames(double t0, double dt, int n, uint32_t rays) {
  std::vector<FrameRecord> f;
  for (int i = 0; i < n; ++i) f.push_back({t0 + dt * i, uint64_t(i) * rays, rays});
  return f;
}

// Two line scanners at different rates and phases and a point sensor, with a pause.
TEST(ScanSlicesTest, OwnRowsPartitionEverySensorAndContextSurroundsThem) {
  std::vector<std::vector<FrameRecord>> frames = {Frames(0.01, 0.025, 400, 1081),
                                                  Frames(0.02, 0.05, 200, 541),
                                                  Frames(0.0, 0.1, 100, 77)};
  // A pause: the points sensor stops at 10 s and records again from 25 s.
  for (int i = 0; i < 20; ++i) frames[2].push_back({25.0 + 0.1 * i, 0, 77});
  const std::vector<SensorKind> kinds = {SensorKind::kLine, SensorKind::kLine,
                                         SensorKind::kPoints};
  absl::StatusOr<std::vector<ScanSlice>> slices = PlanSlices(frames, kinds, 3.0);
  ASSERT_TRUE(slices.ok()) << slices.status();
  // 0–27 s in 3 s slices: [0, 3), [3, 6), [6, 9), [9, 12), then [24, 27); those of 12–24 s
  // hold no frame (the line sensors end at 10 s) and are left out.
  ASSERT_EQ(slices->size(), 5u);
  std::vector<uint64_t> next(3, 0);
  for (size_t k = 0; k < slices->size(); ++k) {
    const ScanSlice& s = (*slices)[k];
    EXPECT_EQ(s.index, k);
    uint64_t rays = 0;
    for (size_t i = 0; i < 3; ++i) {
      EXPECT_EQ(s.own[i].begin, next[i]) << k << " " << i;  // contiguous, in order
      next[i] = s.own[i].end;
      for (uint64_t r = s.own[i].begin; r < s.own[i].end; ++r) {
        EXPECT_GE(frames[i][r].t, s.t_begin);
        EXPECT_LT(frames[i][r].t, s.t_end);
        rays += frames[i][r].count;
      }
      if (s.own[i].begin == s.own[i].end) {
        EXPECT_EQ(s.read[i].begin, s.read[i].end);
      } else if (kinds[i] == SensorKind::kLine) {
        EXPECT_EQ(s.read[i].begin, s.own[i].begin - std::min<uint64_t>(2, s.own[i].begin));
        EXPECT_EQ(s.read[i].end, std::min<uint64_t>(frames[i].size(), s.own[i].end + 1));
      } else {
        EXPECT_EQ(s.read[i].begin, s.own[i].begin);
        EXPECT_EQ(s.read[i].end, s.own[i].end);
      }
    }
    EXPECT_EQ(s.own_rays, rays);
  }
  for (size_t i = 0; i < 3; ++i) EXPECT_EQ(next[i], frames[i].size());  // every row, once
  EXPECT_EQ((*slices)[4].t_begin, 24.0);  // after the pause, numbered on
}

TEST(ScanSlicesTest, LengthsAndErrors) {
  SlicePlanOptions o;
  // The backpack at full rate: 151 M rays in 1164 s → about 31 s per 4 M rays.
  EXPECT_NEAR(SliceSeconds(o, 151'000'000, 1164), 1164 * 4.0 / 151, 1e-9);
  EXPECT_EQ(SliceSeconds(o, 1'000'000, 600), 75);    // a sparse scan: still 8 slices
  EXPECT_EQ(SliceSeconds(o, 400'000'000, 100), 10);  // a dense one: not below min_slice_s
  EXPECT_EQ(SliceSeconds(o, 200'000, 8), 2);         // a short one: not below 2 s
  o.slice_s = 7;
  EXPECT_EQ(SliceSeconds(o, 151'000'000, 1164), 7);
  const std::vector<std::vector<FrameRecord>> one = {Frames(0, 1, 5, 10)};
  const std::vector<SensorKind> line = {SensorKind::kLine};
  EXPECT_FALSE(PlanSlices(one, line, 0).ok());
  EXPECT_FALSE(PlanSlices(one, {}, 1).ok());
  absl::StatusOr<std::vector<ScanSlice>> all = PlanSlices(one, line, 100);
  ASSERT_TRUE(all.ok());
  ASSERT_EQ(all->size(), 1u);
  EXPECT_EQ(all->front().own[0].end, 5u);
  const std::vector<std::vector<FrameRecord>> none = {{}};
  absl::StatusOr<std::vector<ScanSlice>> empty = PlanSlices(none, line, 1);
  ASSERT_TRUE(empty.ok());
  EXPECT_TRUE(empty->empty());
}

// The plan read from a file: the same slices as PlanSlices over the file's frame tables, the
// scan's rays counted, the options honoured.
TEST(ScanSlicesTest, PlanScanSlicesReadsTheFramesTablesOfAFile) {
  const std::string root =
      (std::filesystem::path(::testing::TempDir()) / "scan_slices_test").string();
  std::filesystem::remove_all(root);
  SimulateOptions sim;
  sim.preset = "office";
  sim.rig.rate_hz = 3;
  sim.rig.beam_step_deg = 2;
  sim.max_duration_s = 12;
  sim.output_dir = root;
  absl::StatusOr<SimulationSummary> simulated = Simulate(sim);
  ASSERT_TRUE(simulated.ok()) << simulated.status();
  ScanReader::OpenOptions open;
  open.path_rows = ScanReader::PathRows::kNone;
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(simulated->scan_path, open);
  ASSERT_TRUE(reader.ok()) << reader.status();

  SlicePlanOptions options;
  options.slice_s = 2.5;
  absl::StatusOr<ScanSlicePlan> plan = PlanScanSlices(**reader, options);
  ASSERT_TRUE(plan.ok()) << plan.status();
  EXPECT_EQ(plan->slice_s, 2.5);
  std::vector<std::vector<FrameRecord>> frames;
  std::vector<SensorKind> kinds;
  uint64_t rays = 0;
  for (size_t i = 0; i < (*reader)->sensors().size(); ++i) {
    frames.push_back(*(*reader)->FrameRecords(int(i)));
    kinds.push_back((*reader)->sensors()[i].kind);
    for (const FrameRecord& r : frames.back()) rays += r.count;
  }
  EXPECT_EQ(plan->rays, rays);
  EXPECT_GT(rays, 0u);
  absl::StatusOr<std::vector<ScanSlice>> expected = PlanSlices(frames, kinds, 2.5);
  ASSERT_TRUE(expected.ok());
  ASSERT_EQ(plan->slices.size(), expected->size());
  EXPECT_GE(plan->slices.size(), 4u);
  for (size_t k = 0; k < expected->size(); ++k) {
    EXPECT_EQ(plan->slices[k].own_rays, (*expected)[k].own_rays) << k;
    EXPECT_EQ(plan->slices[k].t_begin, (*expected)[k].t_begin) << k;
  }
  // The default length: SliceSeconds of the file's rays and duration.
  absl::StatusOr<ScanSlicePlan> by_default = PlanScanSlices(**reader, SlicePlanOptions{});
  ASSERT_TRUE(by_default.ok()) << by_default.status();
  EXPECT_EQ(by_default->rays, rays);
  EXPECT_GE(by_default->slices.size(), 2u);
}

}  // namespace
}  // namespace carvemap

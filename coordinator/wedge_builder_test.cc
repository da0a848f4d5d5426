#include "coordinator/wedge_builder.h"

#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <set>
#include <span>
#include <string>
#include <tuple>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "storage/scan_reader.h"
#include "storage/scan_writer.h"

namespace carvemap {
namespace {

using Eigen::Vector3d;
using Eigen::Vector3f;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr double kWallX = 5.0;

// A 2D scanner whose scan plane is the system's x–z plane (its own x–y plane rolled 90° about
// x), rays from −30° to +30° in elevation.
SensorInfo VerticalLineSensor() {
  SensorInfo s;
  s.name = "v0";
  s.kind = SensorKind::kLine;
  s.R_s2c = Eigen::AngleAxisd(M_PI / 2, Vector3d::UnitX()).toRotationMatrix();
  s.range_sigma = {0.01, 0.0};
  return s;
}

double RayAngle(int j, int num_rays) { return (-30.0 + 60.0 * j / (num_rays - 1)) * M_PI / 180; }

// Frame i of a sweep along +y past the wall x = kWallX: ray j ends on the wall at height
// kWallX·tan(angle) (or on a surface at `range_x` in front of the sensor if given).
ScanFrame WallFrame(int i, int num_rays, const std::vector<double>& range_x = {}) {
  ScanFrame f;
  f.sensor = 0;
  f.row = i;
  f.t = 0.025 * i;
  for (int j = 0; j < num_rays; ++j) {
    const double x = range_x.empty() ? kWallX : range_x[j];
    f.points_sensor.emplace_back(float(x), float(x * std::tan(RayAngle(j, num_rays))), 0.f);
  }
  return f;
}

FrameContext WalkContext(int i) {
  FrameContext c;
  c.pose_world_sys.translation = Vector3d(0, 0.1 * i, 0);
  c.covariance = DefaultPoseCovariance(NoiseModelOptions{});
  return c;
}

struct Collected {
  std::vector<Wedge> wedges;
  std::vector<std::vector<RayId>> ids;
  WedgeSink Sink() {
    return [this](const Wedge& w, std::span<const RayId> i) {
      wedges.push_back(w);
      ids.emplace_back(i.begin(), i.end());
      return absl::OkStatus();
    };
  }
  int Count(int num_rays) const {
    int n = 0;
    for (const Wedge& w : wedges) n += w.num_rays == num_rays;
    return n;
  }
};

TEST(WedgeBuilderTest, OptionsValidate) {
  EXPECT_TRUE(WedgeBuilderOptions{}.Validate().ok());
  WedgeBuilderOptions o;
  o.max_range_ratio = 0.9;
  EXPECT_EQ(o.Validate().code(), absl::StatusCode::kInvalidArgument);
  o = {};
  o.min_jump_m = -1;
  EXPECT_FALSE(o.Validate().ok());
  o = {};
  o.noise.covariance_floor_m = NAN;
  EXPECT_FALSE(o.Validate().ok());
}

TEST(WedgeBuilderTest, LineSensorSweepingAWall) {
  constexpr int kRays = 9, kFrames = 6;
  Collected out;
  absl::StatusOr<WedgeBuilder> b =
      WedgeBuilder::Create({VerticalLineSensor()}, WedgeBuilderOptions{}, out.Sink());
  ASSERT_TRUE(b.ok()) << b.status();
  for (int i = 0; i < kFrames; ++i) ASSERT_TRUE(b->AddFrame(WallFrame(i, kRays), WalkContext(i)).ok());
  ASSERT_TRUE(b->Finish().ok());
  ASSERT_EQ(out.wedges.size(), size_t{(kRays - 1) * (kFrames - 1)});
  EXPECT_EQ(out.Count(1), 0);
  EXPECT_EQ(b->stats().wedges, uint64_t{(kRays - 1) * (kFrames - 1)});
  EXPECT_EQ(b->stats().rays, uint64_t{kRays * kFrames});
  EXPECT_EQ(b->stats().frames, uint64_t{kFrames});

  // Wedges come per frame pair, ray pairs ascending; corners {(i,j), (i,j+1), (i+1,j), (i+1,j+1)}.
  for (int i = 0; i + 1 < kFrames; ++i) {
    for (int j = 0; j + 1 < kRays; ++j) {
      const Wedge& w = out.wedges[i * (kRays - 1) + j];
      ASSERT_EQ(w.num_rays, 4);
      const int fi[4] = {i, i, i + 1, i + 1};
      const int rj[4] = {j, j + 1, j, j + 1};
      for (int k = 0; k < 4; ++k) {
        const Vector3d expect(kWallX, 0.1 * fi[k], kWallX * std::tan(RayAngle(rj[k], kRays)));
        EXPECT_NEAR((w.rays[k].point_mean.cast<double>() - expect).norm(), 0, 1e-5)
            << "frame pair " << i << " ray " << j << " corner " << k;
        EXPECT_NEAR((w.rays[k].sensor_mean.cast<double>() - Vector3d(0, 0.1 * fi[k], 0)).norm(), 0,
                    1e-6);
        // Eq 4.6 includes range noise along the ray: the point is more uncertain than the sensor.
        EXPECT_GT(w.rays[k].point_cov[0], w.rays[k].sensor_cov[0]);
      }
    }
  }
}

// The ids let a slice store each ray once: equal ids are the same ray, bit for bit, and
// rays of one frame share their sensor Gaussian.
TEST(WedgeBuilderTest, RayIdsNameRaysAndFrames) {
  constexpr int kRays = 9, kFrames = 6;
  Collected out;
  absl::StatusOr<WedgeBuilder> b =
      WedgeBuilder::Create({VerticalLineSensor()}, WedgeBuilderOptions{}, out.Sink());
  ASSERT_TRUE(b.ok()) << b.status();
  for (int i = 0; i < kFrames; ++i) {
    ScanFrame f = WallFrame(i, kRays);
    if (i == 3) f.points_sensor[4] = Vector3f(kNaN, kNaN, kNaN);  // singles too
    ASSERT_TRUE(b->AddFrame(f, WalkContext(i)).ok());
  }
  ASSERT_TRUE(b->Finish().ok());
  ASSERT_EQ(out.ids.size(), out.wedges.size());
  std::map<std::tuple<uint32_t, uint64_t, uint32_t>, RayModel> rays;
  std::map<std::pair<uint32_t, uint64_t>, RayModel> frames;
  size_t shared = 0;
  for (size_t w = 0; w < out.wedges.size(); ++w) {
    ASSERT_EQ(out.ids[w].size(), out.wedges[w].num_rays);
    for (int r = 0; r < out.wedges[w].num_rays; ++r) {
      const RayId& id = out.ids[w][r];
      const RayModel& ray = out.wedges[w].rays[r];
      EXPECT_EQ(id.sensor, 0u);
      EXPECT_LT(id.frame, uint64_t{kFrames});
      EXPECT_LT(id.index, uint32_t{kRays});
      auto [it, inserted] = rays.try_emplace({id.sensor, id.frame, id.index}, ray);
      if (!inserted) {
        ++shared;
        EXPECT_EQ(std::memcmp(&it->second, &ray, sizeof(RayModel)), 0);
      }
      auto [f, new_frame] = frames.try_emplace({id.sensor, id.frame}, ray);
      EXPECT_EQ(f->second.sensor_mean, ray.sensor_mean);
      EXPECT_EQ(f->second.sensor_cov, ray.sensor_cov);
    }
  }
  EXPECT_EQ(rays.size(), size_t{kRays * kFrames - 1});  // every return, the NaN row not
  EXPECT_EQ(frames.size(), size_t{kFrames});
  EXPECT_GT(shared, rays.size());  // inner rays are in four wedges
  // Distinct ids, distinct rays.
  std::set<std::vector<float>> distinct;
  for (const auto& [id, ray] : rays) {
    distinct.insert({ray.point_mean.x(), ray.point_mean.y(), ray.point_mean.z()});
  }
  EXPECT_EQ(distinct.size(), rays.size());
}

TEST(WedgeBuilderTest, MissingReturnsLeaveIsolatedRaysAsSingles) {
  constexpr int kRays = 7, kFrames = 5;
  Collected out;
  absl::StatusOr<WedgeBuilder> b =
      WedgeBuilder::Create({VerticalLineSensor()}, WedgeBuilderOptions{}, out.Sink());
  ASSERT_TRUE(b.ok());
  for (int i = 0; i < kFrames; ++i) {
    ScanFrame f = WallFrame(i, kRays);
    if (i == 2) {  // a frame that only returned ray 3
      for (int j = 0; j < kRays; ++j) {
        if (j != 3) f.points_sensor[j] = Vector3f(kNaN, kNaN, kNaN);
      }
    }
    ASSERT_TRUE(b->AddFrame(f, WalkContext(i)).ok());
  }
  ASSERT_TRUE(b->Finish().ok());
  // Pairs (1,2) and (2,3) form nothing; every other ray is still in some wedge.
  EXPECT_EQ(out.Count(4), (kRays - 1) * (kFrames - 1 - 2));
  ASSERT_EQ(out.Count(1), 1);
  EXPECT_EQ(b->stats().rays_without_return, uint64_t{kRays - 1});
  for (const Wedge& w : out.wedges) {
    if (w.num_rays != 1) continue;
    const Vector3d expect(kWallX, 0.2, kWallX * std::tan(RayAngle(3, kRays)));
    for (const RayModel& r : w.rays) {  // the ray fills all four slots
      EXPECT_NEAR((r.point_mean.cast<double>() - expect).norm(), 0, 1e-5);
    }
  }
}

TEST(WedgeBuilderTest, DepthDiscontinuityIsNotBridged) {
  constexpr int kRays = 8, kFrames = 5;
  Collected out;
  absl::StatusOr<WedgeBuilder> b =
      WedgeBuilder::Create({VerticalLineSensor()}, WedgeBuilderOptions{}, out.Sink());
  ASSERT_TRUE(b.ok());
  for (int i = 0; i < kFrames; ++i) {
    std::vector<double> range_x(kRays, kWallX);
    if (i == 2) range_x[3] = range_x[4] = 2.0;  // a thin pole 3 m in front of the wall
    ASSERT_TRUE(b->AddFrame(WallFrame(i, kRays, range_x), WalkContext(i)).ok());
  }
  ASSERT_TRUE(b->Finish().ok());
  // Ray pairs j = 2, 3, 4 of frame pairs (1,2) and (2,3) touch the pole's rays.
  EXPECT_EQ(b->stats().discontinuities, 6u);
  EXPECT_EQ(out.Count(4), (kRays - 1) * (kFrames - 1) - 6);
  // The pole's two returns are carved alone; nothing is lost.
  ASSERT_EQ(out.Count(1), 2);
  for (const Wedge& w : out.wedges) {
    if (w.num_rays == 1) {
      EXPECT_NEAR(w.rays[0].point_mean.x(), 2.0, 1e-5);
    }
  }
}

TEST(WedgeBuilderTest, SmallRangeChangesAndNoiseAreJoined) {
  // Two frames of two rays (±30°) with the given ranges along x; the builder's stats.
  auto build = [](const std::vector<double>& first, const std::vector<double>& second,
                  Collected& out) {
    absl::StatusOr<WedgeBuilder> b =
        WedgeBuilder::Create({VerticalLineSensor()}, WedgeBuilderOptions{}, out.Sink());
    EXPECT_TRUE(b.ok());
    EXPECT_TRUE(b->AddFrame(WallFrame(0, 2, first), WalkContext(0)).ok());
    EXPECT_TRUE(b->AddFrame(WallFrame(1, 2, second), WalkContext(1)).ok());
    EXPECT_TRUE(b->Finish().ok());
    return b->stats();
  };
  Collected jump, near, far, steep;
  EXPECT_EQ(build({0.3, 5.0}, {0.38, 6.0}, jump).discontinuities, 1u);  // 0.3 vs 6 m
  EXPECT_EQ(jump.Count(4), 0);
  EXPECT_EQ(jump.Count(1), 4);
  // 0.3 m vs 0.38 m: a 27 % ratio but under min_jump_m; 5 m vs 5.35 m: 7 %, under the ratio.
  build({0.30, 0.32}, {0.38, 0.35}, near);
  EXPECT_EQ(near.Count(4), 1);
  build({5.0, 5.2}, {5.2, 5.35}, far);
  EXPECT_EQ(far.Count(4), 1);
  // 5 m then 6 m, frames 10 cm apart: within the range rule's 25 %, but the points lie 1.15 m
  // apart for 10 cm between the rays, a surface met at 85° or an occlusion edge: not joined.
  EXPECT_EQ(build({5.0, 5.5}, {6.0, 5.2}, steep).discontinuities, 1u);
  EXPECT_EQ(steep.Count(4), 0);
}

// An occlusion edge that the range rule joins: a near surface (x = 4) over a far one (the wall,
// x = 5), 1 m apart along the rays where neighbouring rays are 9 cm apart, as a desk's front edge
// over the chair seat below it. A wedge across it would carve a solid sheet joining the two.
TEST(WedgeBuilderTest, OcclusionEdgeIsNotBridged) {
  constexpr int kRays = 61, kFrames = 4;  // 1° apart
  std::vector<double> range_x(kRays, kWallX);
  for (int j = 40; j < kRays; ++j) range_x[j] = 4.0;
  auto build = [&](double max_obliquity, Collected& out) {
    WedgeBuilderOptions o;
    o.max_obliquity = max_obliquity;
    absl::StatusOr<WedgeBuilder> b = WedgeBuilder::Create({VerticalLineSensor()}, o, out.Sink());
    EXPECT_TRUE(b.ok());
    for (int i = 0; i < kFrames; ++i) {
      EXPECT_TRUE(b->AddFrame(WallFrame(i, kRays, range_x), WalkContext(i)).ok());
    }
    EXPECT_TRUE(b->Finish().ok());
    return b->stats();
  };
  auto spans_edge = [](const Collected& out) {
    int n = 0;
    for (size_t w = 0; w < out.wedges.size(); ++w) {
      if (out.wedges[w].num_rays != 4) continue;
      std::set<uint32_t> index;
      for (const RayId& id : out.ids[w]) index.insert(id.index);
      n += index.count(39) && index.count(40);
    }
    return n;
  };
  Collected split, joined;
  const WedgeBuilderStats s = build(WedgeBuilderOptions{}.max_obliquity, split);
  EXPECT_EQ(s.discontinuities, uint64_t{kFrames - 1});
  EXPECT_EQ(spans_edge(split), 0);
  EXPECT_EQ(split.Count(4), (kRays - 2) * (kFrames - 1));
  EXPECT_EQ(split.Count(1), 0);  // every ray still belongs to a wedge on its own surface
  // The range rule alone joins them (the test can fail).
  EXPECT_EQ(build(1e9, joined).discontinuities, 0u);
  EXPECT_EQ(spans_edge(joined), kFrames - 1);
  // A limit below 1 would split a wall met head-on: refused.
  WedgeBuilderOptions o;
  o.max_obliquity = 0.5;
  EXPECT_EQ(o.Validate().code(), absl::StatusCode::kInvalidArgument);
}

// Consecutive frames farther apart than max_frame_gap_m across the rays (a walker turning)
// join only on a surface facing the scanner: a near surface in one frame (a chair back, 4 m)
// and a far one in the next (the wall behind, 4.8 m) are one surface met at 53° when the frames
// are 0.6 m apart, which the range and obliquity rules allow.
TEST(WedgeBuilderTest, WideGapsJoinOnlyFacingSurfaces) {
  constexpr int kRays = 61;  // 1° apart: 7–10 cm on the wall
  auto four_ray_wedges = [&](double step_m, double second_range_x) {
    Collected out;
    absl::StatusOr<WedgeBuilder> b =
        WedgeBuilder::Create({VerticalLineSensor()}, WedgeBuilderOptions{}, out.Sink());
    EXPECT_TRUE(b.ok());
    for (int i = 0; i < 2; ++i) {
      FrameContext c = WalkContext(i);
      c.pose_world_sys.translation = Vector3d(0, step_m * i, 0);
      const std::vector<double> range_x(kRays, i == 0 ? 4.0 : second_range_x);
      EXPECT_TRUE(b->AddFrame(WallFrame(i, kRays, range_x), c).ok());
    }
    EXPECT_TRUE(b->Finish().ok());
    return out.Count(4);
  };
  ASSERT_EQ(WedgeBuilderOptions{}.max_frame_gap_m, 0.5);
  EXPECT_EQ(four_ray_wedges(0.4, 4.8), kRays - 1);  // close frames: within the obliquity rule
  EXPECT_EQ(four_ray_wedges(0.6, 4.8), 0);          // far apart, ranges 0.8 m apart
  EXPECT_EQ(four_ray_wedges(0.6, 4.0), kRays - 1);  // far apart on a wall facing the scanner
  EXPECT_EQ(four_ray_wedges(0.6, 4.25), kRays - 1);  // ranges within half the spacing
}

// The point covariance of every ray carved, by (frame, ray).
std::map<std::pair<uint64_t, uint32_t>, Eigen::Matrix3d> PointCovariances(const Collected& out) {
  std::map<std::pair<uint64_t, uint32_t>, Eigen::Matrix3d> cov;
  for (size_t w = 0; w < out.wedges.size(); ++w) {
    for (size_t r = 0; r < out.ids[w].size(); ++r) {
      cov[{out.ids[w][r].frame, out.ids[w][r].index}] = ToMatrix(out.wedges[w].rays[r].point_cov);
    }
  }
  return cov;
}

// §4.2.1's sampling term: each ray's point is spread over its share of the surface up to its
// neighbours' points (in-frame and the previous frame's), within the surface, and not across
// an edge to a surface the range rule still joins.
TEST(WedgeBuilderTest, PointsAreSpreadOverTheirShareOfTheSurface) {
  constexpr int kRays = 61, kFrames = 4;  // 1° apart
  // Rays 40 and up meet a nearer surface x = 4: ray 39 ends at 5.06 m, ray 40 at 4.06 m, which
  // the range rule joins (1 m ≤ 25 % of 4.06 m), 1 m apart against 9 cm between the rays there.
  std::vector<double> range_x(kRays, kWallX);
  for (int j = 40; j < kRays; ++j) range_x[j] = 4.0;
  auto build = [&](double share) {
    WedgeBuilderOptions o;
    o.sampling_share = share;
    Collected out;
    absl::StatusOr<WedgeBuilder> b = WedgeBuilder::Create({VerticalLineSensor()}, o, out.Sink());
    EXPECT_TRUE(b.ok());
    for (int i = 0; i < kFrames; ++i) {
      EXPECT_TRUE(b->AddFrame(WallFrame(i, kRays, range_x), WalkContext(i)).ok());
    }
    EXPECT_TRUE(b->Finish().ok());
    // The step between rays 39 and 40 joins no wedge either (OcclusionEdgeIsNotBridged).
    EXPECT_EQ(b->stats().discontinuities, uint64_t{kFrames - 1});
    return PointCovariances(out);
  };
  const auto spread = build(1.0 / 12), plain = build(0);
  ASSERT_EQ(spread.size(), size_t{kRays * kFrames});
  auto z = [](int j) { return kWallX * std::tan(RayAngle(j, kRays)); };

  // Ray 20 of frame 2: along z half the two in-frame gaps' squares, along y the 10 cm step from
  // frame 1; nothing along the wall's normal x.
  const Eigen::Matrix3d d = spread.at({2, 20}) - plain.at({2, 20});
  const double dz_lo = z(20) - z(19), dz_hi = z(21) - z(20);
  EXPECT_NEAR(d(2, 2), (dz_lo * dz_lo + dz_hi * dz_hi) / 2 / 12, 1e-8);
  EXPECT_NEAR(d(1, 1), 0.1 * 0.1 / 12, 1e-8);
  EXPECT_NEAR(d(0, 0), 0, 1e-9);
  // The first frame has no previous one: only the in-frame spread.
  EXPECT_NEAR((spread.at({0, 20}) - plain.at({0, 20}))(1, 1), 0, 1e-9);
  // Ray 39 is not spread towards ray 40's surface: one side only, and still nothing along x.
  const Eigen::Matrix3d edge = spread.at({2, 39}) - plain.at({2, 39});
  EXPECT_NEAR(edge(2, 2), (z(39) - z(38)) * (z(39) - z(38)) / 12, 1e-8);
  EXPECT_NEAR(edge(0, 0), 0, 1e-9);
}

TEST(WedgeBuilderTest, FramesFarApartAreNotJoined) {
  Collected out;
  absl::StatusOr<WedgeBuilder> b =
      WedgeBuilder::Create({VerticalLineSensor()}, WedgeBuilderOptions{}, out.Sink());
  ASSERT_TRUE(b.ok());
  ScanFrame f0 = WallFrame(0, 4), f1 = WallFrame(1, 4);
  f1.t = f0.t + 2.0;
  ASSERT_TRUE(b->AddFrame(f0, WalkContext(0)).ok());
  ASSERT_TRUE(b->AddFrame(f1, WalkContext(1)).ok());
  ASSERT_TRUE(b->Finish().ok());
  EXPECT_EQ(out.Count(4), 0);
  EXPECT_EQ(out.Count(1), 8);
  // Time going backwards is an error, and so is a row not after the previous one.
  f1.row = 2;
  EXPECT_EQ(b->AddFrame(f1, WalkContext(1)).code(), absl::StatusCode::kOk);
  f0.row = 3;
  EXPECT_EQ(b->AddFrame(f0, WalkContext(0)).code(), absl::StatusCode::kInvalidArgument);
  f1.row = 2;
  f1.t += 1;
  EXPECT_EQ(b->AddFrame(f1, WalkContext(1)).code(), absl::StatusCode::kInvalidArgument);
}

SensorInfo Grid(uint32_t rows, uint32_t cols) {
  SensorInfo s;
  s.name = "depth";
  s.kind = SensorKind::kGrid;
  s.rows = rows;
  s.cols = cols;
  return s;
}

// A depth image of the wall x = kWallX seen by a camera at the origin looking along +x.
ScanFrame GridFrame(uint32_t rows, uint32_t cols) {
  ScanFrame f;
  f.sensor = 0;
  for (uint32_t r = 0; r < rows; ++r) {
    for (uint32_t c = 0; c < cols; ++c) {
      f.points_sensor.emplace_back(float(kWallX), 0.1f * c, -0.1f * r);
    }
  }
  return f;
}

TEST(WedgeBuilderTest, GridNeighbours) {
  Collected out;
  absl::StatusOr<WedgeBuilder> b =
      WedgeBuilder::Create({Grid(3, 4)}, WedgeBuilderOptions{}, out.Sink());
  ASSERT_TRUE(b.ok());
  ASSERT_TRUE(b->AddFrame(GridFrame(3, 4), FrameContext{}).ok());
  ASSERT_EQ(out.Count(4), 2 * 3);
  EXPECT_EQ(out.Count(1), 0);
  // Wedge (r=1, c=2): pixels (1,2), (1,3), (2,2), (2,3).
  const Wedge& w = out.wedges[1 * 3 + 2];
  const float expect[4][2] = {{0.2f, -0.1f}, {0.3f, -0.1f}, {0.2f, -0.2f}, {0.3f, -0.2f}};
  for (int k = 0; k < 4; ++k) {
    EXPECT_NEAR((w.rays[k].point_mean - Vector3f(kWallX, expect[k][0], expect[k][1])).norm(), 0,
                1e-6);
  }

  // Pixels (0,1) and (1,0) without returns: wedges (0,0), (0,1), (1,0) go, and pixels (0,0)
  // and (2,0), which only those wedges held, are carved alone, each after the wedges of its
  // row: wedge (0,2), pixel (0,0), wedges (1,1) and (1,2), pixel (2,0).
  out.wedges.clear();
  ScanFrame f = GridFrame(3, 4);
  f.row = 1;
  f.points_sensor[1] = f.points_sensor[4] = Vector3f(kNaN, kNaN, kNaN);
  ASSERT_TRUE(b->AddFrame(f, FrameContext{}).ok());
  EXPECT_EQ(out.Count(4), 3);
  ASSERT_EQ(out.Count(1), 2);
  EXPECT_EQ(out.wedges[1].num_rays, 1);
  EXPECT_NEAR((out.wedges[1].rays[0].point_mean - Vector3f(kWallX, 0, 0)).norm(), 0, 1e-6);
  EXPECT_EQ(out.wedges[4].num_rays, 1);
  EXPECT_NEAR((out.wedges[4].rays[0].point_mean - Vector3f(kWallX, 0, -0.2f)).norm(), 0, 1e-6);

  // A frame of the wrong size.
  f.row = 2;
  f.points_sensor.pop_back();
  EXPECT_EQ(b->AddFrame(f, FrameContext{}).code(), absl::StatusCode::kInvalidArgument);
}

TEST(WedgeBuilderTest, PointsAreCarvedOneByOne) {
  SensorInfo s;
  s.name = "cloud";
  s.kind = SensorKind::kPoints;
  Collected out;
  absl::StatusOr<WedgeBuilder> b = WedgeBuilder::Create({s}, WedgeBuilderOptions{}, out.Sink());
  ASSERT_TRUE(b.ok());
  ScanFrame f;
  f.sensor = 0;
  f.points_sensor = {Vector3f(1, 0, 0), Vector3f(kNaN, kNaN, kNaN), Vector3f(0, 2, 0),
                     Vector3f(0, 0, 0.001f), Vector3f(0, 0, 3)};
  ASSERT_TRUE(b->AddFrame(f, FrameContext{}).ok());
  ASSERT_EQ(out.wedges.size(), 3u);  // the NaN row and the return at the sensor carve nothing
  for (const Wedge& w : out.wedges) {
    EXPECT_EQ(w.num_rays, 1);
    EXPECT_EQ(w.rays[3].point_mean, w.rays[0].point_mean);
  }
  EXPECT_EQ(b->stats().rays_without_return, 2u);
}

TEST(WedgeBuilderTest, SinkErrorsStopTheBuilder) {
  absl::StatusOr<WedgeBuilder> b =
      WedgeBuilder::Create({VerticalLineSensor()}, WedgeBuilderOptions{},
                           [](const Wedge&, std::span<const RayId>) {
                             return absl::ResourceExhaustedError("disk full");
                           });
  ASSERT_TRUE(b.ok());
  ASSERT_TRUE(b->AddFrame(WallFrame(0, 3), WalkContext(0)).ok());  // nothing emitted yet
  EXPECT_EQ(b->AddFrame(WallFrame(1, 3), WalkContext(1)).code(),
            absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(WedgeBuilder::Create({}, WedgeBuilderOptions{}, nullptr).status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(WedgeBuilderTest, FrameContextFromPath) {
  std::vector<TimedPose> path = {
      {0.0, Pose{Eigen::Quaterniond::Identity(), Vector3d(0, 0, 0)}},
      {1.0, Pose{Eigen::Quaterniond(Eigen::AngleAxisd(0.5, Vector3d::UnitZ())), Vector3d(2, 0, 0)}}};
  absl::StatusOr<FrameContext> c = FrameContextAt(path, {}, 0.5, NoiseModelOptions{});
  ASSERT_TRUE(c.ok());
  EXPECT_NEAR((c->pose_world_sys.translation - Vector3d(1, 0, 0)).norm(), 0, 1e-12);
  EXPECT_NEAR((c->omega_world - Vector3d(0, 0, 0.5)).norm(), 0, 1e-12);
  EXPECT_NEAR(c->covariance.position(0, 0), 0.05 * 0.05, 1e-15);
  EXPECT_FALSE(FrameContextAt({}, {}, 0.5, NoiseModelOptions{}).ok());
}

// A tiny scan.h5 through ScanWriter and ScanReader: a line sensor with 4 frames of 5 rays (one
// NaN in the middle of frame 1) and a points sensor with 3 rays (one NaN).
std::string WriteTinyScan(bool with_cov) {
  const std::string path =
      ::testing::TempDir() + (with_cov ? "/wedge_builder_cov.h5" : "/wedge_builder_nocov.h5");
  absl::StatusOr<std::unique_ptr<ScanWriter>> w = ScanWriter::Create(path);
  EXPECT_TRUE(w.ok()) << w.status();
  std::vector<PathRecord> poses;
  std::vector<PathCovariance> cov;
  for (int i = 0; i <= 10; ++i) {
    poses.push_back(PathRecord{0.01 * i, 0, 0.02 * i, 1.0, 1, 0, 0, 0});
    PathCovariance c{};
    c[0] = c[3] = c[5] = 1e-4f;
    c[6] = c[9] = c[11] = 1e-6f;
    cov.push_back(c);
  }
  EXPECT_TRUE((*w)->AppendPath(poses, with_cov ? std::span<const PathCovariance>(cov)
                                               : std::span<const PathCovariance>())
                  .ok());
  absl::StatusOr<int> line = (*w)->AddSensor(VerticalLineSensor());
  SensorInfo pts;
  pts.name = "cloud";
  pts.kind = SensorKind::kPoints;
  absl::StatusOr<int> cloud = (*w)->AddSensor(pts);
  EXPECT_TRUE(line.ok() && cloud.ok());
  for (int i = 0; i < 4; ++i) {
    ScanFrame f = WallFrame(i, 5);
    if (i == 1) f.points_sensor[2] = Vector3f(kNaN, kNaN, kNaN);
    EXPECT_TRUE((*w)->AppendFrame(*line, 0.02 * i + 0.005, f.points_sensor).ok());
  }
  const std::vector<Vector3f> cloud_points = {Vector3f(1, 1, 0), Vector3f(kNaN, kNaN, kNaN),
                                              Vector3f(2, 0, 1)};
  EXPECT_TRUE((*w)->AppendFrame(*cloud, 0.03, cloud_points).ok());
  EXPECT_TRUE((*w)->Close().ok());
  return path;
}

TEST(WedgeBuilderTest, TinyScanFileThroughTheReader) {
  for (bool with_cov : {true, false}) {
    const std::string file = WriteTinyScan(with_cov);
    absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(file);
    ASSERT_TRUE(reader.ok()) << reader.status();
    ASSERT_TRUE((*reader)->Validate().ok());
    Collected out;
    absl::StatusOr<WedgeBuilderStats> stats =
        BuildWedges(**reader, WedgeBuilderOptions{}, out.Sink());
    ASSERT_TRUE(stats.ok()) << stats.status();
    // Line: 4·3 ray-pair × frame-pair wedges minus the 2·2 touching the NaN; ray 2 of the
    // first frame was only in those, so it is carved alone. Points: two returns.
    EXPECT_EQ(stats->wedges, 4u * 3 - 4);
    EXPECT_EQ(stats->single_ray_wedges, 1u + 2);
    EXPECT_EQ(out.wedges.size(), 4u * 3 - 4 + 3);
    EXPECT_EQ(stats->rays, 4u * 5 + 3);
    EXPECT_EQ(stats->rays_without_return, 2u);
    EXPECT_EQ(stats->default_covariance, !with_cov);
    // The system stands 1 m up: sensors at z = 1 and wall points at their heights + 1.
    for (const Wedge& w : out.wedges) {
      EXPECT_NEAR(w.rays[0].sensor_mean.z(), 1.0, 1e-5);
    }
  }
}

}  // namespace
}  // namespace carvemap

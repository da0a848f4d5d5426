#include "storage/wedge_codec.h"

#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace carvemap {
namespace {

using ::testing::HasSubstr;

Wedge RandomWedge(std::mt19937_64& rng, int num_rays) {
  std::normal_distribution<float> n(0, 20);
  Wedge w;
  w.num_rays = uint8_t(num_rays);
  for (int r = 0; r < 4; ++r) {
    RayModel& ray = w.rays[r];
    if (r >= num_rays) {
      ray = RayModel{Eigen::Vector3f::Zero(), Eigen::Vector3f::Zero(), {}, {}};
      continue;
    }
    ray.sensor_mean = Eigen::Vector3f(n(rng), n(rng), n(rng));
    ray.point_mean = Eigen::Vector3f(n(rng), n(rng), n(rng));
    for (float& v : ray.sensor_cov) v = n(rng) * 1e-4f;
    for (float& v : ray.point_cov) v = n(rng) * 1e-3f;
  }
  return w;
}

bool SameWedge(const Wedge& a, const Wedge& b) {
  if (a.num_rays != b.num_rays) return false;
  for (int r = 0; r < a.num_rays; ++r) {
    const RayModel &x = a.rays[r], &y = b.rays[r];
    if (x.sensor_mean != y.sensor_mean || x.point_mean != y.point_mean ||
        x.sensor_cov != y.sensor_cov || x.point_cov != y.point_cov) {
      return false;
    }
  }
  return true;
}

TEST(WedgeCodecTest, RoundTrip) {
  std::mt19937_64 rng(1);
  std::vector<Wedge> wedges;
  for (int i = 0; i < 1000; ++i) wedges.push_back(RandomWedge(rng, 1 + i % 4));
  const std::string bytes = EncodeWedges(wedges);
  // Nothing shared: a frame record and a ray record per ray, and the wedge records.
  size_t rays = 0;
  for (const Wedge& w : wedges) rays += w.num_rays;
  EXPECT_GT(bytes.size(), 2 + rays * (kFrameRecordBytes + kRayRecordBytes));
  EXPECT_LT(bytes.size(), 2 + rays * (kFrameRecordBytes + kRayRecordBytes + 5) + wedges.size());
  auto decoded = DecodeWedges(bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  ASSERT_EQ(decoded->size(), wedges.size());
  for (size_t i = 0; i < wedges.size(); ++i) {
    EXPECT_TRUE(SameWedge((*decoded)[i], wedges[i])) << i;
    EXPECT_EQ((*decoded)[i].rays[3].point_mean, wedges[i].rays[3].point_mean);  // zero padding
  }
  EXPECT_EQ(EncodeWedges(*decoded), bytes);
  EXPECT_EQ(*CountWedgeRecords(bytes), wedges.size());
  EXPECT_TRUE(DecodeWedges("")->empty());
}

// A line sensor's frame pairs, as the wedge builder emits them: wedge j of pair (i, i+1) joins
// rays j, j+1 of frames i and i+1; every inner ray belongs to four wedges.
struct Strip {
  std::vector<std::vector<RayModel>> frames;
  std::vector<std::pair<Wedge, std::array<RayId, 4>>> wedges;
};
Strip LineScan(int num_frames, int beams) {
  Strip s;
  for (int f = 0; f < num_frames; ++f) {
    std::vector<RayModel> frame;
    const Eigen::Vector3f sensor(0.05f * f, 0, 1.5f);
    for (int j = 0; j < beams; ++j) {
      const float a = 0.02f * j;
      frame.push_back(RayModel{sensor, sensor + Eigen::Vector3f(3, std::cos(a), std::sin(a)),
                               {1e-4f, 0, 0, 1e-4f, 0, 1e-4f},
                               {1e-3f * j, 0, 0, 1e-3f, 0, 1e-3f * f}});
    }
    s.frames.push_back(frame);
  }
  for (int f = 0; f + 1 < num_frames; ++f) {
    for (int j = 0; j + 1 < beams; ++j) {
      Wedge w;
      w.rays = {s.frames[f][j], s.frames[f][j + 1], s.frames[f + 1][j], s.frames[f + 1][j + 1]};
      w.num_rays = 4;
      std::array<RayId, 4> ids = {RayId{7, uint64_t(f), uint32_t(j)},
                                  RayId{7, uint64_t(f), uint32_t(j + 1)},
                                  RayId{7, uint64_t(f + 1), uint32_t(j)},
                                  RayId{7, uint64_t(f + 1), uint32_t(j + 1)}};
      s.wedges.emplace_back(w, ids);
    }
  }
  return s;
}

TEST(WedgeCodecTest, SharedRaysAndFramesAreWrittenOnce) {
  const Strip scan = LineScan(6, 40);
  WedgePayloadWriter writer;
  std::string bytes;
  for (const auto& [w, ids] : scan.wedges) writer.Add(w, ids, bytes);
  writer.Finish(bytes);
  EXPECT_EQ(writer.wedges(), scan.wedges.size());
  auto decoded = DecodeWedgePayload(bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_EQ(decoded->rays.size(), 6u * 40u);
  ASSERT_EQ(decoded->wedges.size(), scan.wedges.size());
  // Header, 6 frames, 240 rays, 5·39 wedges of a tag, four 1-byte back-references and a
  // 1-byte hull hint (none), and the end record (tag, 195 as a 2-byte varint).
  EXPECT_EQ(bytes.size(), 2 + 6 * kFrameRecordBytes + 240 * kRayRecordBytes + 195 * 6 + 3);
  for (size_t w = 0; w < scan.wedges.size(); ++w) {
    const WedgeRef& ref = decoded->wedges[w];
    ASSERT_EQ(ref.num_rays, 4);
    for (int r = 0; r < 4; ++r) {
      const RayModel& got = decoded->rays[ref.ray[r]];
      const RayModel& want = scan.wedges[w].first.rays[r];
      EXPECT_EQ(got.sensor_mean, want.sensor_mean);
      EXPECT_EQ(got.point_mean, want.point_mean);
      EXPECT_EQ(got.sensor_cov, want.sensor_cov);
      EXPECT_EQ(got.point_cov, want.point_cov);
    }
  }
  // The same wedges without ids share by bit identity: the same rays, once each.
  std::vector<Wedge> plain;
  for (const auto& [w, ids] : scan.wedges) plain.push_back(w);
  EXPECT_EQ(DecodeWedgePayload(EncodeWedges(plain))->rays.size(), 240u);
}

TEST(WedgeCodecTest, HullHintsRoundTrip) {
  const Strip scan = LineScan(2, 4);
  WedgePayloadWriter writer;
  std::string bytes;
  const uint64_t hints[3] = {0, 0x9a5c3, uint64_t{1} << 55};
  for (int w = 0; w < 3; ++w) writer.Add(scan.wedges[w].first, scan.wedges[w].second, bytes, hints[w]);
  writer.Finish(bytes);
  auto decoded = DecodeWedgePayload(bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  for (int w = 0; w < 3; ++w) EXPECT_EQ(decoded->wedges[w].facets, hints[w]);
}

TEST(WedgeCodecTest, OnlyTheLastTwoFramesOfASensorAreRemembered) {
  const Strip scan = LineScan(4, 3);
  WedgePayloadWriter writer;
  std::string bytes;
  writer.Add(scan.wedges[0].first, scan.wedges[0].second, bytes);  // frames 0, 1
  writer.Add(scan.wedges[4].first, scan.wedges[4].second, bytes);  // frames 2, 3: 0, 1 dropped
  writer.Add(scan.wedges[0].first, scan.wedges[0].second, bytes);  // written again
  writer.Finish(bytes);
  auto decoded = DecodeWedgePayload(bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_EQ(decoded->rays.size(), 12u);
  EXPECT_EQ(decoded->wedges[0].ray, (std::array<uint32_t, 4>{0, 1, 2, 3}));
  EXPECT_EQ(decoded->wedges[2].ray, (std::array<uint32_t, 4>{8, 9, 10, 11}));
}

TEST(WedgeCodecTest, LittleEndianLayout) {
  Wedge w;
  w.num_rays = 1;
  w.rays[0] = RayModel{Eigen::Vector3f(1.0f, -2.0f, 0.5f), Eigen::Vector3f(3, 4, 5),
                       {1e-4f, 0, 0, 1e-4f, 0, 1e-4f}, {0.01f, 0.001f, 0, 0.02f, 0, 0.03f}};
  const std::string b = EncodeWedges({&w, 1});
  ASSERT_EQ(b.size(), 2 + kFrameRecordBytes + kRayRecordBytes + 2 + 2);
  EXPECT_EQ(b.substr(0, 2), std::string("\xc7\x02", 2));  // magic, version
  EXPECT_EQ(b[2], 0x01);                                  // frame record
  // 1.0f = 0x3f800000, little-endian; −2.0f = 0xc0000000.
  EXPECT_EQ(b.substr(3, 4), std::string("\x00\x00\x80\x3f", 4));
  EXPECT_EQ(b.substr(7, 4), std::string("\x00\x00\x00\xc0", 4));
  const size_t ray = 2 + kFrameRecordBytes;
  EXPECT_EQ(b[ray], 0x02);      // ray record
  EXPECT_EQ(b[ray + 1], 0x00);  // of the latest frame
  float v;
  std::memcpy(&v, b.data() + ray + 2, 4);  // point_mean.x
  EXPECT_EQ(v, 3.0f);
  std::memcpy(&v, b.data() + ray + 14 + 4, 4);  // point_cov[1]
  EXPECT_EQ(v, 0.001f);
  EXPECT_EQ(b.substr(ray + kRayRecordBytes), std::string("\x11\x00\x7f\x01", 4));  // wedge, end
}

TEST(WedgeCodecTest, Validate) {
  std::mt19937_64 rng(2);
  Wedge w = RandomWedge(rng, 4);
  EXPECT_TRUE(ValidateWedge(w).ok());
  w.num_rays = 0;
  EXPECT_THAT(ValidateWedge(w).message(), HasSubstr("num_rays 0"));
  w.num_rays = 5;
  EXPECT_EQ(ValidateWedge(w).code(), absl::StatusCode::kInvalidArgument);
  w.num_rays = 4;
  w.rays[2].point_cov[3] = std::numeric_limits<float>::infinity();
  EXPECT_THAT(ValidateWedge(w).message(), HasSubstr("ray 2 has a non-finite point_cov"));
  w.num_rays = 2;  // unused rays are not checked
  EXPECT_TRUE(ValidateWedge(w).ok());
}

TEST(WedgeCodecTest, ClearErrors) {
  std::mt19937_64 rng(3);
  std::vector<Wedge> wedges = {RandomWedge(rng, 4), RandomWedge(rng, 1), RandomWedge(rng, 4)};
  const std::string good = EncodeWedges(wedges);
  // Records: frame, ray × 4, wedge (records 0–8 for wedge 0), then wedge 1's frame at 10.
  const size_t wedge0 = 2 + 4 * (kFrameRecordBytes + kRayRecordBytes);

  auto truncated = DecodeWedges(std::string_view(good).substr(0, good.size() - 10));
  EXPECT_EQ(truncated.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(truncated.status().message(), HasSubstr("ray record is truncated"));
  EXPECT_EQ(CountWedgeRecords(std::string_view(good).substr(0, good.size() - 10)).status().code(),
            absl::StatusCode::kDataLoss);
  // Cut at a record boundary: the end record is missing, or counts more wedges than remain.
  for (size_t cut : {size_t{2}, size_t{6}}) {
    auto r = DecodeWedges(std::string_view(good).substr(0, good.size() - cut));
    EXPECT_EQ(r.status().code(), absl::StatusCode::kDataLoss) << cut;
  }
  EXPECT_THAT(DecodeWedges(std::string_view(good).substr(0, good.size() - 2)).status().message(),
              HasSubstr("no end record (truncated)"));
  EXPECT_THAT(DecodeWedges(good + std::string("\x11\x00", 2)).status().message(),
              HasSubstr("bytes after the end record"));

  std::string bad = good;
  bad[wedge0] = 0x17;
  EXPECT_THAT(DecodeWedges(bad).status().message(),
              HasSubstr("record 8 at byte " + std::to_string(wedge0) + ": unknown record tag 0x17"));
  bad = good;
  bad[wedge0 + 1] = 9;  // 9 rays back from the 4th
  EXPECT_THAT(DecodeWedges(bad).status().message(),
              HasSubstr("refers 9 rays back, but only 4 rays precede it"));
  bad = good;
  bad[2 + kFrameRecordBytes + 1] = 1;  // ray 0 of frame −1
  EXPECT_THAT(DecodeWedges(bad).status().message(), HasSubstr("only 1 frames precede it"));

  bad = good;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(bad.data() + 2 + kFrameRecordBytes + 2 + 4, &nan, 4);  // ray 0 point_mean.y
  EXPECT_THAT(DecodeWedges(bad).status().message(),
              HasSubstr("record 1 at byte 39: non-finite point_mean"));
  EXPECT_EQ(*CountWedgeRecords(bad), 3u);  // values are not checked by the count

  // Other formats and versions are named.
  std::string v1(289, '\0');
  v1[0] = 4;
  EXPECT_THAT(DecodeWedges(v1).status().message(), HasSubstr("version 1"));
  bad = good;
  bad[1] = 3;
  EXPECT_THAT(DecodeWedges(bad).status().message(),
              HasSubstr("wedge payload version 3; this build reads version 2"));
  bad[0] = 'x';
  EXPECT_THAT(DecodeWedges(bad).status().message(), HasSubstr("not a wedge payload"));
}

}  // namespace
}  // namespace carvemap

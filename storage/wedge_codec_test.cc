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
  size_t expected = 0;
  for (const Wedge& w : wedges) expected += WedgeRecordBytes(w.num_rays);
  EXPECT_EQ(bytes.size(), expected);
  auto decoded = DecodeWedges(bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  ASSERT_EQ(decoded->size(), wedges.size());
  for (size_t i = 0; i < wedges.size(); ++i) {
    EXPECT_TRUE(SameWedge((*decoded)[i], wedges[i])) << i;
    EXPECT_EQ((*decoded)[i].rays[3].point_mean, wedges[i].rays[3].point_mean);  // zero padding
  }
  EXPECT_EQ(EncodeWedges(*decoded), bytes);
  EXPECT_TRUE(DecodeWedges("")->empty());
}

TEST(WedgeCodecTest, SizesAndLittleEndianLayout) {
  EXPECT_EQ(WedgeRecordBytes(1), 73u);
  EXPECT_EQ(WedgeRecordBytes(4), 289u);
  Wedge w;
  w.num_rays = 1;
  w.rays[0] = RayModel{Eigen::Vector3f(1.0f, -2.0f, 0.5f), Eigen::Vector3f(3, 4, 5),
                       {1e-4f, 0, 0, 1e-4f, 0, 1e-4f}, {0.01f, 0.001f, 0, 0.02f, 0, 0.03f}};
  const std::string b = EncodeWedges({&w, 1});
  ASSERT_EQ(b.size(), 73u);
  EXPECT_EQ(b[0], 1);
  // 1.0f = 0x3f800000, little-endian; −2.0f = 0xc0000000.
  EXPECT_EQ(b.substr(1, 4), std::string("\x00\x00\x80\x3f", 4));
  EXPECT_EQ(b.substr(5, 4), std::string("\x00\x00\x00\xc0", 4));
  // point_mean.x at byte 13, point_cov[1] at byte 1 + 4·13 = 53.
  float v;
  std::memcpy(&v, b.data() + 13, 4);
  EXPECT_EQ(v, 3.0f);
  std::memcpy(&v, b.data() + 53, 4);
  EXPECT_EQ(v, 0.001f);
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
  ASSERT_EQ(good.size(), 289u + 73u + 289u);

  auto truncated = DecodeWedges(std::string_view(good).substr(0, good.size() - 10));
  EXPECT_EQ(truncated.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(truncated.status().message(), HasSubstr("record 2 at byte 362 is truncated"));

  std::string bad = good;
  bad[289] = 7;
  auto bad_rays = DecodeWedges(bad);
  EXPECT_EQ(bad_rays.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(bad_rays.status().message(), HasSubstr("record 1 at byte 289: num_rays 7"));
  bad[289] = 0;
  EXPECT_THAT(DecodeWedges(bad).status().message(), HasSubstr("num_rays 0"));

  bad = good;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(bad.data() + 1 + 4 * 4, &nan, 4);  // record 0, ray 0, point_mean.y
  EXPECT_THAT(DecodeWedges(bad).status().message(),
              HasSubstr("record 0 at byte 0: ray 0 has a non-finite point_mean"));
}

}  // namespace
}  // namespace carvemap

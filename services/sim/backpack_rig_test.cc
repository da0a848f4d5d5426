#include "services/sim/backpack_rig.h"

#include <cmath>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180;

TEST(BackpackRig, HokuyoDefaults) {
  const std::vector<LineScanner> rig = MakeBackpackRig(RigOptions{});
  ASSERT_EQ(rig.size(), 3u);
  for (const LineScanner& s : rig) {
    EXPECT_EQ(s.beams_sensor.size(), 1081u) << s.name;
    EXPECT_DOUBLE_EQ(s.rate_hz, 40.0);
    EXPECT_DOUBLE_EQ(s.max_range_m, 30.0);
    // Beam convention: a = -135° + j·0.25°, direction (cos a, sin a, 0).
    EXPECT_NEAR(s.beams_sensor.front().x(), std::cos(-135 * kDeg), 1e-6);
    EXPECT_NEAR(s.beams_sensor.front().y(), std::sin(-135 * kDeg), 1e-6);
    EXPECT_NEAR(s.beams_sensor[540].x(), 1.0, 1e-6);
    EXPECT_NEAR(s.beams_sensor.back().y(), std::sin(135 * kDeg), 1e-6);
    for (const auto& d : s.beams_sensor) EXPECT_NEAR(d.norm(), 1.0f, 1e-6f);
    const double lever = s.T_system_sensor.translation.norm();
    EXPECT_GE(lever, 0.1);
    EXPECT_LE(lever, 0.3);
    EXPECT_NEAR(s.T_system_sensor.rotation.norm(), 1.0, 1e-12);
    EXPECT_GE(s.phase_s, 0);
    EXPECT_LT(s.phase_s, 1 / s.rate_hz);
  }
  // Level scanner: its scan plane normal (sensor z) is vertical and mid-sweep looks forward.
  const Eigen::Vector3d n0 = rig[0].T_system_sensor.rotation * Eigen::Vector3d::UnitZ();
  EXPECT_NEAR(std::abs(n0.z()), 1.0, 1e-12);
  EXPECT_NEAR((rig[0].T_system_sensor.rotation * Eigen::Vector3d::UnitX()).x(), 1.0, 1e-12);
  // Tilted scanners: near-vertical planes (normal horizontal), yawed ±25° from across.
  for (int k : {1, 2}) {
    const Eigen::Vector3d n = rig[k].T_system_sensor.rotation * Eigen::Vector3d::UnitZ();
    EXPECT_NEAR(n.z(), 0.0, 1e-12);
    EXPECT_NEAR(std::abs(n.x()), std::cos(25 * kDeg), 1e-9);
    // Mid-sweep up, blind wedge down into the operator.
    EXPECT_NEAR((rig[k].T_system_sensor.rotation * Eigen::Vector3d::UnitX()).z(), 1.0, 1e-12);
  }
  const Eigen::Vector3d nl = rig[1].T_system_sensor.rotation * Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d nr = rig[2].T_system_sensor.rotation * Eigen::Vector3d::UnitZ();
  EXPECT_GT(std::abs(nl.normalized().dot(nr.normalized())), 0.5);
  EXPECT_LT(std::abs(nl.normalized().dot(nr.normalized())), 0.99);  // not parallel planes
}

TEST(BackpackRig, Thinned) {
  RigOptions o;
  o.rate_hz = 10;
  o.beam_step_deg = 1;
  const auto rig = MakeBackpackRig(o);
  EXPECT_EQ(rig[0].beams_sensor.size(), 271u);
  EXPECT_DOUBLE_EQ(rig[1].rate_hz, 10);
  o.beam_step_deg = 0;
  EXPECT_FALSE(o.Validate().ok());
}

}  // namespace
}  // namespace carvemap

// Test support for the wall-sample stages checked against a simulated building's truth
// (gt/building.json, services/building/truth_writer.h): the true rooms of a level, and the true
// wall nearest a sample. Point-in-ring is building.h's RingContains.
#pragma once

#include <algorithm>
#include <cstddef>
#include <limits>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

namespace carvemap::testing {

// Distance from p to the segment a–b.
inline double SegmentDistance(const Eigen::Vector2d& p, const Eigen::Vector2d& a,
                              const Eigen::Vector2d& b) {
  const Eigen::Vector2d ab = b - a;
  const double l2 = ab.squaredNorm();
  const double t = l2 > 0 ? std::clamp((p - a).dot(ab) / l2, 0.0, 1.0) : 0.0;
  return (a + t * ab - p).norm();
}

struct TruthRoom {
  std::vector<std::vector<Eigen::Vector2d>> rings;  // polygon, then holes
  double floor_z = 0, ceiling_z = 0;
};

// The rooms of `level` in building.json's "rooms".
inline std::vector<TruthRoom> TruthRoomsOfLevel(const nlohmann::json& truth, int level) {
  auto read_ring = [](const nlohmann::json& j) {
    std::vector<Eigen::Vector2d> ring;
    for (const auto& p : j) ring.emplace_back(p.at(0).get<double>(), p.at(1).get<double>());
    return ring;
  };
  std::vector<TruthRoom> rooms;
  for (const auto& r : truth.at("rooms")) {
    if (r.at("level").get<int>() != level) continue;
    TruthRoom t;
    t.rings.push_back(read_ring(r.at("polygon")));
    for (const auto& h : r.at("holes")) t.rings.push_back(read_ring(h));
    t.floor_z = r.at("floor_z").get<double>();
    t.ceiling_z = r.at("ceiling_z").get<double>();
    rooms.push_back(std::move(t));
  }
  return rooms;
}

// The edge of a room ring (outer or hole) nearest p: its distance and unit direction (the
// first of equally near edges; +x when there is none).
struct NearestWall {
  double distance_m = std::numeric_limits<double>::infinity();
  Eigen::Vector2d direction = Eigen::Vector2d::UnitX();
};
inline NearestWall NearestTrueWall(const std::vector<TruthRoom>& rooms, const Eigen::Vector2d& p) {
  NearestWall out;
  for (const TruthRoom& r : rooms) {
    for (const auto& ring : r.rings) {
      for (size_t i = 0; i < ring.size(); ++i) {
        const Eigen::Vector2d &a = ring[i], &b = ring[(i + 1) % ring.size()];
        const double d = SegmentDistance(p, a, b);
        if (d < out.distance_m) {
          out.distance_m = d;
          out.direction = (b - a).normalized();
        }
      }
    }
  }
  return out;
}

}  // namespace carvemap::testing

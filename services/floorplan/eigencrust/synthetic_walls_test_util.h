// Test support: synthetic wall samples with normals and visibility. Wall faces are 2D segments
// with the room on their left, sampled every d_s = 5 cm with ±noise and the face's normal
// (towards the room); the path is a polyline sampled every 0.25 m; a pose sees a sample when the
// segment between them crosses no other face and the sample's face looks towards it.
#pragma once

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "services/floorplan/wall_samples.h"

namespace carvemap::testing {

using Eigen::Vector2d;

inline constexpr double kSpacing = 0.05;

struct Face {
  Vector2d a, b;  // the room is on the left of a → b
};

inline bool Crosses(const Vector2d& p, const Vector2d& q, const Vector2d& a, const Vector2d& b) {
  auto cross = [](const Vector2d& u, const Vector2d& v, const Vector2d& w) {
    return (v - u).x() * (w - u).y() - (v - u).y() * (w - u).x();
  };
  const double d1 = cross(p, q, a), d2 = cross(p, q, b), d3 = cross(a, b, p), d4 = cross(a, b, q);
  return ((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0));
}

struct Scene {
  std::vector<Face> faces;
  std::vector<Vector2d> path;  // polyline, sampled every 0.25 m
  double noise_m = 0.002;
};

inline WallSampleSet MakeSamples(const Scene& scene, uint32_t seed = 3) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> noise(-scene.noise_m, scene.noise_m);
  WallSampleSet set;
  set.spacing_m = kSpacing;
  std::vector<int> owner;
  for (size_t f = 0; f < scene.faces.size(); ++f) {
    const Face& face = scene.faces[f];
    const Vector2d d = face.b - face.a;
    const int n = static_cast<int>(std::ceil(d.norm() / kSpacing - 1e-9));
    for (int k = 0; k < n; ++k) {
      WallSample s;
      s.position = face.a + d * ((k + 0.5) / n) + Vector2d(noise(rng), noise(rng));
      s.normal = Vector2d(-d.y(), d.x()).normalized();
      s.floor_z = 0;
      s.ceiling_z = 2.5;
      set.samples.push_back(s);
      owner.push_back(static_cast<int>(f));
    }
  }
  for (size_t i = 1; i < scene.path.size(); ++i) {
    const Vector2d d = scene.path[i] - scene.path[i - 1];
    const int n = std::max(1, static_cast<int>(d.norm() / 0.25));
    for (int k = (i == 1 ? 0 : 1); k <= n; ++k) set.poses.push_back(scene.path[i - 1] + d * k / n);
  }
  for (size_t i = 0; i < set.samples.size(); ++i) {
    const WallSample& s = set.samples[i];
    for (size_t j = 0; j < set.poses.size(); ++j) {
      const Vector2d& q = set.poses[j];
      if ((q - s.position).dot(s.normal) <= 0) continue;
      bool blocked = false;
      for (size_t f = 0; f < scene.faces.size() && !blocked; ++f) {
        if (static_cast<int>(f) != owner[i]) {
          blocked = Crosses(q, s.position, scene.faces[f].a, scene.faces[f].b);
        }
      }
      if (!blocked) set.samples[i].poses.push_back(static_cast<uint32_t>(j));
    }
  }
  return set;
}

// A room's faces, counter-clockwise (room inside).
inline void AddRoom(std::vector<Face>& faces, double x0, double y0, double x1, double y1) {
  faces.push_back({{x0, y0}, {x1, y0}});
  faces.push_back({{x1, y0}, {x1, y1}});
  faces.push_back({{x1, y1}, {x0, y1}});
  faces.push_back({{x0, y1}, {x0, y0}});
}

// Two 5 × 4 m rooms, A = [0, 5] × [0, 4] and B = [5.15, 10.15] × [0, 4], with a 0.15 m wall
// between them and a 0.9 m door (y ∈ [1.5, 2.4]); the path walks through both.
inline Scene TwoRoomsWithDoor() {
  Scene scene;
  const double w0 = 5.0, w1 = 5.15;
  const double d0 = 1.5, d1 = 2.4;
  auto& f = scene.faces;
  f.push_back({{0, 0}, {w0, 0}});
  f.push_back({{w0, 0}, {w0, d0}});
  f.push_back({{w0, d1}, {w0, 4}});
  f.push_back({{w0, 4}, {0, 4}});
  f.push_back({{0, 4}, {0, 0}});
  f.push_back({{w1, 0}, {10.15, 0}});
  f.push_back({{10.15, 0}, {10.15, 4}});
  f.push_back({{10.15, 4}, {w1, 4}});
  f.push_back({{w1, 4}, {w1, d1}});
  f.push_back({{w1, d0}, {w1, 0}});
  f.push_back({{w0, d0}, {w1, d0}});  // the door's jambs
  f.push_back({{w1, d1}, {w0, d1}});
  scene.path = {{1, 1}, {4, 1}, {4, 2}, {6, 2}, {9, 2}, {9, 3}, {6, 3}};
  return scene;
}

}  // namespace carvemap::testing

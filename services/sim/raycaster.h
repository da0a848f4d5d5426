// Ray casting against a building's truth meshes with Embree (docs/DESIGN.md §4): the simulator's
// scanners, and closest-point distances for tests. Geometry 0 is the structure (walls,
// floors, ceilings, stairs), geometry 1 the objects (furniture, fixtures).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "storage/ply_io.h"

namespace carvemap {

// A ray in the world frame. `direction` must be unit length; hits beyond max_range_m miss.
struct RayQuery {
  Eigen::Vector3f origin = Eigen::Vector3f::Zero();
  Eigen::Vector3f direction = Eigen::Vector3f::UnitX();
  float max_range_m = 30.0f;
};

inline constexpr int kHitStructure = 0;
inline constexpr int kHitObject = 1;

struct RayHitResult {
  float distance_m = 0;  // along the ray; +inf when it missed
  int geometry = -1;     // kHitStructure, kHitObject, or -1 (miss)
  int primitive = -1;    // triangle index within that geometry's mesh
  [[nodiscard]] bool hit() const { return geometry >= 0; }
};

// How Cast() hands rays to Embree; all give the same hits. The bench measures them.
// rtcIntersect16 measured fastest (tests/bench/raycast_bench: office, 1 core: 32 M rays/s vs
// 29 M for rtcIntersect1M and 8 M for the rtcIntersect1 loop), so it is the default.
enum class CastMode {
  kSingle,  // a loop of rtcIntersect1 with the coherent-context flag
  kStream,  // rtcIntersect1M over blocks of 256 rays
  kPacket,  // rtcIntersect16 packets
};

struct ClosestPoint {
  float distance_m = 0;
  Eigen::Vector3f point = Eigen::Vector3f::Zero();
  int geometry = -1;
  int primitive = -1;
};

// Thread-safe after Create(): Cast() and Closest() may run concurrently.
class RayCaster {
 public:
  // Builds the BVH. `objects` may be empty. Fails on indices out of range or an Embree error.
  static absl::StatusOr<std::unique_ptr<RayCaster>> Create(const TriangleMesh& structure,
                                                           const TriangleMesh& objects);
  ~RayCaster();
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  // REQUIRES: hits.size() == rays.size().
  void Cast(std::span<const RayQuery> rays, std::span<RayHitResult> hits,
            CastMode mode = CastMode::kPacket) const;
  [[nodiscard]] RayHitResult Cast(const RayQuery& ray) const;

  // The closest point of either mesh to `p` (Embree point query; exact triangle distance).
  // distance_m is +inf if both meshes are empty.
  [[nodiscard]] ClosestPoint Closest(const Eigen::Vector3f& p) const;

  [[nodiscard]] size_t triangle_count() const;

 private:
  struct Impl;
  explicit RayCaster(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Closest point on triangle (a, b, c) to p (Ericson, Real-Time Collision Detection §5.1.5).
[[nodiscard]] Eigen::Vector3f ClosestPointOnTriangle(const Eigen::Vector3f& p,
                                                     const Eigen::Vector3f& a,
                                                     const Eigen::Vector3f& b,
                                                     const Eigen::Vector3f& c);

}  // namespace carvemap

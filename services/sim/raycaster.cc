#include "services/sim/raycaster.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>
#include <limits>

#include <embree3/rtcore.h>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

absl::Status EmbreeStatus(RTCDevice device, const char* what) {
  const RTCError err = rtcGetDeviceError(device);
  if (err == RTC_ERROR_NONE) return absl::OkStatus();
  return absl::InternalError(absl::StrCat("raycaster: embree error ", static_cast<int>(err),
                                          " in ", what));
}

void FillRay(const RayQuery& q, RTCRayHit& rh) {
  rh.ray.org_x = q.origin.x();
  rh.ray.org_y = q.origin.y();
  rh.ray.org_z = q.origin.z();
  rh.ray.dir_x = q.direction.x();
  rh.ray.dir_y = q.direction.y();
  rh.ray.dir_z = q.direction.z();
  rh.ray.tnear = 0.0f;
  rh.ray.tfar = q.max_range_m;
  rh.ray.time = 0.0f;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
}

RayHitResult ToResult(float tfar, unsigned geom, unsigned prim) {
  if (geom == RTC_INVALID_GEOMETRY_ID) return RayHitResult{kInf, -1, -1};
  return RayHitResult{tfar, static_cast<int>(geom), static_cast<int>(prim)};
}

}  // namespace

Eigen::Vector3f ClosestPointOnTriangle(const Eigen::Vector3f& p, const Eigen::Vector3f& a,
                                       const Eigen::Vector3f& b, const Eigen::Vector3f& c) {
  const Eigen::Vector3f ab = b - a, ac = c - a, ap = p - a;
  const float d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3f bp = p - b;
  const float d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const float vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
  const Eigen::Vector3f cp = p - c;
  const float d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const float vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
  const float va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  }
  const float denom = 1.0f / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

struct RayCaster::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  TriangleMesh meshes[2];  // kept for closest-point queries

  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }
};

namespace {

struct PointQueryState {
  const TriangleMesh* meshes;
  ClosestPoint best;
};

bool PointQueryCallback(RTCPointQueryFunctionArguments* args) {
  auto* state = static_cast<PointQueryState*>(args->userPtr);
  const TriangleMesh& mesh = state->meshes[args->geomID];
  const Eigen::Vector3i& tri = mesh.triangles[args->primID];
  const Eigen::Vector3f p(args->query->x, args->query->y, args->query->z);
  const Eigen::Vector3f q = ClosestPointOnTriangle(p, mesh.vertices[tri[0]],
                                                   mesh.vertices[tri[1]], mesh.vertices[tri[2]]);
  const float d = (q - p).norm();
  if (d < state->best.distance_m) {
    state->best = ClosestPoint{d, q, static_cast<int>(args->geomID),
                               static_cast<int>(args->primID)};
    args->query->radius = d;  // shrinks the search
    return true;
  }
  return false;
}

}  // namespace

RayCaster::RayCaster(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
RayCaster::~RayCaster() = default;

absl::StatusOr<std::unique_ptr<RayCaster>> RayCaster::Create(const TriangleMesh& structure,
                                                             const TriangleMesh& objects) {
  auto impl = std::make_unique<Impl>();
  impl->meshes[0] = structure;
  impl->meshes[1] = objects;
  impl->device = rtcNewDevice(nullptr);
  if (!impl->device) return absl::InternalError("raycaster: cannot create an embree device");
  impl->scene = rtcNewScene(impl->device);
  rtcSetSceneBuildQuality(impl->scene, RTC_BUILD_QUALITY_HIGH);
  // Fixed geometry ids: 0 = structure, 1 = objects; an empty mesh is not attached.
  for (int g = 0; g < 2; ++g) {
    const TriangleMesh& mesh = impl->meshes[g];
    const size_t nv = mesh.vertices.size();
    if (mesh.triangles.empty()) continue;
    for (size_t i = 0; i < mesh.triangles.size(); ++i) {
      const Eigen::Vector3i& t = mesh.triangles[i];
      if ((t.array() < 0).any() || (t.array() >= static_cast<int>(nv)).any()) {
        return absl::InvalidArgumentError(absl::StrCat("raycaster: ",
                                                       g == 0 ? "structure" : "objects",
                                                       " triangle ", i, " has an index out of range"));
      }
    }
    RTCGeometry geom = rtcNewGeometry(impl->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    // Embree reads 16 bytes past the last vertex with SSE loads: pad by one vertex.
    float* vb = static_cast<float*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), nv + 1));
    unsigned* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
        mesh.triangles.size()));
    if (!vb || !ib) {
      rtcReleaseGeometry(geom);
      absl::Status s = EmbreeStatus(impl->device, "rtcSetNewGeometryBuffer");
      return s.ok() ? absl::InternalError("raycaster: cannot allocate geometry buffers") : s;
    }
    for (size_t i = 0; i < nv; ++i) std::memcpy(vb + 3 * i, mesh.vertices[i].data(), 12);
    vb[3 * nv] = vb[3 * nv + 1] = vb[3 * nv + 2] = 0.0f;
    for (size_t i = 0; i < mesh.triangles.size(); ++i) {
      for (int k = 0; k < 3; ++k) ib[3 * i + k] = static_cast<unsigned>(mesh.triangles[i][k]);
    }
    rtcSetGeometryPointQueryFunction(geom, PointQueryCallback);
    rtcCommitGeometry(geom);
    rtcAttachGeometryByID(impl->scene, geom, g);
    rtcReleaseGeometry(geom);
  }
  rtcCommitScene(impl->scene);
  if (absl::Status s = EmbreeStatus(impl->device, "rtcCommitScene"); !s.ok()) return s;
  return std::unique_ptr<RayCaster>(new RayCaster(std::move(impl)));
}

size_t RayCaster::triangle_count() const {
  return impl_->meshes[0].triangles.size() + impl_->meshes[1].triangles.size();
}

RayHitResult RayCaster::Cast(const RayQuery& ray) const {
  RayHitResult hit;
  Cast(std::span<const RayQuery>(&ray, 1), std::span<RayHitResult>(&hit, 1));
  return hit;
}

void RayCaster::Cast(std::span<const RayQuery> rays, std::span<RayHitResult> hits,
                     CastMode mode) const {
  assert(rays.size() == hits.size());
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  // A scanner's rays share an origin and sweep in angle order: coherent.
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  switch (mode) {
    case CastMode::kSingle: {
      RTCRayHit rh;
      for (size_t i = 0; i < rays.size(); ++i) {
        FillRay(rays[i], rh);
        rtcIntersect1(impl_->scene, &context, &rh);
        hits[i] = ToResult(rh.ray.tfar, rh.hit.geomID, rh.hit.primID);
      }
      break;
    }
    case CastMode::kStream: {
      constexpr size_t kBlock = 256;
      alignas(16) RTCRayHit block[kBlock];
      for (size_t first = 0; first < rays.size(); first += kBlock) {
        const size_t n = std::min(kBlock, rays.size() - first);
        for (size_t i = 0; i < n; ++i) FillRay(rays[first + i], block[i]);
        rtcIntersect1M(impl_->scene, &context, block, static_cast<unsigned>(n),
                       sizeof(RTCRayHit));
        for (size_t i = 0; i < n; ++i) {
          hits[first + i] = ToResult(block[i].ray.tfar, block[i].hit.geomID, block[i].hit.primID);
        }
      }
      break;
    }
    case CastMode::kPacket: {
      alignas(64) RTCRayHit16 p;
      alignas(64) int valid[16];
      for (size_t first = 0; first < rays.size(); first += 16) {
        const size_t n = std::min<size_t>(16, rays.size() - first);
        for (size_t i = 0; i < 16; ++i) {
          valid[i] = i < n ? -1 : 0;
          const RayQuery& q = rays[first + std::min(i, n - 1)];
          p.ray.org_x[i] = q.origin.x();
          p.ray.org_y[i] = q.origin.y();
          p.ray.org_z[i] = q.origin.z();
          p.ray.dir_x[i] = q.direction.x();
          p.ray.dir_y[i] = q.direction.y();
          p.ray.dir_z[i] = q.direction.z();
          p.ray.tnear[i] = 0.0f;
          p.ray.tfar[i] = q.max_range_m;
          p.ray.time[i] = 0.0f;
          p.ray.mask[i] = 0xFFFFFFFFu;
          p.ray.id[i] = 0;
          p.ray.flags[i] = 0;
          p.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
          p.hit.primID[i] = RTC_INVALID_GEOMETRY_ID;
          p.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
        }
        rtcIntersect16(valid, impl_->scene, &context, &p);
        for (size_t i = 0; i < n; ++i) {
          hits[first + i] = ToResult(p.ray.tfar[i], p.hit.geomID[i], p.hit.primID[i]);
        }
      }
      break;
    }
  }
}

ClosestPoint RayCaster::Closest(const Eigen::Vector3f& p) const {
  PointQueryState state{impl_->meshes, ClosestPoint{kInf, p, -1, -1}};
  alignas(16) RTCPointQuery query;
  query.x = p.x();
  query.y = p.y();
  query.z = p.z();
  query.time = 0.0f;
  query.radius = kInf;
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  rtcPointQuery(impl_->scene, &query, &context, nullptr, &state);
  return state.best;
}

}  // namespace carvemap

// SplitObjects (services/segment/object_meshes.h) on a synthetic object mesh the size of a large
// building's: levels of 4 × 4 m rooms, each with furniture in stacked pieces and many specks
// around it, as the finer re-carve leaves them. Prints the seconds and a fingerprint of the
// objects (ids, levels, rooms, boxes, triangle counts), so two builds can be compared for speed
// and for identical output (the fingerprint covers the meshes' vertices and triangles too).
//
//   object_split_bench [--side N] [--levels L] [--pieces P] [--specks S]
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>

#include "services/segment/object_meshes.h"
#include "services/segment/plan_volume.h"
#include "services/segment/segment_test_util.h"

namespace carvemap {
namespace {

// 12 triangles facing into the box, as dual contouring orients the object volume's surface.
void AppendInwardBox(TriangleMesh& m, const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
  const int b = static_cast<int>(m.vertices.size());
  for (int i = 0; i < 8; ++i) {
    m.vertices.emplace_back(i & 1 ? hi.x() : lo.x(), i & 2 ? hi.y() : lo.y(),
                            i & 4 ? hi.z() : lo.z());
  }
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.triangles.emplace_back(b + q[0], b + q[2], b + q[1]);
    m.triangles.emplace_back(b + q[0], b + q[3], b + q[2]);
  }
}

uint64_t Mix(uint64_t h, double v) {
  uint64_t bits;
  std::memcpy(&bits, &v, sizeof bits);
  for (int i = 0; i < 8; ++i) h = (h ^ ((bits >> (8 * i)) & 0xff)) * 1099511628211ull;
  return h;
}

int Main(int argc, char** argv) {
  int side = 20, levels = 4, pieces = 6, specks = 200;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    const int v = std::atoi(argv[i + 1]);
    if (a == "--side") side = v;
    else if (a == "--levels") levels = v;
    else if (a == "--pieces") pieces = v;
    else if (a == "--specks") specks = v;
    else {
      std::fprintf(stderr, "unknown option %s\n", a.c_str());
      return 2;
    }
  }
  const double room = 4, storey = 3;
  std::vector<testing::TestRoom> rooms;
  for (int l = 0; l < levels; ++l)
    for (int y = 0; y < side; ++y)
      for (int x = 0; x < side; ++x)
        rooms.push_back({{x * room, y * room}, {(x + 1) * room, (y + 1) * room}, l * storey,
                         l * storey + 2.5});
  std::vector<FloorPlan> plans;
  for (int l = 0; l < levels; ++l) {
    plans.push_back(testing::RectanglePlan(
        {rooms.begin() + l * side * side, rooms.begin() + (l + 1) * side * side}));
  }
  std::vector<PlanLevelInput> inputs;
  for (int l = 0; l < levels; ++l) {
    inputs.push_back({&plans[l], l, l * storey - 0.2, l * storey + 2.7});
  }
  const absl::StatusOr<PlanVolume> volume = RasterizePlanVolume(inputs, 0.0625, 1.0);
  if (!volume.ok()) {
    std::fprintf(stderr, "%s\n", std::string(volume.status().message()).c_str());
    return 1;
  }

  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0, 1);
  TriangleMesh mesh;
  for (const testing::TestRoom& r : rooms) {
    for (int p = 0; p < pieces; ++p) {
      // A piece of furniture: a top and, under it, a leg piece 5–40 cm below (stacked).
      const Eigen::Vector3f lo(r.lo.x() + 0.2f + 2.8f * u(rng), r.lo.y() + 0.2f + 2.8f * u(rng),
                               static_cast<float>(r.floor_z) + 0.6f + 0.6f * u(rng));
      const Eigen::Vector3f size(0.3f + 0.6f * u(rng), 0.3f + 0.6f * u(rng),
                                 0.05f + 0.1f * u(rng));
      AppendInwardBox(mesh, lo, lo + size);
      const float gap = 0.05f + 0.35f * u(rng);
      const Eigen::Vector3f leg_lo(lo.x(), lo.y(), static_cast<float>(r.floor_z) + 0.02f);
      const Eigen::Vector3f leg_hi(lo.x() + 0.1f, lo.y() + 0.1f,
                                   std::max(lo.z() - gap, leg_lo.z() + 0.1f));
      AppendInwardBox(mesh, leg_lo, leg_hi);
    }
    for (int s = 0; s < specks; ++s) {
      const Eigen::Vector3f lo(r.lo.x() + 3.9f * u(rng), r.lo.y() + 3.9f * u(rng),
                               static_cast<float>(r.floor_z) + 2.4f * u(rng));
      AppendInwardBox(mesh, lo, lo + Eigen::Vector3f::Constant(0.02f + 0.04f * u(rng)));
    }
  }
  std::printf("%zu rooms, %zu triangles in %zu pieces\n", rooms.size(), mesh.triangles.size(),
              mesh.triangles.size() / 12);
  const auto t0 = std::chrono::steady_clock::now();
  ObjectSplitReport report;
  const std::vector<SegmentedObject> objects =
      SplitObjects(mesh, *volume, ObjectSplitOptions{}, &report);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  uint64_t h = 1469598103934665603ull;
  for (const SegmentedObject& o : objects) {
    for (double v : {double(o.id), double(o.level), double(o.room), o.box.min().x(),
                     o.box.min().y(), o.box.min().z(), o.box.max().x(), o.box.max().y(),
                     o.box.max().z(), double(o.mesh.triangles.size()), o.volume_m3})
      h = Mix(h, v);
    for (const Eigen::Vector3f& v : o.mesh.vertices) {
      for (int d = 0; d < 3; ++d) h = Mix(h, v[d]);
    }
    for (const Eigen::Vector3i& t : o.mesh.triangles) {
      for (int d = 0; d < 3; ++d) h = Mix(h, t[d]);
    }
  }
  std::printf("SplitObjects: %.3f s; %zu objects; components %llu, grouped %llu, dropped small "
              "%llu, ceiling %llu, cavities %llu; fingerprint %016llx\n",
              s, objects.size(), (unsigned long long)report.components,
              (unsigned long long)report.grouped, (unsigned long long)report.dropped_small,
              (unsigned long long)report.dropped_ceiling,
              (unsigned long long)report.dropped_cavities, (unsigned long long)h);
  return 0;
}

}  // namespace
}  // namespace carvemap

int main(int argc, char** argv) { return carvemap::Main(argc, argv); }

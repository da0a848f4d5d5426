#include "services/segment/object_meshes.h"

#include <algorithm>
#include <numeric>
#include <tuple>

namespace carvemap {
namespace {

int Find(std::vector<int>& parent, int x) {
  while (parent[x] != x) {
    parent[x] = parent[parent[x]];
    x = parent[x];
  }
  return x;
}

}  // namespace

std::vector<SegmentedObject> SplitObjects(const TriangleMesh& object_mesh,
                                          const PlanVolume& plan,
                                          const ObjectSplitOptions& options,
                                          ObjectSplitReport* report) {
  ObjectSplitReport local_report;
  ObjectSplitReport& rep = report ? *report : local_report;
  rep = ObjectSplitReport{};
  const int nv = static_cast<int>(object_mesh.vertices.size());
  std::vector<int> parent(nv);
  std::iota(parent.begin(), parent.end(), 0);
  for (const Eigen::Vector3i& t : object_mesh.triangles) {
    for (int e = 1; e < 3; ++e) {
      const int a = Find(parent, t[0]), b = Find(parent, t[e]);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  }
  // Component of each triangle, numbered by first appearance.
  std::vector<int> comp_of_root(nv, -1);
  std::vector<std::vector<int>> comp_triangles;
  for (int i = 0; i < static_cast<int>(object_mesh.triangles.size()); ++i) {
    const int root = Find(parent, object_mesh.triangles[i][0]);
    if (comp_of_root[root] < 0) {
      comp_of_root[root] = static_cast<int>(comp_triangles.size());
      comp_triangles.emplace_back();
    }
    comp_triangles[comp_of_root[root]].push_back(i);
  }
  rep.components = comp_triangles.size();

  std::vector<SegmentedObject> objects;
  std::vector<int> remap(nv, -1);
  for (const std::vector<int>& tris : comp_triangles) {
    SegmentedObject obj;
    for (int ti : tris) {
      const Eigen::Vector3i& t = object_mesh.triangles[ti];
      Eigen::Vector3i u;
      for (int c = 0; c < 3; ++c) {
        int& r = remap[t[c]];
        if (r < 0) {
          r = static_cast<int>(obj.mesh.vertices.size());
          obj.mesh.vertices.push_back(object_mesh.vertices[t[c]]);
          obj.box.extend(object_mesh.vertices[t[c]].cast<double>());
        }
        u[c] = r;
      }
      // Flip: the input faces the free space, an object's mesh faces out of the object.
      obj.mesh.triangles.emplace_back(u[0], u[2], u[1]);
    }
    for (int ti : tris) {
      for (int c = 0; c < 3; ++c) remap[object_mesh.triangles[ti][c]] = -1;
    }
    // Divergence theorem, about the box centre to keep the sums small.
    const Eigen::Vector3d o = obj.box.center();
    double six_v = 0;
    for (const Eigen::Vector3i& t : obj.mesh.triangles) {
      const Eigen::Vector3d a = obj.mesh.vertices[t[0]].cast<double>() - o;
      const Eigen::Vector3d b = obj.mesh.vertices[t[1]].cast<double>() - o;
      const Eigen::Vector3d c = obj.mesh.vertices[t[2]].cast<double>() - o;
      six_v += a.dot(b.cross(c));
    }
    obj.volume_m3 = six_v / 6.0;
    if (obj.volume_m3 < 0) {
      ++rep.dropped_cavities;
      continue;
    }
    if (obj.volume_m3 < options.min_volume_m3 ||
        obj.box.sizes().minCoeff() < options.min_thickness_m) {
      ++rep.dropped_small;
      continue;
    }
    const PlanColumn col = LookupPlan(plan, obj.box.center());
    obj.level = col.level;
    obj.room = col.room;
    if (col.room >= 0 && obj.box.max().z() >= col.ceiling_z - options.ceiling_film_m) {
      const Eigen::Vector3d size = obj.box.sizes();
      const double thin = std::min(size.x(), size.y()), wide = std::max(size.x(), size.y());
      if (size.z() <= options.ceiling_film_m ||
          (thin <= options.door_header_depth_m && wide >= options.door_header_min_width_m)) {
        ++rep.dropped_ceiling;
        continue;
      }
    }
    objects.push_back(std::move(obj));
  }
  std::sort(objects.begin(), objects.end(), [](const SegmentedObject& a, const SegmentedObject& b) {
    return std::make_tuple(a.level, a.box.min().x(), a.box.min().y(), a.box.min().z()) <
           std::make_tuple(b.level, b.box.min().x(), b.box.min().y(), b.box.min().z());
  });
  for (size_t i = 0; i < objects.size(); ++i) objects[i].id = static_cast<int>(i);
  return objects;
}

}  // namespace carvemap

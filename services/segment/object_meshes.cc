#include "services/segment/object_meshes.h"

#include <algorithm>
#include <cmath>
#include <tuple>

#include "absl/container/flat_hash_map.h"
#include "services/geometry/union_find.h"

namespace carvemap {
namespace {

// A piece that only joins others while grouping (a speck), never links two.
bool Speck(const SegmentedObject& o, const ObjectSplitOptions& options) {
  return o.volume_m3 < options.speck_volume_m3 ||
         o.box.sizes().minCoeff() < options.min_thickness_m;
}

// An object, once grouped, too small to report.
bool TooSmall(const SegmentedObject& o, const ObjectSplitOptions& options) {
  return Speck(o, options) || o.volume_m3 < options.min_volume_m3;
}

// The share of the smaller footprint (xy box) that the two footprints share.
double FootprintOverlap(const Eigen::AlignedBox3d& a, const Eigen::AlignedBox3d& b) {
  const Eigen::AlignedBox2d fa(a.min().head<2>(), a.max().head<2>());
  const Eigen::AlignedBox2d fb(b.min().head<2>(), b.max().head<2>());
  const Eigen::AlignedBox2d i = fa.intersection(fb);
  if (i.isEmpty()) return 0;
  const double smaller = std::min(fa.volume(), fb.volume());
  return smaller > 0 ? i.volume() / smaller : 0;
}

// The pieces whose footprints could overlap a box's, on its level: the members' footprints
// bucketed on an xy grid. Why: a building's finer re-carve leaves hundreds of thousands of
// specks, and testing each against every piece grows with their product.
class FootprintGrid {
 public:
  static constexpr double kCellM = 0.5;

  void Add(int index, const SegmentedObject& piece) {
    ForCells(piece.box, [&](int64_t x, int64_t y) { cells_[{piece.level, x, y}].push_back(index); });
  }

  // Members sharing a cell with `box` on `level`, in increasing order, each once.
  void Candidates(const Eigen::AlignedBox3d& box, int level, std::vector<int>& out) const {
    out.clear();
    ForCells(box, [&](int64_t x, int64_t y) {
      if (auto it = cells_.find({level, x, y}); it != cells_.end()) {
        out.insert(out.end(), it->second.begin(), it->second.end());
      }
    });
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
  }

 private:
  template <typename F>
  static void ForCells(const Eigen::AlignedBox3d& box, F&& f) {
    const auto cell = [](double v) { return static_cast<int64_t>(std::floor(v / kCellM)); };
    for (int64_t y = cell(box.min().y()); y <= cell(box.max().y()); ++y) {
      for (int64_t x = cell(box.min().x()); x <= cell(box.max().x()); ++x) f(x, y);
    }
  }

  absl::flat_hash_map<std::tuple<int, int64_t, int64_t>, std::vector<int>> cells_;
};

// Pieces on one level stacked over each other (footprints overlapping by stack_overlap of the
// smaller, vertical gap at most stack_gap_m) become one object, transitively.
std::vector<SegmentedObject> GroupStacked(std::vector<SegmentedObject> pieces,
                                          const PlanVolume& plan,
                                          const ObjectSplitOptions& options,
                                          ObjectSplitReport& rep) {
  if (options.stack_gap_m < 0) return pieces;
  const int n = static_cast<int>(pieces.size());
  UnionFind<int> groups(n);
  // How much j's footprint shares with i's when they are stacked; 0 when not.
  auto stacked = [&](int i, int j) {
    const Eigen::AlignedBox3d &a = pieces[i].box, &b = pieces[j].box;
    if (pieces[i].level != pieces[j].level) return 0.0;
    const double gap = std::max(a.min().z() - b.max().z(), b.min().z() - a.max().z());
    const double overlap = FootprintOverlap(a, b);
    return gap <= options.stack_gap_m && overlap >= options.stack_overlap ? overlap : 0.0;
  };
  // Only footprints that overlap stack, so only pieces sharing a grid cell need the test.
  std::vector<bool> small(n);
  FootprintGrid footprints;
  for (int i = 0; i < n; ++i) {
    small[i] = Speck(pieces[i], options);
    if (!small[i]) footprints.Add(i, pieces[i]);
  }
  std::vector<int> near;
  for (int i = 0; i < n; ++i) {
    if (small[i]) continue;
    footprints.Candidates(pieces[i].box, pieces[i].level, near);
    for (int j : near) {
      if (j > i && stacked(i, j) > 0) groups.Union(i, j);
    }
  }
  // A speck joins the one object it overlaps most, so specks never link two objects (a desk
  // and the chair beside it share specks in the gap between them). Ties go to the first piece.
  for (int i = 0; i < n; ++i) {
    if (!small[i]) continue;
    int best = -1;
    double best_overlap = 0;
    footprints.Candidates(pieces[i].box, pieces[i].level, near);
    for (int j : near) {
      if (const double o = stacked(i, j); o > best_overlap) best = j, best_overlap = o;
    }
    if (best >= 0) groups.Union(i, best);
  }
  std::vector<SegmentedObject> grouped;
  std::vector<int> group_of(n, -1);
  std::vector<bool> grew;  // per group: its box changed, so its level and room may have
  for (int i = 0; i < n; ++i) {
    const int root = groups.Find(i);
    if (group_of[root] < 0) {
      group_of[root] = static_cast<int>(grouped.size());
      grouped.push_back(std::move(pieces[i]));
      grew.push_back(false);
      continue;
    }
    grew[group_of[root]] = true;
    SegmentedObject& g = grouped[group_of[root]];
    const SegmentedObject& p = pieces[i];
    const int offset = static_cast<int>(g.mesh.vertices.size());
    g.mesh.vertices.insert(g.mesh.vertices.end(), p.mesh.vertices.begin(), p.mesh.vertices.end());
    for (const Eigen::Vector3i& t : p.mesh.triangles) {
      g.mesh.triangles.push_back(t + Eigen::Vector3i::Constant(offset));
    }
    g.box.extend(p.box);
    g.volume_m3 += p.volume_m3;
    ++rep.grouped;
  }
  // A piece kept alone keeps the level and room SplitObjects found for it.
  for (size_t g = 0; g < grouped.size(); ++g) {
    if (!grew[g]) continue;
    const PlanColumn col = LookupPlan(plan, grouped[g].box.center());
    grouped[g].level = col.level;
    grouped[g].room = col.room;
  }
  return grouped;
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
  UnionFind<int> joined(nv);
  for (const Eigen::Vector3i& t : object_mesh.triangles) {
    for (int e = 1; e < 3; ++e) joined.Union(t[0], t[e]);
  }
  // Component of each triangle, numbered by first appearance.
  std::vector<int> comp_of_root(nv, -1);
  std::vector<std::vector<int>> comp_triangles;
  for (int i = 0; i < static_cast<int>(object_mesh.triangles.size()); ++i) {
    const int root = joined.Find(object_mesh.triangles[i][0]);
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
    const PlanColumn col = LookupPlan(plan, obj.box.center());
    obj.level = col.level;
    obj.room = col.room;
    // Specks are judged after grouping: a speck stacked on an object is part of it (a point
    // of a lamp's rod, a leg's foot).
    if (!Speck(obj, options) && col.room >= 0 &&
        obj.box.max().z() >= col.ceiling_z - options.ceiling_film_m) {
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
  objects = GroupStacked(std::move(objects), plan, options, rep);
  const size_t before = objects.size();
  std::erase_if(objects, [&](const SegmentedObject& o) { return TooSmall(o, options); });
  rep.dropped_small = before - objects.size();
  std::sort(objects.begin(), objects.end(), [](const SegmentedObject& a, const SegmentedObject& b) {
    return std::make_tuple(a.level, a.box.min().x(), a.box.min().y(), a.box.min().z()) <
           std::make_tuple(b.level, b.box.min().x(), b.box.min().y(), b.box.min().z());
  });
  for (size_t i = 0; i < objects.size(); ++i) objects[i].id = static_cast<int>(i);
  return objects;
}

}  // namespace carvemap

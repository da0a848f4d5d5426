#include "services/segment/object_meshes.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <span>
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
    ForCells(piece.box,
             [&](int64_t x, int64_t y) { cells_[{piece.level, x, y}].push_back(index); });
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

// Objects as grouping makes them, before their meshes: each one's box, volume, level and room,
// and the pieces it is made of, in ascending order.
struct Groups {
  std::vector<SegmentedObject> objects;  // meshes empty
  std::vector<std::vector<int>> pieces;
};

// Pieces on one level stacked over each other (footprints overlapping by stack_overlap of the
// smaller, vertical gap at most stack_gap_m) become one object, transitively. `pieces` carry
// no meshes: only what the grouping reads.
Groups GroupStacked(std::vector<SegmentedObject> pieces, const PlanVolume& plan,
                    const ObjectSplitOptions& options, ObjectSplitReport& rep) {
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
  // Only footprints that overlap stack, so only pieces sharing a grid cell need the test. With
  // stack_gap_m < 0 the grid stays empty: every piece is an object of its own.
  std::vector<bool> small(n);
  FootprintGrid footprints;
  for (int i = 0; i < n && options.stack_gap_m >= 0; ++i) {
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
  Groups grouped;
  std::vector<int> group_of(n, -1);
  std::vector<bool> grew;  // per group: its box changed, so its level and room may have
  for (int i = 0; i < n; ++i) {
    const int root = groups.Find(i);
    if (group_of[root] < 0) {
      group_of[root] = static_cast<int>(grouped.objects.size());
      grouped.objects.push_back(std::move(pieces[i]));
      grouped.pieces.push_back({i});
      grew.push_back(false);
      continue;
    }
    const int g = group_of[root];
    grew[g] = true;
    grouped.objects[g].box.extend(pieces[i].box);
    grouped.objects[g].volume_m3 += pieces[i].volume_m3;
    grouped.pieces[g].push_back(i);
    ++rep.grouped;
  }
  // A piece kept alone keeps the level and room SplitObjects found for it.
  for (size_t g = 0; g < grouped.objects.size(); ++g) {
    if (!grew[g]) continue;
    SegmentedObject& o = grouped.objects[g];
    const PlanColumn col = LookupPlan(plan, o.box.center());
    o.level = col.level;
    o.room = col.room;
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
  const auto& tris = object_mesh.triangles;
  const auto& verts = object_mesh.vertices;
  const int nv = static_cast<int>(verts.size());
  const int nt = static_cast<int>(tris.size());
  UnionFind<int> joined(nv);
  for (const Eigen::Vector3i& t : tris) {
    for (int e = 1; e < 3; ++e) joined.Union(t[0], t[e]);
  }
  // Components numbered by first appearance; each one's triangles in ascending order:
  // order[start[c], start[c + 1]).
  std::vector<int> start, order(nt);
  {
    std::vector<int> comp_of_root(nv, -1), comp_of(nt);
    for (int i = 0; i < nt; ++i) {
      int& c = comp_of_root[joined.Find(tris[i][0])];
      if (c < 0) {
        c = static_cast<int>(start.size());
        start.push_back(0);
      }
      comp_of[i] = c;
      ++start[c];
    }
    start.push_back(0);
    std::exclusive_scan(start.begin(), start.end(), start.begin(), 0);
    std::vector<int> next(start.begin(), start.end() - 1);
    for (int i = 0; i < nt; ++i) order[next[comp_of[i]]++] = i;
  }
  const int num_comps = static_cast<int>(start.size()) - 1;
  rep.components = num_comps;
  const auto comp_triangles = [&](int c) {
    return std::span<const int>(order).subspan(start[c], start[c + 1] - start[c]);
  };
  // Flip: the input faces the free space, an object's mesh faces out of the object.
  const auto flipped = [](const Eigen::Vector3i& t) { return Eigen::Vector3i(t[0], t[2], t[1]); };

  // Each piece's box, volume, level and room first; meshes only for the objects kept (the
  // specks, cavities and films dropped are most of the pieces of a building's re-carve).
  std::vector<SegmentedObject> pieces;
  std::vector<int> piece_comp;
  for (int c = 0; c < num_comps; ++c) {
    SegmentedObject obj;
    for (int ti : comp_triangles(c)) {
      for (int k = 0; k < 3; ++k) obj.box.extend(verts[tris[ti][k]].cast<double>());
    }
    // Divergence theorem, about the box centre to keep the sums small.
    const Eigen::Vector3d o = obj.box.center();
    double six_v = 0;
    for (int ti : comp_triangles(c)) {
      const Eigen::Vector3i t = flipped(tris[ti]);
      const Eigen::Vector3d a = verts[t[0]].cast<double>() - o;
      const Eigen::Vector3d b = verts[t[1]].cast<double>() - o;
      const Eigen::Vector3d d = verts[t[2]].cast<double>() - o;
      six_v += a.dot(b.cross(d));
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
    pieces.push_back(std::move(obj));
    piece_comp.push_back(c);
  }
  Groups groups = GroupStacked(std::move(pieces), plan, options, rep);
  std::vector<int> kept;
  for (int g = 0; g < static_cast<int>(groups.objects.size()); ++g) {
    if (!TooSmall(groups.objects[g], options)) kept.push_back(g);
  }
  rep.dropped_small = groups.objects.size() - kept.size();
  std::sort(kept.begin(), kept.end(), [&](int i, int j) {
    const SegmentedObject &a = groups.objects[i], &b = groups.objects[j];
    return std::make_tuple(a.level, a.box.min().x(), a.box.min().y(), a.box.min().z()) <
           std::make_tuple(b.level, b.box.min().x(), b.box.min().y(), b.box.min().z());
  });
  // The meshes: each piece's vertices in the order its triangles first use them, the pieces
  // of an object one after the other (each a closed surface of its own).
  std::vector<SegmentedObject> objects;
  objects.reserve(kept.size());
  std::vector<int> remap(nv, -1);
  for (int g : kept) {
    SegmentedObject obj = std::move(groups.objects[g]);
    obj.id = static_cast<int>(objects.size());
    for (int p : groups.pieces[g]) {
      const std::span<const int> piece = comp_triangles(piece_comp[p]);
      for (int ti : piece) {
        Eigen::Vector3i u;
        for (int k = 0; k < 3; ++k) {
          int& r = remap[tris[ti][k]];
          if (r < 0) {
            r = static_cast<int>(obj.mesh.vertices.size());
            obj.mesh.vertices.push_back(verts[tris[ti][k]]);
          }
          u[k] = r;
        }
        obj.mesh.triangles.push_back(flipped(u));
      }
      for (int ti : piece) {
        for (int k = 0; k < 3; ++k) remap[tris[ti][k]] = -1;
      }
    }
    objects.push_back(std::move(obj));
  }
  return objects;
}

}  // namespace carvemap

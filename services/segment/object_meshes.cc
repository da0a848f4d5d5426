#include "services/segment/object_meshes.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <span>
#include <tuple>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "geometry/union_find.h"

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

// Whether every corner of the footprint (xy box) of `box` lies within `band` of the plan's
// walls (ObjectSplitOptions::wall_smear_m), or outside the plan.
bool AlongAWall(const Eigen::AlignedBox3d& box, const PlanVolume& plan, double band) {
  if (!(band > 0)) return false;
  for (double x : {box.min().x(), box.max().x()}) {
    for (double y : {box.min().y(), box.max().y()}) {
      if (LookupPlan(plan, Eigen::Vector3d(x, y, box.center().z())).signed_distance_m > band) {
        return false;
      }
    }
  }
  return true;
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
  // A speck along a wall (wall_smear_m) does not join one below it.
  for (int i = 0; i < n; ++i) {
    if (!small[i]) continue;
    int best = -1;
    double best_overlap = 0;
    bool held_off = false;
    const bool along_a_wall = AlongAWall(pieces[i].box, plan, options.wall_smear_m);
    footprints.Candidates(pieces[i].box, pieces[i].level, near);
    for (int j : near) {
      const double o = stacked(i, j);
      if (o > 0 && along_a_wall && pieces[i].box.min().z() > pieces[j].box.max().z()) {
        held_off = true;
        continue;
      }
      if (o > best_overlap) best = j, best_overlap = o;
    }
    if (best >= 0) groups.Union(i, best);
    rep.specks_off_walls += held_off;
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

// Flip: the stream faces the free space, an object's mesh faces out of the object.
Eigen::Vector3i Flipped(const Eigen::Vector3i& t) { return {t[0], t[2], t[1]}; }

}  // namespace

ObjectSplitter::ObjectSplitter(const PlanVolume& plan, const ObjectSplitOptions& options,
                               PieceSink sink)
    : plan_(plan), options_(options), sink_(std::move(sink)) {}

void ObjectSplitter::AddVertices(std::span<const Eigen::Vector3f> vertices) {
  int v = static_cast<int>(finished_vertex_.size());
  for (const Eigen::Vector3f& p : vertices) vertices_.emplace(v, Vertex{p, v}), ++v;
  finished_vertex_.resize(v, false);
}

int ObjectSplitter::Find(int v) {
  // Path halving, as UnionFind does, over the hash map of the open vertices.
  for (;;) {
    Vertex& x = vertices_.find(v)->second;
    if (x.parent == v) return v;
    const int grand = vertices_.find(x.parent)->second.parent;
    x.parent = grand;
    v = grand;
  }
}

absl::Status ObjectSplitter::AddTriangles(int64_t column,
                                          std::span<const Eigen::Vector3i> triangles) {
  if (column < column_) {
    return absl::InvalidArgumentError(
        absl::StrCat("object mesh: chunk column ", column, " after column ", column_));
  }
  if (column > column_) {
    column_ = column;
    if (absl::Status s = FinishPieces(column - 1); !s.ok()) return s;
  }
  for (const Eigen::Vector3i& t : triangles) {
    int roots[3];
    for (int k = 0; k < 3; ++k) {
      if (t[k] < 0 || size_t(t[k]) >= finished_vertex_.size()) {
        return absl::InvalidArgumentError(absl::StrCat("object mesh: triangle ", next_triangle_,
                                                       " names vertex ", t[k], " of ",
                                                       finished_vertex_.size()));
      }
      if (finished_vertex_[t[k]]) {
        return absl::InternalError(
            absl::StrCat("object mesh: triangle ", next_triangle_, " in chunk column ", column,
                         " joins a piece finished before it (its vertex ", t[k], ")"));
      }
      roots[k] = Find(t[k]);
    }
    // The piece with the most triangles absorbs the others (a vertex's first triangle makes
    // its piece).
    const auto size_of = [&](int r) {
      auto it = open_.find(r);
      return it == open_.end() ? size_t{0} : it->second.triangles.size();
    };
    int root = roots[0];
    for (int k = 1; k < 3; ++k) {
      if (roots[k] != root && size_of(roots[k]) > size_of(root)) root = roots[k];
    }
    OpenPiece& into = open_.try_emplace(root).first->second;
    for (int k = 0; k < 3; ++k) {
      if (roots[k] == root) continue;
      vertices_.find(roots[k])->second.parent = root;
      // Erasing leaves the other elements (and `into`) where they are.
      if (auto it = open_.find(roots[k]); it != open_.end()) {
        into.triangles.insert(into.triangles.end(), it->second.triangles.begin(),
                              it->second.triangles.end());
        into.last_column = std::max(into.last_column, it->second.last_column);
        open_.erase(it);
      }
    }
    into.triangles.emplace_back(next_triangle_++, t);
    into.last_column = column;
    ++open_triangles_;
  }
  return absl::OkStatus();
}

absl::Status ObjectSplitter::FinishPieces(int64_t before_column) {
  // In the order of their keys, so the sink sees the same order whatever the hash map's.
  std::vector<std::pair<uint64_t, int>> done;
  for (const auto& [root, piece] : open_) {
    if (piece.last_column < before_column) {
      uint64_t first = piece.triangles.front().first;
      for (const auto& t : piece.triangles) first = std::min(first, t.first);
      done.emplace_back(first, root);
    }
  }
  std::sort(done.begin(), done.end());
  for (const auto& [key, root] : done) {
    auto it = open_.find(root);
    OpenPiece piece = std::move(it->second);
    open_.erase(it);
    if (absl::Status s = FinishPiece(std::move(piece)); !s.ok()) return s;
  }
  return absl::OkStatus();
}

absl::Status ObjectSplitter::FinishPiece(OpenPiece piece) {
  auto& tris = piece.triangles;
  std::sort(tris.begin(), tris.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  open_triangles_ -= tris.size();
  ++report_.components;
  const auto position = [&](int v) { return vertices_.find(v)->second.position; };
  SegmentedObject obj;
  for (const auto& [index, t] : tris) {
    for (int k = 0; k < 3; ++k) obj.box.extend(position(t[k]).cast<double>());
  }
  // Divergence theorem, about the box centre to keep the sums small.
  const Eigen::Vector3d o = obj.box.center();
  double six_v = 0;
  for (const auto& [index, tri] : tris) {
    const Eigen::Vector3i t = Flipped(tri);
    const Eigen::Vector3d a = position(t[0]).cast<double>() - o;
    const Eigen::Vector3d b = position(t[1]).cast<double>() - o;
    const Eigen::Vector3d d = position(t[2]).cast<double>() - o;
    six_v += a.dot(b.cross(d));
  }
  obj.volume_m3 = six_v / 6.0;
  bool keep = true;
  if (obj.volume_m3 < 0) {
    ++report_.dropped_cavities;
    keep = false;
  } else {
    const PlanColumn col = LookupPlan(plan_, obj.box.center());
    obj.level = col.level;
    obj.room = col.room;
    // Specks are judged after grouping: a speck stacked on an object is part of it (a point
    // of a lamp's rod, a leg's foot).
    if (!Speck(obj, options_) && col.room >= 0 &&
        obj.box.max().z() >= col.ceiling_z - options_.ceiling_film_m) {
      const Eigen::Vector3d size = obj.box.sizes();
      const double thin = std::min(size.x(), size.y()), wide = std::max(size.x(), size.y());
      if (size.z() <= options_.ceiling_film_m ||
          (thin <= options_.door_header_depth_m && wide >= options_.door_header_min_width_m)) {
        ++report_.dropped_ceiling;
        keep = false;
      } else if (AlongAWall(obj.box, plan_, options_.wall_smear_m)) {
        ++report_.dropped_wall_smear;
        keep = false;
      }
    }
  }
  absl::Status sunk;
  // A speck's mesh is never written (ObjectSplitOptions::speck_volume_m3): its summary is all
  // the grouping needs.
  if (keep && !Speck(obj, options_)) {
    // The piece's mesh: vertices in the order its triangles first use them.
    TriangleMesh mesh;
    mesh.triangles.reserve(tris.size());
    absl::flat_hash_map<int, int> local;
    for (const auto& [index, t] : tris) {
      Eigen::Vector3i u;
      for (int k = 0; k < 3; ++k) {
        auto [it, inserted] = local.emplace(t[k], static_cast<int>(mesh.vertices.size()));
        if (inserted) mesh.vertices.push_back(position(t[k]));
        u[k] = it->second;
      }
      mesh.triangles.push_back(Flipped(u));
    }
    if (sink_) sunk = sink_(tris.front().first, mesh);
  }
  if (keep) summaries_.emplace_back(tris.front().first, std::move(obj));
  for (const auto& [index, t] : tris) {
    for (int k = 0; k < 3; ++k) {
      finished_vertex_[t[k]] = true;
      vertices_.erase(t[k]);
    }
  }
  return sunk;
}

absl::StatusOr<ObjectLayout> ObjectSplitter::Finish() {
  if (absl::Status s = FinishPieces(std::numeric_limits<int64_t>::max()); !s.ok()) return s;
  vertices_.clear();
  // Pieces in the order of their first triangles, as the whole mesh's components are numbered.
  std::sort(summaries_.begin(), summaries_.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<SegmentedObject> pieces;
  std::vector<uint64_t> keys;
  std::vector<bool> speck;     // per piece: a speck, in its object's box but not its mesh
  std::vector<double> volume;  // per piece
  pieces.reserve(summaries_.size());
  keys.reserve(summaries_.size());
  for (auto& [key, piece] : summaries_) {
    keys.push_back(key);
    speck.push_back(Speck(piece, options_));
    volume.push_back(piece.volume_m3);
    pieces.push_back(std::move(piece));
  }
  summaries_.clear();
  ObjectLayout layout;
  layout.report = report_;
  Groups groups = GroupStacked(std::move(pieces), plan_, options_, layout.report);
  std::vector<int> kept;
  for (int g = 0; g < static_cast<int>(groups.objects.size()); ++g) {
    if (!TooSmall(groups.objects[g], options_)) kept.push_back(g);
  }
  layout.report.dropped_small = groups.objects.size() - kept.size();
  std::sort(kept.begin(), kept.end(), [&](int i, int j) {
    const SegmentedObject &a = groups.objects[i], &b = groups.objects[j];
    return std::make_tuple(a.level, a.box.min().x(), a.box.min().y(), a.box.min().z()) <
           std::make_tuple(b.level, b.box.min().x(), b.box.min().y(), b.box.min().z());
  });
  for (int g : kept) {
    SegmentedObject& obj = layout.objects.emplace_back(std::move(groups.objects[g]));
    obj.id = static_cast<int>(layout.objects.size()) - 1;
    // The grouping decided on the volume with the specks; the object's volume is its mesh's.
    std::vector<uint64_t>& of = layout.pieces.emplace_back();
    obj.volume_m3 = 0;
    for (int p : groups.pieces[g]) {
      if (speck[p]) {
        ++layout.report.specks_unmeshed;
      } else {
        obj.volume_m3 += volume[p];
        of.push_back(keys[p]);
      }
    }
  }
  return layout;
}

std::vector<SegmentedObject> SplitObjects(const TriangleMesh& object_mesh, const PlanVolume& plan,
                                          const ObjectSplitOptions& options,
                                          ObjectSplitReport* report) {
  // The whole mesh as one column: every piece is finished by Finish().
  absl::flat_hash_map<uint64_t, TriangleMesh> meshes;
  ObjectSplitter splitter(plan, options, [&](uint64_t key, const TriangleMesh& mesh) {
    meshes.emplace(key, mesh);
    return absl::OkStatus();
  });
  splitter.AddVertices(object_mesh.vertices);
  absl::Status added = splitter.AddTriangles(0, object_mesh.triangles);
  absl::StatusOr<ObjectLayout> layout =
      added.ok() ? splitter.Finish() : absl::StatusOr<ObjectLayout>(added);
  // Triangles naming vertices the mesh lacks are the caller's error; there is no other.
  if (!layout.ok()) {
    if (report) *report = ObjectSplitReport{};
    return {};
  }
  if (report) *report = layout->report;
  for (size_t i = 0; i < layout->objects.size(); ++i) {
    for (uint64_t key : layout->pieces[i]) layout->objects[i].mesh.Append(meshes.at(key));
  }
  return std::move(layout->objects);
}

}  // namespace carvemap

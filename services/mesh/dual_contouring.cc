#include "services/mesh/dual_contouring.h"

#include <algorithm>
#include <iterator>
#include <limits>
#include <utility>

#include <Eigen/Geometry>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

struct KeyHash {
  size_t operator()(const MeshVertexKey& k) const {
    uint64_t h = 1469598103934665603ull;
    for (int32_t x : k.v) h = (h ^ static_cast<uint32_t>(x)) * 1099511628211ull;
    return h ^ (h >> 29);
  }
};

// A leaf as the mesh needs it: its p (taken at each of its cells, IsosurfaceOffsetM), its
// label and whether it was observed.
struct CellLeaf {
  double p = 0.5;
  bool interior = false;
  bool observed = false;
};

// Finest-cell labels of the chunk plus a one-cell halo on its low sides: cells
// [base − 1, base + n) per axis, each an index into `leaves` (0 = unobserved).
class LabelWindow {
 public:
  LabelWindow(const NeighbourhoodIndex& index) : index_(index) {
    const OctreeGrid& grid = index.hood().grid;
    n_ = grid.leaves_per_side();
    w_ = n_ + 1;
    res_ = grid.resolution_m();
    base_ = index.hood().chunk * n_;
    cells_.assign(static_cast<size_t>(w_) * w_ * w_, 0);
    leaves_.push_back(CellLeaf{0.5, false, false});
    const int k = grid.chunk_depth;
    if (const TileData* own = index.hood().tiles[ChunkNeighbourhood::Index(0, 0, 0)]) {
      for (const TileLeaf& leaf : own->leaves) {
        const uint32_t id = Add(leaf);
        const int s = 1 << (k - leaf.node.depth);
        const Eigen::Vector3i lo = leaf.node.local * s;
        for (int z = lo.z(); z < lo.z() + s; ++z) {
          for (int y = lo.y(); y < lo.y() + s; ++y) {
            uint32_t* row = &cells_[Index(Eigen::Vector3i(lo.x(), y, z))];
            std::fill(row, row + s, id);
          }
        }
      }
    }
    // The halo: one slab per low side, looked up leaf by leaf.
    absl::flat_hash_map<const TileLeaf*, uint32_t> ids;
    for (int z = -1; z < n_; ++z) {
      for (int y = -1; y < n_; ++y) {
        for (int x = -1; x < n_; ++x) {
          if (x >= 0 && y >= 0 && z >= 0) {
            x = n_;  // skip the chunk's own cells
            continue;
          }
          const Eigen::Vector3i local(x, y, z);
          const TileLeaf* leaf = index.StoredAt(base_ + local);
          if (leaf == nullptr) continue;
          auto [it, inserted] = ids.try_emplace(leaf, 0);
          if (inserted) it->second = Add(*leaf);
          cells_[Index(local)] = it->second;
        }
      }
    }
    for (const CellLeaf& l : leaves_) any_interior_ |= l.interior;
  }

  [[nodiscard]] bool any_interior() const { return any_interior_; }
  // `local` = global cell − base, in [−1, n).
  [[nodiscard]] const CellLeaf& At(const Eigen::Vector3i& local) const {
    return leaves_[cells_[Index(local)]];
  }
  [[nodiscard]] int n() const { return n_; }
  [[nodiscard]] double res() const { return res_; }
  [[nodiscard]] const LeafKey& base() const { return base_; }

 private:
  uint32_t Add(const TileLeaf& leaf) {
    leaves_.push_back(CellLeaf{leaf.stats.p(), leaf.stats.interior(), leaf.stats.observed()});
    return static_cast<uint32_t>(leaves_.size() - 1);
  }
  [[nodiscard]] size_t Index(const Eigen::Vector3i& local) const {
    return static_cast<size_t>(local.x() + 1) +
           static_cast<size_t>(w_) * (static_cast<size_t>(local.y() + 1) +
                                      static_cast<size_t>(w_) * static_cast<size_t>(local.z() + 1));
  }

  const NeighbourhoodIndex& index_;
  int n_ = 0, w_ = 0;
  double res_ = 0;
  LeafKey base_;
  std::vector<uint32_t> cells_;
  std::vector<CellLeaf> leaves_;
  bool any_interior_ = false;
};

// The faces around one grid corner g. Cell v ∈ [0, 8) of the 2×2×2 block around g is
// g + o with o_a = ((v >> a) & 1) − 1; face id = 3 v + axis for the face of interior cell v
// perpendicular to `axis` (each cell has exactly one such face touching g).
class CornerMesher {
 public:
  CornerMesher(const LabelWindow& window, ChunkMesh& out) : win_(window), out_(out) {}

  void Mesh(const Eigen::Vector3i& g_local) {
    g_ = g_local;
    int mask = 0;
    for (int v = 0; v < 8; ++v) {
      cell_[v] = &win_.At(g_ + Offset(v));
      if (cell_[v]->interior) mask |= 1 << v;
    }
    if (mask == 0 || mask == 0xff) return;
    std::array<int, 24> next;
    next.fill(-1);
    for (int v = 0; v < 8; ++v) {
      if (!Interior(v)) continue;
      for (int i = 0; i < 3; ++i) {
        if (!Interior(v ^ (1 << i))) next[3 * v + i] = Partner(v, i);
      }
    }
    std::array<bool, 24> seen{};
    int polygon = 0;
    std::vector<int> cycle;
    for (int f = 0; f < 24; ++f) {
      if (next[f] < 0 || seen[f]) continue;
      cycle.clear();
      for (int c = f; !seen[c]; c = next[c]) {
        seen[c] = true;
        cycle.push_back(c);
      }
      Triangulate(cycle, polygon++);
    }
  }

 private:
  static Eigen::Vector3i Offset(int v) {
    return Eigen::Vector3i((v & 1) - 1, ((v >> 1) & 1) - 1, ((v >> 2) & 1) - 1);
  }
  [[nodiscard]] bool Interior(int v) const { return cell_[v]->interior; }
  // +1 when the exterior neighbour of face (v, i) lies towards +axis i.
  static int Sign(int v, int i) { return ((v >> i) & 1) ? -1 : 1; }

  // The face joined to face (v, i) across its edge that enters g when the face is traversed
  // counter-clockwise seen from the interior (its normal −sign·e_i). Following these links
  // walks the faces around g counter-clockwise seen from the interior side.
  [[nodiscard]] int Partner(int v, int i) const {
    const int u = (i + 1) % 3, w = (i + 2) % 3;
    // Edge directions from g along the face: +1 when the face lies on g's + side.
    const int su = ((v >> u) & 1) ? 1 : -1;
    const int sw = ((v >> w) & 1) ? 1 : -1;
    // (su e_u × sw e_w) · n with n = −sign e_i and e_u × e_w = e_i.
    const int sigma = su * sw * -Sign(v, i);
    // Incoming edge along w when sigma > 0 (it lies on the face's −su side along u), else
    // along u. Stepping across it from v flips that axis' bit.
    const int ta = sigma > 0 ? u : w;
    const int bt = 1 << ta, bi = 1 << i;
    if (!Interior(v ^ bt)) return 3 * v + ta;                  // convex fold, same cell
    if (!Interior(v ^ bt ^ bi)) return 3 * (v ^ bt) + i;       // flat
    return 3 * (v ^ bt ^ bi) + ta;                             // concave fold
  }

  // Global key and position of face f's vertex (its Fig 4.9 isosurface point).
  int Vertex(int f) {
    const int v = f / 3, i = f % 3;
    const int s = Sign(v, i);
    Eigen::Vector3i lower = win_.base() + g_ + Offset(v);
    if (s < 0) lower[i] -= 1;
    MeshVertexKey key;
    key.v = {lower.x(), lower.y(), lower.z(), i};
    auto [it, inserted] = local_.try_emplace(key, 0);
    if (!inserted) return it->second;
    const CellLeaf& in = *cell_[v];
    const CellLeaf& ex = *cell_[v ^ (1 << i)];
    const double res = win_.res();
    Eigen::Vector3d pos = (lower.cast<double>() + Eigen::Vector3d::Constant(0.5)) * res;
    pos[i] = (lower[i] + 1) * res;
    pos[i] += s * IsosurfaceOffsetM(in.p, ex.p, res, kIsosurfaceLimitFraction * res);
    return it->second = Push(key, pos, ex.observed);
  }

  int Push(const MeshVertexKey& key, const Eigen::Vector3d& pos, bool observed) {
    out_.vertex_keys.push_back(key);
    out_.vertex_positions.push_back(pos);
    out_.vertex_observed.push_back(observed ? 1 : 0);
    return static_cast<int>(out_.vertex_keys.size() - 1);
  }

  // Whether faces f and h (both touching g) share an edge, i.e. a second corner.
  [[nodiscard]] bool ShareEdge(int f, int h) const {
    auto corners = [&](int face) {
      const int v = face / 3, i = face % 3;
      Eigen::Vector3i lo = Offset(v);  // relative to g
      if (Sign(v, i) > 0) lo[i] += 1;  // the face plane
      std::array<Eigen::Vector3i, 4> c;
      const int u = (i + 1) % 3, w = (i + 2) % 3;
      for (int j = 0; j < 4; ++j) {
        c[j] = lo;
        c[j][u] += j & 1;
        c[j][w] += (j >> 1) & 1;
      }
      return c;
    };
    const auto a = corners(f), b = corners(h);
    int common = 0;
    for (const auto& x : a) {
      for (const auto& y : b) common += (x == y);
    }
    return common >= 2;
  }

  [[nodiscard]] bool Good(int a, int b, int c) const {
    const auto& p = out_.vertex_positions;
    const double area2 = (p[b] - p[a]).cross(p[c] - p[a]).norm();
    return area2 > 2e-4 * win_.res() * win_.res();
  }

  void Triangulate(const std::vector<int>& cycle, int polygon) {
    ++out_.polygons;
    const int m = static_cast<int>(cycle.size());
    std::vector<int> vs(m);
    for (int j = 0; j < m; ++j) vs[j] = Vertex(cycle[j]);
    auto& tris = out_.triangles;
    if (m == 3 && Good(vs[0], vs[1], vs[2])) {
      tris.emplace_back(vs[0], vs[1], vs[2]);
      return;
    }
    if (m == 4) {
      // A diagonal is a new edge; it is used by no other polygon when its two faces share
      // only the corner g (faces sharing an edge g–g' could meet again at g').
      for (int r = 0; r < 2; ++r) {
        const int a = vs[r], b = vs[r + 1], c = vs[r + 2], d = vs[(r + 3) % 4];
        if (ShareEdge(cycle[r], cycle[r + 2])) continue;
        if (!Good(a, b, c) || !Good(a, c, d)) continue;
        tris.emplace_back(a, b, c);
        tris.emplace_back(a, c, d);
        return;
      }
    }
    // Otherwise a fan around a vertex of its own at the polygon's mean.
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    bool observed = true;
    for (int x : vs) {
      mean += out_.vertex_positions[x];
      observed = observed && out_.vertex_observed[x];
    }
    mean /= m;
    const Eigen::Vector3i g = win_.base() + g_;
    MeshVertexKey key;
    key.v = {g.x(), g.y(), g.z(), 3 + polygon};
    const int c = Push(key, mean, observed);
    ++out_.centre_vertices;
    for (int j = 0; j < m; ++j) tris.emplace_back(c, vs[j], vs[(j + 1) % m]);
  }

  const LabelWindow& win_;
  ChunkMesh& out_;
  Eigen::Vector3i g_;
  std::array<const CellLeaf*, 8> cell_{};
  absl::flat_hash_map<MeshVertexKey, int, KeyHash> local_;
};

}  // namespace

absl::StatusOr<ChunkMesh> DualContourChunk(const ChunkNeighbourhood& hood) {
  // Only the low-side neighbours are read; the rest are not validated either.
  ChunkNeighbourhood low = hood;
  for (int dz = -1; dz <= 1; ++dz) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        if (dx > 0 || dy > 0 || dz > 0) low.tiles[ChunkNeighbourhood::Index(dx, dy, dz)] = nullptr;
      }
    }
  }
  absl::StatusOr<NeighbourhoodIndex> index = NeighbourhoodIndex::Build(low);
  if (!index.ok()) return index.status();
  ChunkMesh out;
  out.chunk = hood.chunk;
  const LabelWindow window(*index);
  if (!window.any_interior()) return out;
  CornerMesher mesher(window, out);
  const int n = window.n();
  for (int z = 0; z < n; ++z) {
    for (int y = 0; y < n; ++y) {
      for (int x = 0; x < n; ++x) mesher.Mesh(Eigen::Vector3i(x, y, z));
    }
  }
  return out;
}

ChunkMeshWelder::ChunkMeshWelder(int chunk_cells, Sink sink)
    : chunk_cells_(chunk_cells),
      sink_(std::move(sink)),
      front_(std::numeric_limits<int64_t>::min()) {}

absl::Status ChunkMeshWelder::Add(ChunkMesh chunk) {
  if (last_ && ChunkKeyLess()(chunk.chunk, *last_)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "dense mesh weld: chunk (", chunk.chunk.x(), ", ", chunk.chunk.y(), ", ", chunk.chunk.z(),
        ") comes after (", last_->x(), ", ", last_->y(), ", ", last_->z(), ")"));
  }
  if (!last_ || chunk.chunk.x() != last_->x()) {
    // No chunk from this column on has a key below its first cell minus the margin.
    if (absl::Status s = Advance(int64_t{chunk.chunk.x()} * chunk_cells_ - kMargin); !s.ok()) {
      return s;
    }
  }
  last_ = chunk.chunk;
  PendingChunk pc;
  pc.chunk = chunk.chunk;
  pc.min_key_x = std::numeric_limits<int32_t>::max();
  pc.max_key_x = std::numeric_limits<int32_t>::min();
  for (size_t i = 0; i < chunk.vertex_keys.size(); ++i) {
    const MeshVertexKey& key = chunk.vertex_keys[i];
    if (key.v[0] < front_) {
      return absl::InternalError(absl::StrCat(
          "dense mesh weld: chunk (", chunk.chunk.x(), ", ", chunk.chunk.y(), ", ", chunk.chunk.z(),
          ") has a vertex at x cell ", key.v[0], ", below the welded front at ", front_));
    }
    pc.min_key_x = std::min(pc.min_key_x, key.v[0]);
    pc.max_key_x = std::max(pc.max_key_x, key.v[0]);
    pending_.push_back(
        PendingVertex{key, chunk.vertex_positions[i].cast<float>(),
                      i < chunk.vertex_observed.size() ? chunk.vertex_observed[i] : uint8_t{0}});
  }
  pc.keys = std::move(chunk.vertex_keys);
  pc.triangles = std::move(chunk.triangles);
  chunks_.push_back(std::move(pc));
  return absl::OkStatus();
}

absl::Status ChunkMeshWelder::Advance(int64_t front) {
  // The pending vertices below the front, sorted by key; stable, so of a key given by several
  // chunks the first chunk's copy is kept (they agree anyway).
  auto below =
      std::stable_partition(pending_.begin(), pending_.end(),
                            [front](const PendingVertex& v) { return v.key.v[0] < front; });
  std::vector<PendingVertex> ready(std::make_move_iterator(pending_.begin()),
                                   std::make_move_iterator(below));
  pending_.erase(pending_.begin(), below);
  std::stable_sort(ready.begin(), ready.end(),
                   [](const PendingVertex& a, const PendingVertex& b) { return a.key < b.key; });
  const bool to_sink = sink_.vertices && sink_.triangles;
  std::vector<Eigen::Vector3f> positions;
  std::vector<uint8_t> observed;
  for (size_t i = 0; i < ready.size(); ++i) {
    if (i > 0 && ready[i].key == ready[i - 1].key) continue;
    welded_.emplace_back(ready[i].key, num_vertices_++);
    (to_sink ? positions : mesh_.vertices).push_back(ready[i].position);
    (to_sink ? observed : observed_).push_back(ready[i].observed);
  }
  if (to_sink && !positions.empty()) {
    if (absl::Status s = sink_.vertices(positions, observed); !s.ok()) return s;
  }
  front_ = front;
  // The chunks whose keys are all welded, in order.
  while (!chunks_.empty() && chunks_.front().max_key_x < front_) {
    const PendingChunk& c = chunks_.front();
    std::vector<int> index(c.keys.size());
    for (size_t i = 0; i < c.keys.size(); ++i) {
      auto it = std::lower_bound(welded_.begin(), welded_.end(), c.keys[i],
                                 [](const std::pair<MeshVertexKey, int>& e,
                                    const MeshVertexKey& k) { return e.first < k; });
      if (it == welded_.end() || !(it->first == c.keys[i])) {
        return absl::InternalError("dense mesh weld: a chunk's vertex was not welded");
      }
      index[i] = it->second;
    }
    std::vector<Eigen::Vector3i> triangles;
    std::vector<Eigen::Vector3i>& out = to_sink ? triangles : mesh_.triangles;
    for (const Eigen::Vector3i& t : c.triangles)
      out.emplace_back(index[t[0]], index[t[1]], index[t[2]]);
    if (to_sink) {
      if (absl::Status s = sink_.triangles(c.chunk, triangles); !s.ok()) return s;
    }
    chunks_.pop_front();
  }
  // Welded keys no pending chunk can name any more.
  int64_t needed = front_;
  for (const PendingChunk& c : chunks_) needed = std::min<int64_t>(needed, c.min_key_x);
  auto keep = std::lower_bound(
      welded_.begin(), welded_.end(), needed,
      [](const std::pair<MeshVertexKey, int>& e, int64_t x) { return e.first.v[0] < x; });
  welded_.erase(welded_.begin(), keep);
  return absl::OkStatus();
}

absl::StatusOr<TriangleMesh> ChunkMeshWelder::Finish(std::vector<uint8_t>* vertex_observed) {
  if (absl::Status s = Advance(std::numeric_limits<int64_t>::max()); !s.ok()) return s;
  if (!chunks_.empty()) return absl::InternalError("dense mesh weld: chunks left unwelded");
  if (vertex_observed != nullptr) *vertex_observed = std::move(observed_);
  TriangleMesh out = std::move(mesh_);
  *this = ChunkMeshWelder(chunk_cells_, std::move(sink_));
  return out;
}

std::vector<ChunkKey> DenseMeshChunks(std::span<const ChunkKey> tile_chunks) {
  std::vector<ChunkKey> out;
  out.reserve(tile_chunks.size() * 8);
  for (const ChunkKey& c : tile_chunks) {
    for (int j = 0; j < 8; ++j) out.push_back(c + ChunkKey(j & 1, (j >> 1) & 1, (j >> 2) & 1));
  }
  std::sort(out.begin(), out.end(), ChunkKeyLess());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace carvemap

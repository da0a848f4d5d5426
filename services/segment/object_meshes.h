// The objects of a building, one watertight mesh each (§5.6.2; docs/DESIGN.md §6 stage 8, §7
// mesh/objects.ply, mesh/objects/<id>.ply): the dense mesh (dual_contouring.h) of the object
// volume (segment_chunk.h) split into its connected pieces.
//
// Why components of the mesh and not of the leaves: dual contouring joins the faces of one
// 6-connected set of interior cells into one closed surface (dual_contouring.h), so the mesh's
// edge-connected components are exactly the objects' surfaces, found with one union-find over
// the triangles, without a second pass over the octree.
//
// Plain data; no files, no logging.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "absl/container/flat_hash_map.h"
#include "absl/status/statusor.h"
#include "services/segment/plan_volume.h"
#include "storage/ply_io.h"

namespace carvemap {

struct ObjectSplitOptions {
  // Pieces smaller than this are specks (noise on floors and walls), m³: while stacked pieces
  // are grouped (below) a speck joins the one object it overlaps most and never links two;
  // left alone it is dropped. A speck that joins an object widens its box (it is the evidence
  // of a leg or a rod the wedges carved away) but is left out of its mesh: most are single
  // cells made solid by one scan point, and meshed they made an object a cloud of tens to hundreds
  // of separate shells around its surfaces.
  double speck_volume_m3 = 0.001;
  // Objects smaller than this after grouping are dropped, m³. 5 litres (a 17 cm cube):
  // slivers of walls that a drifting path or sparse frames put inside the plan are 1–4
  // litres; measured on office2 (docs/BENCHMARKS.md), false objects 11 % → 7 % with rotation
  // drift and 10 % → 8 % at 10 Hz, with the same objects found as at 1 litre. Raising the
  // speck size instead lost objects: pieces of one chair stopped joining.
  double min_volume_m3 = 0.005;
  // Pieces whose bounding box is thinner than this on any axis are dropped too (one-cell films
  // where the carved walls bulge into a room past the plan's tolerance), m. 0 = keep.
  double min_thickness_m = 0;
  // Pieces whose top is within this of their room's ceiling and that are no taller than it are
  // the carved ceiling's unevenness (grazing views put it a cell or two low), not objects, m.
  double ceiling_film_m = 0.15;
  // Pieces touching the ceiling (as above) that are at most this deep on one horizontal side
  // and at least door_header_min_width_m long on the other are the wall over a doorway: the
  // plan's rooms run through the door, so §5.6's rule makes door headers objects (the dissertation
  // counts door frames as objects); users of a furniture list do not want them. m.
  double door_header_depth_m = 0.4;
  double door_header_min_width_m = 0.6;
  // Pieces stacked over each other are one object: footprints (xy boxes) that share at least
  // stack_overlap of the smaller one, and at most stack_gap_m between them vertically, on one
  // level. Why: furniture made of thin parts comes out of the carve in pieces along its
  // height (a shelf's boards, whose 2 cm side panels the wedges carve away; a table's top and
  // the lower parts of its legs), while neighbours standing side by side (a desk and its
  // chair) do not overlap. < 0: no grouping (the dissertation's one object per connected
  // component).
  double stack_gap_m = 0.5;
  double stack_overlap = 0.5;
  // Under localization drift a wall's scan points land up to a few σ of the path's position
  // error inside the room, and §5.6 makes the cells they fill objects: mostly specks, which
  // stacked over the desks and cabinets standing against the wall and took their boxes up to
  // 1.8 m too tall (docs/BENCHMARKS.md). A speck whose footprint lies within this of the plan's
  // walls (every corner) does not join an object below it, m; the merge sets 3 σ of the scan's
  // /path_cov. 0 = off. A piece that reaches its room's ceiling (ceiling_film_m) with its
  // footprint in that band is the wall itself, drifted into the room (a wall slab 0.4–0.6 m
  // deep where the plan's wall line runs through it), and is dropped: at the default drift it
  // made 8 of the office's 20 false objects, and no true object's piece is like it
  // (docs/BENCHMARKS.md). §5.6 keeps furniture up to the ceiling; a shelf that truly reaches it
  // and is no deeper than the band goes with the wall then.
  double wall_smear_m = 0;
};

struct SegmentedObject {
  int id = 0;                 // 0.. in output order
  int level = -1;             // the plan level holding the centre of its box (−1 none)
  int room = -1;              // the room under that centre (−1 none)
  Eigen::AlignedBox3d box;    // m: of its mesh and the specks grouped into it
  double volume_m3 = 0;       // enclosed volume of its mesh (divergence theorem)
  TriangleMesh mesh;          // watertight, counter-clockwise seen from outside (normals out)
};

struct ObjectSplitReport {
  uint64_t components = 0;     // closed surfaces found
  uint64_t dropped_small = 0;  // below min_volume_m3 or min_thickness_m (after grouping)
  uint64_t dropped_ceiling = 0;  // ceiling films and door headers
  uint64_t dropped_cavities = 0;  // inner surfaces of hollow objects (negative volume)
  uint64_t grouped = 0;  // pieces joined to a piece stacked over or under them
  uint64_t specks_unmeshed = 0;  // specks in a kept object's box, not in its mesh
  uint64_t specks_off_walls = 0;  // specks held off an object below them (wall_smear_m)
  uint64_t dropped_wall_smear = 0;  // pieces up to the ceiling within wall_smear_m of a wall
};

// The objects of a building, found as its object mesh streams past (StreamDenseMesh's order:
// chunk columns along x), so that memory holds the pieces still open, not the mesh. A piece
// (one closed surface) is finished once the stream is two columns past the last column that
// gave it a triangle: a dense mesh's triangles reach at most a few cells past their chunk, so
// no later triangle can share its vertices (checked: one that does is an Internal error).
// A finished piece that is kept (not a cavity, not a ceiling film, not a speck) goes to `sink` with
// its mesh, facing out of the object, its vertices in the order its triangles first use them, and
// its key: the index of its first triangle in the stream. Finish() groups the pieces' summaries as
// SplitObjects does; an object's mesh is its pieces' meshes appended in the order of its keys.
//
// Memory: the open pieces' triangles (~16 B each) and vertices (~32 B), one summary per kept
// piece (~100 B), and one bit per vertex of the stream.
struct ObjectLayout {
  std::vector<SegmentedObject> objects;       // ids 0.. in order; meshes empty
  std::vector<std::vector<uint64_t>> pieces;  // per object: its pieces' keys, ascending
  ObjectSplitReport report;
};

class ObjectSplitter {
 public:
  using PieceSink = std::function<absl::Status(uint64_t key, const TriangleMesh& mesh)>;

  ObjectSplitter(const PlanVolume& plan, const ObjectSplitOptions& options, PieceSink sink);
  ObjectSplitter(const ObjectSplitter&) = delete;
  ObjectSplitter& operator=(const ObjectSplitter&) = delete;

  // The stream's next vertices (dual contouring's orientation: facing the free space).
  void AddVertices(std::span<const Eigen::Vector3f> vertices);
  // The next triangles, of a chunk in chunk column `column` (its x); columns never decrease.
  // InvalidArgument for an index not given yet or a column going back; Internal for a triangle
  // that joins a piece already finished; the sink's error.
  [[nodiscard]] absl::Status AddTriangles(int64_t column,
                                          std::span<const Eigen::Vector3i> triangles);
  // Finishes the pieces still open and groups them (stack_gap_m, min_volume_m3, ...).
  [[nodiscard]] absl::StatusOr<ObjectLayout> Finish();

  // Triangles of the pieces not finished yet.
  [[nodiscard]] size_t open_triangles() const { return open_triangles_; }

 private:
  struct Vertex {
    Eigen::Vector3f position;
    int parent;  // union-find over the open vertices; a root holds its piece's triangles
  };
  struct OpenPiece {
    std::vector<std::pair<uint64_t, Eigen::Vector3i>> triangles;  // (index in the stream, t)
    int64_t last_column = 0;
  };
  int Find(int v);
  [[nodiscard]] absl::Status FinishPieces(int64_t before_column);
  [[nodiscard]] absl::Status FinishPiece(OpenPiece piece);

  const PlanVolume& plan_;
  ObjectSplitOptions options_;
  PieceSink sink_;
  absl::flat_hash_map<int, Vertex> vertices_;  // given and not in a finished piece
  absl::flat_hash_map<int, OpenPiece> open_;   // by root vertex
  std::vector<bool> finished_vertex_;          // per vertex of the stream
  int64_t column_ = std::numeric_limits<int64_t>::min();
  uint64_t next_triangle_ = 0;
  size_t open_triangles_ = 0;
  std::vector<std::pair<uint64_t, SegmentedObject>> summaries_;  // kept pieces, by key
  ObjectSplitReport report_;
};

// `object_mesh`: dual contouring of the object volume, counter-clockwise seen from the free
// space (normals into the objects, as dual_contouring.h makes them). Objects are ordered by
// level, then by the min corner of their box (x, y, z), so ids are deterministic. An inner
// surface (a free cavity enclosed in an object) is dropped: its object stays watertight, filled.
// Stacked pieces (options.stack_gap_m) are then joined: such an object's mesh is several closed
// surfaces, each watertight; specks joined to it are in its box, not its mesh. ObjectSplitter over
// the whole mesh at once, held in memory.
[[nodiscard]] std::vector<SegmentedObject> SplitObjects(const TriangleMesh& object_mesh,
                                                        const PlanVolume& plan,
                                                        const ObjectSplitOptions& options,
                                                        ObjectSplitReport* report = nullptr);

}  // namespace carvemap

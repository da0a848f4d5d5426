// Planar meshing on a real tiles directory (§4.2.4, §4.3.3): boundary faces, planar
// regions, planar mesh and dense mesh of `carvemap run`'s tiles (or the merge's segmented
// building tiles), with the counts and CPU seconds of each stage. For docs/BENCHMARKS.md and
// for tuning on kept carves without re-running the whole merge.
//
//   planar_mesh_bench TILES_DIR [--mesh-growth] [--no-dense] [--regions-only] [--out DIR]
//                     [--gt GT_DIR] [--max-displacement CELLS] [--chain-tolerance CELLS]
//                     [--untangle-edge CELLS] [--untangle-move CELLS]
//
// --max-displacement sets PlanarMeshOptions::max_displacement_cells (eq 4.9's clamp),
// --chain-tolerance its chain_tolerance_cells (how far a chain vertex may lie off the segment
// that replaces it), --untangle-edge and --untangle-move its untangle_edge_cells and
// untangle_move_cells (0 and 0: the self-intersections are not untangled).
// --regions-only stops after the regions, so that a heap profiler's peak is theirs.
// --mesh-growth fits the regions as the merge does for mesh/building.ply
// (PlanarRegionOptions::mesh_growth); without it, as for the levels and floor plans.
// --out writes DIR/building.ply (face property `region`) and DIR/dense.ply. --gt (a simulated
// building's gt/) splits the faces by what they lie on (building surfaces, objects, neither:
// the closure against unobserved space) and reports how whole the regions of each are, and
// (with the dense mesh) the wall cover of the planar mesh as object_segmentation_test measures
// it on building.ply: points on the true walls within 20 cm of the dense mesh, and the share
// of them within 5 / 10 cm of the planar mesh.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <string>
#include <vector>

#include "services/merge/dense_mesh.h"
#include "services/merge/tile_set.h"
#include "services/mesh/mesh_checks.h"
#include "services/mesh/planar_mesh.h"
#include "services/mesh/planar_regions.h"
#include "services/mesh/self_intersections.h"
#include "services/system/process_memory.h"
#include "storage/ply_io.h"
#include "tests/support/truth_distance.h"

namespace {

double CpuSeconds() { return double(std::clock()) / CLOCKS_PER_SEC; }

// What the merge's memory budget is sized by: the resident memory after a stage and the
// stage's own peak. The peak (VmHWM) is reset after each print ("5" to clear_refs,
// proc(5)), so each stage's peak is its own.
void PrintMemory(const char* after) {
  const carvemap::ProcessStatus m = carvemap::ReadProcessStatus();
  std::printf("memory after %s: resident %.0f MiB, peak in the stage %.0f MiB\n", after,
              double(m.resident_bytes) / (1 << 20), double(m.peak_resident_bytes) / (1 << 20));
  std::fflush(stdout);
  std::ofstream("/proc/self/clear_refs") << "5";
}

}  // namespace

int main(int argc, char** argv) {
  using namespace carvemap;
  if (argc < 2) {
    std::fprintf(stderr,
                 "usage: %s TILES_DIR [--mesh-growth] [--no-dense] [--regions-only] [--out DIR] "
                 "[--gt GT_DIR] [--max-displacement CELLS] [--chain-tolerance CELLS]\n",
                 argv[0]);
    return 2;
  }
  const std::string dir = argv[1];
  bool dense = true;
  bool mesh = true;  // --regions-only: stop after the regions (to profile them alone)
  std::string out, gt;
  PlanarRegionOptions region_options;
  PlanarMeshOptions mesh_options;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--mesh-growth") {
      region_options.mesh_growth = true;
    } else if (a == "--no-dense") {
      dense = false;
    } else if (a == "--regions-only") {
      mesh = false;
      dense = false;
    } else if (a == "--out" && i + 1 < argc) {
      out = argv[++i];
    } else if (a == "--gt" && i + 1 < argc) {
      gt = argv[++i];
    } else if (a == "--max-displacement" && i + 1 < argc) {
      mesh_options.max_displacement_cells = std::atof(argv[++i]);
    } else if (a == "--chain-tolerance" && i + 1 < argc) {
      mesh_options.chain_tolerance_cells = std::atof(argv[++i]);
    } else if (a == "--untangle-edge" && i + 1 < argc) {
      mesh_options.untangle_edge_cells = std::atof(argv[++i]);
    } else if (a == "--untangle-move" && i + 1 < argc) {
      mesh_options.untangle_move_cells = std::atof(argv[++i]);
    } else {
      std::fprintf(stderr, "%s: unknown argument %s\n", argv[0], a.c_str());
      return 2;
    }
  }
  absl::StatusOr<std::unique_ptr<TileSet>> tiles = TileSet::Open(dir, 0, uint64_t{256} << 20);
  if (!tiles.ok()) {
    std::fprintf(stderr, "%s\n", std::string(tiles.status().message()).c_str());
    return 1;
  }
  const OctreeGrid grid = (*tiles)->grid();
  double t = CpuSeconds();
  absl::StatusOr<std::vector<BoundaryFace>> faces = CollectBoundaryFaces(**tiles);
  if (!faces.ok()) {
    std::fprintf(stderr, "faces: %s\n", std::string(faces.status().message()).c_str());
    return 1;
  }
  const double faces_s = CpuSeconds() - t;
  std::printf("tiles %zu, resolution %.4f m; faces %zu in %.2f s cpu\n", (*tiles)->chunks().size(),
              grid.resolution_m(), faces->size(), faces_s);
  (*tiles)->ReleaseCache();  // as the merge does before the regions
  PrintMemory("faces");
  t = CpuSeconds();
  absl::StatusOr<PlanarRegionSet> regions = FitPlanarRegions(*faces, grid, region_options);
  if (!regions.ok()) {
    std::fprintf(stderr, "regions: %s\n", std::string(regions.status().message()).c_str());
    return 1;
  }
  const double regions_s = CpuSeconds() - t;
  PrintMemory("regions");
  // Region sizes: how much of the surface lies in regions of at least 0.25 / 1 m².
  double total = 0, big1 = 0, big025 = 0;
  size_t single = 0;
  for (const PlanarRegion& r : regions->regions) {
    total += r.area_m2;
    if (r.area_m2 >= 1.0) big1 += r.area_m2;
    if (r.area_m2 >= 0.25) big025 += r.area_m2;
    if (r.faces.size() == 1) ++single;
  }
  std::printf("faces' area %.1f m2\n", total);
  std::printf(
      "regions (%s growth): flood fill %zu, grown %zu, relaxed %zu (%zu of one face) in %.2f s "
      "cpu\n",
      region_options.mesh_growth ? "mesh" : "default", regions->flood_fill_groups,
      regions->grown_regions, regions->regions.size(), single, regions_s);
  std::printf("area in regions >= 1 m2: %.1f %%, >= 0.25 m2: %.1f %%\n", 100 * big1 / total,
              100 * big025 / total);
  if (!gt.empty()) {
    // Per face: on the building (within 5 cm of gt/surfaces.ply), on an object (objects.ply),
    // or neither; exterior observed or not. Area of each class by the size of its region.
    testing::TruthDistance building(testing::ReadPlyTriangles(gt + "/surfaces.ply"), 0.25, 0.3);
    testing::TruthDistance objects(testing::ReadPlyTriangles(gt + "/objects.ply"), 0.25, 0.3);
    const char* names[3] = {"building", "objects", "neither"};
    double area[3][2][4] = {};  // class, observed, region size class
    for (size_t f = 0; f < faces->size(); ++f) {
      const BoundaryFace& face = (*faces)[f];
      const double db = building(face.isosurface()), dob = objects(face.isosurface());
      const int cls = db <= 0.05 && db <= dob ? 0 : dob <= 0.05 ? 1 : 2;
      const bool observed = face.exterior_observed;
      const double ra = regions->regions[regions->face_region[f]].area_m2;
      const int size = ra >= 1 ? 0 : ra >= 0.25 ? 1 : ra >= 0.05 ? 2 : 3;
      area[cls][observed][size] += face.area_m2();
    }
    for (int c = 0; c < 3; ++c) {
      for (int o = 1; o >= 0; --o) {
        double sum = 0;
        for (double a : area[c][o]) sum += a;
        std::printf(
            "  %-8s %-10s %7.1f m2: in regions >= 1 m2 %5.1f %%, 0.25-1 %5.1f %%, "
            "0.05-0.25 %5.1f %%, < 0.05 %5.1f %%\n",
            names[c], o ? "observed" : "unobserved", sum, 100 * area[c][o][0] / sum,
            100 * area[c][o][1] / sum, 100 * area[c][o][2] / sum, 100 * area[c][o][3] / sum);
      }
    }
  }
  if (!mesh) return 0;
  t = CpuSeconds();
  absl::StatusOr<PlanarMesh> planar = BuildPlanarMesh(*faces, *regions, grid, mesh_options);
  const double planar_s = CpuSeconds() - t;
  PrintMemory("planar mesh");
  size_t planar_triangles = 0;
  if (!planar.ok()) {
    std::printf("planar mesh FAILED in %.2f s cpu: %s\n", planar_s,
                std::string(planar.status().message()).c_str());
  } else {
    planar_triangles = planar->mesh.triangles.size();
    std::printf("planar mesh %zu triangles, %zu vertices in %.2f s cpu: %s\n", planar_triangles,
                planar->mesh.vertices.size(), planar_s, CheckMesh(planar->mesh).ToString().c_str());
    if (!out.empty()) {
      if (absl::Status st =
              WritePly(out + "/building.ply", planar->mesh, &planar->triangle_region, "region");
          !st.ok()) {
        std::fprintf(stderr, "%s\n", std::string(st.message()).c_str());
        return 1;
      }
    }
    t = CpuSeconds();
    const SelfIntersections crossings = CountSelfIntersections(planar->mesh);
    std::printf(
        "planar mesh self-intersections: %llu pairs (%llu triangles not tested) in %.2f s cpu\n",
        static_cast<unsigned long long>(crossings.pairs),
        static_cast<unsigned long long>(crossings.unchecked), CpuSeconds() - t);
    std::printf(
        "regions not re-triangulated (their simplified triangles kept): %d, %zu triangles; "
        "%d of them would have met more lifted onto their plane\n",
        planar->regions_not_retriangulated, planar->triangles_not_retriangulated,
        planar->regions_kept_off_plane);
    std::printf("untangled: %d vertices collapsed, %d moved\n", planar->untangle_collapses,
                planar->untangle_moves);
    // Triangles by the size of their region.
    size_t by_size[4] = {};
    for (int r : planar->triangle_region) {
      const double ra = regions->regions[r].area_m2;
      ++by_size[ra >= 1 ? 0 : ra >= 0.25 ? 1 : ra >= 0.05 ? 2 : 3];
    }
    std::printf("  triangles in regions >= 1 m2: %zu, 0.25-1: %zu, 0.05-0.25: %zu, < 0.05: %zu\n",
                by_size[0], by_size[1], by_size[2], by_size[3]);
  }
  if (dense) {
    t = CpuSeconds();
    absl::StatusOr<DenseMeshResult> d = BuildDenseMesh(**tiles);
    if (!d.ok()) {
      std::fprintf(stderr, "dense: %s\n", std::string(d.status().message()).c_str());
      return 1;
    }
    const double dense_s = CpuSeconds() - t;
    PrintMemory("dense mesh");  // before the check, whose edge map is larger than the weld
    std::printf("dense mesh %zu triangles in %.2f s cpu: %s\n", d->mesh.triangles.size(),
                dense_s, CheckMesh(d->mesh).ToString().c_str());
    if (!gt.empty() && planar.ok()) {
      const testing::TruthDistance to_planar(testing::MeshTriangles(planar->mesh), 0.25, 0.2);
      const testing::TruthDistance to_dense(testing::MeshTriangles(d->mesh), 0.25, 0.2);
      size_t wall_points = 0, covered5 = 0, covered10 = 0, dense5 = 0;
      for (const Eigen::Vector3d& p :
           testing::WallPoints(testing::ReadPlyTriangles(gt + "/surfaces.ply"), 0.1)) {
        const double dd = to_dense(p);
        if (dd >= 0.2) continue;
        ++wall_points;
        dense5 += dd <= 0.05;
        const double dp = to_planar(p);
        covered5 += dp <= 0.05;
        covered10 += dp <= 0.10;
      }
      std::printf("wall cover of the planar mesh: within 5 cm %.1f %%, 10 cm %.1f %% of %zu "
                  "true wall points (the dense mesh: within 5 cm %.1f %%)\n",
                  100.0 * double(covered5) / double(wall_points),
                  100.0 * double(covered10) / double(wall_points), wall_points,
                  100.0 * double(dense5) / double(wall_points));
    }
    if (planar_triangles > 0) {
      std::printf("planar / dense = %.2f %%\n",
                  100.0 * double(planar_triangles) / double(d->mesh.triangles.size()));
    }
    if (!out.empty()) {
      if (absl::Status st = WritePly(out + "/dense.ply", d->mesh); !st.ok()) {
        std::fprintf(stderr, "%s\n", std::string(st.message()).c_str());
        return 1;
      }
    }
  }
  return planar.ok() ? 0 : 1;
}

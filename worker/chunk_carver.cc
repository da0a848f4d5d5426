// CarveChunkToTile: the worker's task (DESIGN §5). Deterministic by construction: the wedges
// are carved in payload order (float sums depend on it), and ToTile/WriteTile emit leaves in
// canonical order whatever the hash maps' iteration order.
#include "worker/chunk_carver.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <system_error>
#include <vector>

#include "absl/strings/str_cat.h"
#include "storage/tile_store.h"
#include "storage/wedge_codec.h"
#include "worker/chunk_octree.h"

namespace carvemap {
namespace {

std::string ChunkName(const ChunkKey& c) { return absl::StrCat(c.x(), ",", c.y(), ",", c.z()); }

absl::Status Prefixed(const ChunkKey& chunk, const absl::Status& s) {
  return absl::Status(s.code(),
                      absl::StrCat("carve chunk (", ChunkName(chunk), "): ", s.message()));
}

}  // namespace

absl::StatusOr<CarveChunkResult> CarveChunkToTile(const CarveChunkRequest& request) {
  const auto t0 = std::chrono::steady_clock::now();
  const ChunkKey& chunk = request.chunk;
  if (request.grid.chunk_depth < kMinChunkDepth || request.grid.chunk_depth > kMaxChunkDepth) {
    return Prefixed(chunk, absl::InvalidArgumentError(absl::StrCat(
                               "chunk depth ", request.grid.chunk_depth, " outside [",
                               kMinChunkDepth, ", ", kMaxChunkDepth, "]")));
  }
  // The ingest binned wedges with its sigmas; the octree carves hulls of kWedgeHullSigmas. A
  // mismatch would carve parts of wedges into chunks that never received them (seams).
  if (std::abs(request.sigmas - kWedgeHullSigmas) > 1e-9) {
    return Prefixed(chunk, absl::InvalidArgumentError(absl::StrCat(
                               "sigmas ", request.sigmas, " differs from the carver's ",
                               kWedgeHullSigmas)));
  }
  if (request.tiles_dir.empty()) {
    return Prefixed(chunk, absl::InvalidArgumentError("no tiles directory"));
  }
  absl::StatusOr<IndexedWedges> wedges = DecodeWedgePayload(request.wedge_payload);
  if (!wedges.ok()) return Prefixed(chunk, wedges.status());

  ChunkOctree tree(request.grid, chunk);
  if (request.region != nullptr) tree.RestrictTo(*request.region);
  tree.SetEvaluation(request.evaluation);
  if (request.progress) tree.SetProgress(request.progress);
  // The whole payload in one call: eq 4.8's set of rays per leaf is exact within a call.
  if (absl::Status s = tree.CarveIndexed(*wedges); !s.ok()) return Prefixed(chunk, s);
  tree.Simplify();

  std::error_code ec;
  std::filesystem::create_directories(request.tiles_dir, ec);
  if (ec) {
    return Prefixed(chunk, absl::UnavailableError(absl::StrCat(
                               "cannot create ", request.tiles_dir, ": ", ec.message())));
  }
  const TileData tile = tree.ToTile(request.job_id);
  absl::StatusOr<std::string> path = WriteTile(request.tiles_dir, tile);
  if (!path.ok()) return Prefixed(chunk, path.status());

  CarveChunkResult result;
  result.tile_path = *path;
  result.tile_bytes = std::filesystem::file_size(*path, ec);
  if (ec) result.tile_bytes = 0;
  result.wedges = tree.num_wedges();
  result.leaf_updates = tree.num_leaf_updates();
  result.leaf_touches = tree.num_leaf_touches();
  result.leaves = tile.leaves.size();
  result.elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return result;
}

}  // namespace carvemap

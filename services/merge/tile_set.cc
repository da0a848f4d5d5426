#include "services/merge/tile_set.h"

#include <algorithm>
#include <charconv>
#include <filesystem>
#include <optional>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "services/merge/parallel_for.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

bool ParseInt(std::string_view s, int& out) {
  if (s.empty()) return false;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && ptr == s.data() + s.size();
}

uint64_t TileBytes(const TileData& tile) {
  return sizeof(TileData) + tile.leaves.capacity() * sizeof(TileLeaf) +
         tile.params.job_id.capacity();
}

}  // namespace

bool ParseTileFileName(const std::string& name, ChunkKey& chunk) {
  std::string_view s(name);
  if (!s.starts_with("c_") || !s.ends_with(".h5")) return false;
  s = s.substr(2, s.size() - 5);
  int v[3];
  for (int i = 0; i < 3; ++i) {
    const size_t cut = i < 2 ? s.find('_') : s.size();
    if (cut == std::string_view::npos || !ParseInt(s.substr(0, cut), v[i])) return false;
    s = i < 2 ? s.substr(cut + 1) : std::string_view();
  }
  chunk = ChunkKey(v[0], v[1], v[2]);
  // Only the canonical spelling, so one chunk never has two files.
  return TileFileName(chunk) == name;
}

absl::StatusOr<std::unique_ptr<TileSet>> TileSet::Open(const std::string& tiles_dir,
                                                       double resolution_m,
                                                       uint64_t cache_budget_bytes) {
  std::error_code ec;
  if (!fs::exists(tiles_dir, ec)) {
    return absl::NotFoundError(absl::StrCat(tiles_dir, ": no such tiles directory"));
  }
  if (!fs::is_directory(tiles_dir, ec)) {
    return absl::InvalidArgumentError(absl::StrCat(tiles_dir, ": not a directory"));
  }
  std::vector<ChunkKey> chunks;
  fs::directory_iterator it(tiles_dir, ec), end;
  if (ec) return absl::UnavailableError(absl::StrCat(tiles_dir, ": ", ec.message()));
  for (; it != end; it.increment(ec)) {
    if (ec) return absl::UnavailableError(absl::StrCat(tiles_dir, ": ", ec.message()));
    ChunkKey key;
    if (it->is_regular_file(ec) && ParseTileFileName(it->path().filename().string(), key)) {
      chunks.push_back(key);
    }
  }
  std::sort(chunks.begin(), chunks.end(), ChunkKeyLess());

  OctreeGrid grid;
  if (resolution_m > 0) {
    absl::StatusOr<OctreeGrid> g = OctreeGrid::FromResolution(resolution_m);
    if (!g.ok()) return g.status();
    grid = *g;
  }
  std::unique_ptr<TileSet> set(
      new TileSet(tiles_dir, grid, std::move(chunks), cache_budget_bytes));
  if (resolution_m <= 0 && !set->chunks_.empty()) {
    // The first tile tells the grid; it stays cached, so learning it costs no extra read.
    const ChunkKey first = set->chunks_.front();
    absl::StatusOr<TileData> tile = ReadTile(set->PathOf(first));
    if (!tile.ok()) return tile.status();
    set->grid_ = tile->grid;
    ++set->tile_reads_;
    if (absl::Status s = set->Insert(first, *std::move(tile)); !s.ok()) return s;
  }
  return set;
}

bool TileSet::Contains(const ChunkKey& chunk) const {
  return std::binary_search(chunks_.begin(), chunks_.end(), chunk, ChunkKeyLess());
}

std::string TileSet::PathOf(const ChunkKey& chunk) const {
  return (fs::path(dir_) / TileFileName(chunk)).string();
}

absl::StatusOr<std::shared_ptr<const TileData>> TileSet::Get(const ChunkKey& chunk) {
  if (auto it = cache_.find(chunk); it != cache_.end()) {
    lru_.splice(lru_.begin(), lru_, it->second.lru_it);
    return it->second.tile;
  }
  const std::string path = PathOf(chunk);
  if (!Contains(chunk)) return absl::NotFoundError(absl::StrCat(path, ": no such tile"));
  ++tile_reads_;
  absl::StatusOr<TileData> tile = ReadTile(path);
  if (!tile.ok()) return tile.status();
  if (absl::Status s = Insert(chunk, *std::move(tile)); !s.ok()) return s;
  return cache_.at(chunk).tile;
}

absl::Status TileSet::Prefetch(std::span<const ChunkKey> chunks, int threads) {
  std::vector<ChunkKey> missing;
  for (const ChunkKey& c : chunks) {
    if (Contains(c) && !cache_.contains(c) &&
        std::find(missing.begin(), missing.end(), c) == missing.end()) {
      missing.push_back(c);
    }
  }
  std::vector<absl::StatusOr<RawTile>> raw;
  raw.reserve(missing.size());
  for (const ChunkKey& c : missing) {
    raw.push_back(ReadRawTile(PathOf(c)));
    if (!raw.back().ok()) return raw.back().status();
  }
  std::vector<std::optional<absl::StatusOr<TileData>>> decoded(missing.size());
  ParallelFor(missing.size(), threads,
              [&](size_t k) { decoded[k].emplace(DecodeTile(*std::move(raw[k]))); });
  for (size_t k = 0; k < missing.size(); ++k) {
    if (!decoded[k]->ok()) return decoded[k]->status();
    ++tile_reads_;
    if (absl::Status s = Insert(missing[k], **std::move(decoded[k])); !s.ok()) return s;
  }
  return absl::OkStatus();
}

void TileSet::ReleaseCache() {
  cache_.clear();
  lru_.clear();
  cached_bytes_ = 0;
}

absl::Status TileSet::Insert(const ChunkKey& chunk, TileData tile) {
  const std::string path = PathOf(chunk);
  if (tile.chunk != chunk) {
    return absl::DataLossError(absl::StrCat(path, ": holds chunk (", tile.chunk.x(), ", ",
                                            tile.chunk.y(), ", ", tile.chunk.z(),
                                            "), not the one its name gives"));
  }
  if (tile.grid.chunk_depth != grid_.chunk_depth) {
    return absl::InvalidArgumentError(absl::StrCat(
        path, ": resolution ", tile.grid.resolution_m(), " m, but the merge uses ",
        grid_.resolution_m(), " m"));
  }
  auto shared = std::make_shared<const TileData>(std::move(tile));
  const uint64_t bytes = TileBytes(*shared);
  // Evict before inserting; the newest tile always stays, whatever the budget.
  while (!lru_.empty() && cached_bytes_ + bytes > budget_) {
    auto victim = cache_.find(lru_.back());
    cached_bytes_ -= victim->second.bytes;
    cache_.erase(victim);
    lru_.pop_back();
  }
  lru_.push_front(chunk);
  cache_.emplace(chunk, Entry{shared, bytes, lru_.begin()});
  cached_bytes_ += bytes;
  return absl::OkStatus();
}

int64_t FindLeaf(const TileData& tile, const Eigen::Vector3i& local) {
  const int k = tile.grid.chunk_depth;
  const uint64_t cell = MortonCode(local);
  auto first_cell = [k](const TileLeaf& l) {
    return MortonCode(l.node.local) << (3 * (k - l.node.depth));
  };
  // Rows are in canonical order (TILE_FORMAT.md): sorted by first cell and non-overlapping, so
  // the only candidate is the last row starting at or before `cell`.
  auto it = std::upper_bound(
      tile.leaves.begin(), tile.leaves.end(), cell,
      [&](uint64_t c, const TileLeaf& l) { return c < first_cell(l); });
  if (it == tile.leaves.begin()) return -1;
  --it;
  const uint64_t span = uint64_t{1} << (3 * (k - it->node.depth));
  if (cell >= first_cell(*it) + span) return -1;
  return it - tile.leaves.begin();
}

absl::StatusOr<LeafQuery> TileSet::Query(const Eigen::Vector3d& x_world) {
  const LeafKey leaf = LeafOf(grid_, x_world);
  LeafQuery q;
  q.chunk = ChunkOfLeaf(grid_, leaf);
  if (!Contains(q.chunk)) return q;
  absl::StatusOr<std::shared_ptr<const TileData>> tile = Get(q.chunk);
  if (!tile.ok()) return tile.status();
  const Eigen::Vector3i local = leaf - q.chunk * grid_.leaves_per_side();
  const int64_t i = FindLeaf(**tile, local);
  if (i < 0) return q;
  q.stored = true;
  q.node = (*tile)->leaves[i].node;
  q.stats = (*tile)->leaves[i].stats;
  return q;
}

}  // namespace carvemap

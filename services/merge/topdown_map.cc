#include "services/merge/topdown_map.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "storage/atomic_file.h"

namespace carvemap {
namespace {

nlohmann::json OrNull(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); }

}  // namespace

TopdownMap::TopdownMap(const OctreeGrid& grid, const std::vector<ChunkKey>& chunks,
                       const TopdownZRange& z_range, bool occupancy)
    : grid_(grid), z_range_(z_range) {
  geometry_.resolution_m = grid.resolution_m();
  if (chunks.empty()) return;
  int min_x = INT_MAX, min_y = INT_MAX, max_x = INT_MIN, max_y = INT_MIN;
  for (const ChunkKey& c : chunks) {
    min_x = std::min(min_x, c.x());
    min_y = std::min(min_y, c.y());
    max_x = std::max(max_x, c.x());
    max_y = std::max(max_y, c.y());
  }
  const int64_t n = grid.leaves_per_side();
  min_leaf_x_ = int64_t{min_x} * n;
  min_leaf_y_ = int64_t{min_y} * n;
  geometry_.origin_x_m = min_x * kChunkSizeM;
  geometry_.origin_y_m = min_y * kChunkSizeM;
  geometry_.width = static_cast<int>((int64_t{max_x} - min_x + 1) * n);
  geometry_.height = static_cast<int>((int64_t{max_y} - min_y + 1) * n);
  height_m_.assign(size_t(geometry_.width) * geometry_.height, 0.0f);
  if (occupancy) {
    observed_m_.assign(height_m_.size(), 0.0f);
    solid_m_.assign(height_m_.size(), 0.0f);
  }
}

absl::Status TopdownMap::AddTile(const TileData& tile) {
  const int k = grid_.chunk_depth;
  const int64_t n = grid_.leaves_per_side();
  const int64_t chunk_col = int64_t{tile.chunk.x()} * n - min_leaf_x_;
  const int64_t chunk_row_from_bottom = int64_t{tile.chunk.y()} * n - min_leaf_y_;
  if (chunk_col < 0 || chunk_row_from_bottom < 0 || chunk_col + n > geometry_.width ||
      chunk_row_from_bottom + n > geometry_.height) {
    return absl::InvalidArgumentError(absl::StrCat("topdown map: chunk (", tile.chunk.x(), ", ",
                                                   tile.chunk.y(), ", ", tile.chunk.z(),
                                                   ") outside the map's footprint"));
  }
  const double res = grid_.resolution_m();
  const double lo = z_range_.z_lo_m, hi = z_range_.z_hi_m;
  const double chunk_z0 = tile.chunk.z() * kChunkSizeM;
  // Written so that a NaN bound (an empty range) skips the tile too.
  if (!(chunk_z0 < hi && chunk_z0 + kChunkSizeM > lo)) return absl::OkStatus();
  const bool whole_chunk = lo <= chunk_z0 && chunk_z0 + kChunkSizeM <= hi;
  for (const TileLeaf& leaf : tile.leaves) {
    if (!leaf.stats.observed()) continue;
    const int side = 1 << (k - leaf.node.depth);  // in finest columns
    // §5.4: each node crossed by the column adds its probability of interior times its height
    // (within the z range: the part of the node inside it, so a level's map sums the levels'
    // open heights).
    double height = side * res;
    if (!whole_chunk) {
      const double z0 = chunk_z0 + double(leaf.node.local.z()) * side * res;
      height = std::min(z0 + side * res, hi) - std::max(z0, lo);
      if (!(height > 0)) continue;
    }
    const float add = static_cast<float>(leaf.stats.p() * height);
    const float solid = leaf.stats.interior() ? 0.0f : static_cast<float>(height);
    const int64_t col0 = chunk_col + int64_t{leaf.node.local.x()} * side;
    const int64_t up0 = chunk_row_from_bottom + int64_t{leaf.node.local.y()} * side;
    for (int dy = 0; dy < side; ++dy) {
      const int64_t row = geometry_.height - 1 - (up0 + dy);
      const size_t at = size_t(row * geometry_.width + col0);
      float* line = height_m_.data() + at;
      for (int dx = 0; dx < side; ++dx) line[dx] += add;
      if (observed_m_.empty()) continue;
      for (int dx = 0; dx < side; ++dx) {
        observed_m_[at + dx] += static_cast<float>(height);
        solid_m_[at + dx] += solid;
      }
    }
  }
  return absl::OkStatus();
}

float TopdownMap::max_open_height_m() const {
  return height_m_.empty() ? 0.0f : *std::max_element(height_m_.begin(), height_m_.end());
}

Image<uint8_t> TopdownMap::ToGray8(double max_height_m) const {
  Image<uint8_t> image;
  image.width = geometry_.width;
  image.height = geometry_.height;
  image.pixels.resize(height_m_.size());
  for (size_t i = 0; i < height_m_.size(); ++i) {
    const double h = std::clamp(double(height_m_[i]), 0.0, max_height_m);
    image.pixels[i] = static_cast<uint8_t>(std::lround(255.0 * h / max_height_m));
  }
  return image;
}

absl::Status TopdownMap::Write(const std::string& png_path, const std::string& json_path,
                               double max_height_m, int level) const {
  if (geometry_.width == 0 || geometry_.height == 0) {
    // libpng cannot write an empty image; an empty job has no map, and its sidecar says so.
  } else if (absl::Status s = WritePngGray8(png_path, ToGray8(max_height_m)); !s.ok()) {
    return s;
  }
  nlohmann::json j = {
      {"format", "carvemap-topdown"},
      {"version", 1},
      {"level", level},
      {"z_range", z_range_.all() ? nlohmann::json("all")
                                 : nlohmann::json::array({OrNull(z_range_.z_lo_m),
                                                          OrNull(z_range_.z_hi_m)})},
      {"quantity",
       "expected open height (m): sum over observed octree leaves in the column of "
       "p(interior) x leaf height (Turner 2015, §5.4)"},
      {"image", geometry_.width > 0 && geometry_.height > 0
                    ? std::filesystem::path(png_path).filename().string()
                    : std::string()},
      {"width", geometry_.width},
      {"height", geometry_.height},
      {"resolution_m", geometry_.resolution_m},
      {"origin_m", {geometry_.origin_x_m, geometry_.origin_y_m}},
      {"pixel_to_world",
       "x = origin_x + (col + 0.5) * res, y = origin_y + (height - 1 - row + 0.5) * res "
       "(pixel centres, lower-left origin)"},
      {"gray_scale", {{"gray_0_m", 0.0}, {"gray_255_m", max_height_m}, {"linear", true},
                      {"clamped", true}}},
      {"max_open_height_m", max_open_height_m()},
  };
  return WriteFileAtomically(json_path, [&](std::ostream& out) { out << j.dump(2) << "\n"; });
}

Image<uint8_t> TopdownMap::ToOccupancy(const OccupancyThresholds& thresholds) const {
  Image<uint8_t> image;
  image.width = geometry_.width;
  image.height = geometry_.height;
  image.pixels.assign(height_m_.size(), kUnknownPixel);
  if (observed_m_.empty()) return image;
  const double occupied_min =
      thresholds.occupied_min_m > 0 ? thresholds.occupied_min_m : grid_.resolution_m();
  // Float sums of leaf heights: half a millimetre of slack against their rounding.
  const double slack = 5e-4;
  const double band = z_range_.z_hi_m - z_range_.z_lo_m;
  const double free_min = thresholds.free_min_fraction * band;
  for (size_t i = 0; i < image.pixels.size(); ++i) {
    if (solid_m_[i] >= occupied_min - slack) {
      image.pixels[i] = kOccupiedPixel;
    } else if (solid_m_[i] < slack && observed_m_[i] >= free_min - slack) {
      image.pixels[i] = kFreePixel;
    }
  }
  return image;
}

absl::Status TopdownMap::WriteRosMap(const std::string& pgm_path, const std::string& yaml_path,
                                     const OccupancyThresholds& thresholds,
                                     const std::string& about) const {
  if (observed_m_.empty()) {
    return absl::FailedPreconditionError(
        absl::StrCat(pgm_path, ": the map was not made with occupancy"));
  }
  if (!std::isfinite(z_range_.z_lo_m) || !std::isfinite(z_range_.z_hi_m)) {
    return absl::FailedPreconditionError(
        absl::StrCat(pgm_path, ": an occupancy map needs a bounded band of heights"));
  }
  // Binary PGM (netpbm P5): a header and the rows top first, one byte per pixel; too small a
  // format to take a library for.
  const Image<uint8_t> image = ToOccupancy(thresholds);
  const auto write_pgm = [&](std::ostream& out) {
    out << "P5\n" << image.width << " " << image.height << "\n255\n";
    out.write(reinterpret_cast<const char*>(image.pixels.data()),
              std::streamsize(image.pixels.size()));
  };
  if (absl::Status s = WriteFileAtomically(pgm_path, write_pgm); !s.ok()) return s;
  return WriteFileAtomically(yaml_path, [&](std::ostream& out) {
    for (const absl::string_view line : absl::StrSplit(about, '\n')) out << "# " << line << "\n";
    out.precision(17);
    out << "image: " << std::filesystem::path(pgm_path).filename().string() << "\n"
        << "mode: trinary\n"
        << "resolution: " << geometry_.resolution_m << "\n"
        << "origin: [" << geometry_.origin_x_m << ", " << geometry_.origin_y_m << ", 0.0]\n"
        << "negate: 0\n"
        << "occupied_thresh: 0.65\n"
        << "free_thresh: 0.196\n";
  });
}

}  // namespace carvemap

#include "geometry/chunk_region.h"

#include <algorithm>
#include <cassert>
#include <cmath>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

size_t CellIndex(const Eigen::Vector3i& c, int depth) {
  const size_t n = size_t{1} << depth;
  return size_t(c.x()) + n * (size_t(c.y()) + n * size_t(c.z()));
}

}  // namespace

ChunkRegion::ChunkRegion(int depth, const std::vector<Eigen::Vector3i>& cells) : depth_(depth) {
  assert(depth >= 0 && depth <= kMaxDepth);
  const int n = 1 << depth;
  std::vector<bool> bits(size_t(n) * n * n, false);
  for (const Eigen::Vector3i& c : cells) {
    if ((c.array() >= 0).all() && (c.array() < n).all()) bits[CellIndex(c, depth)] = true;
  }
  Build(std::move(bits));
}

void ChunkRegion::Build(std::vector<bool> cells) {
  count_ = 0;
  for (bool b : cells) count_ += b;
  any_.assign(depth_ + 1, {});
  any_[depth_] = std::move(cells);
  const int n = 1 << depth_;
  lo_ = Eigen::Vector3i::Constant(n);
  hi_ = Eigen::Vector3i::Constant(-1);
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        if (!any_[depth_][CellIndex({x, y, z}, depth_)]) continue;
        lo_ = lo_.cwiseMin(Eigen::Vector3i(x, y, z));
        hi_ = hi_.cwiseMax(Eigen::Vector3i(x, y, z));
      }
  sums_.clear();
  if (count_ > 0) {
    const Eigen::Vector3i size = hi_ - lo_ + Eigen::Vector3i::Ones();
    const size_t sx = size_t(size.x()) + 1, sy = size_t(size.y()) + 1;
    sums_.assign(sx * sy * (size_t(size.z()) + 1), 0);
    for (int k = 1; k <= size.z(); ++k)
      for (int j = 1; j <= size.y(); ++j)
        for (int i = 1; i <= size.x(); ++i) {
          const auto at = [&](int a, int b, int c) -> uint32_t& {
            return sums_[size_t(a) + sx * (size_t(b) + sy * size_t(c))];
          };
          const uint32_t cell =
              any_[depth_][CellIndex(lo_ + Eigen::Vector3i(i - 1, j - 1, k - 1), depth_)];
          at(i, j, k) = cell + at(i - 1, j, k) + at(i, j - 1, k) + at(i, j, k - 1) -
                        at(i - 1, j - 1, k) - at(i - 1, j, k - 1) - at(i, j - 1, k - 1) +
                        at(i - 1, j - 1, k - 1);
        }
  }
  for (int axis = 0; axis < 3; ++axis) {
    std::vector<uint32_t>& start = row_start_[axis];
    std::vector<CellRun>& runs = row_runs_[axis];
    start.assign(size_t(n) * n + 1, 0);
    runs.clear();
    if (count_ == 0) continue;
    Eigen::Vector3i c;
    for (int v = 0; v < n; ++v) {
      for (int u = 0; u < n; ++u) {
        start[(size_t(v) << depth_) + size_t(u)] = uint32_t(runs.size());
        c[(axis + 1) % 3] = u;
        c[(axis + 2) % 3] = v;
        int first = -1;
        for (int t = 0; t <= n; ++t) {
          c[axis] = t;
          const bool in = t < n && any_[depth_][CellIndex(c, depth_)];
          if (in && first < 0) first = t;
          if (!in && first >= 0) {
            runs.push_back({uint16_t(first), uint16_t(t - 1)});
            first = -1;
          }
        }
      }
    }
    start.back() = uint32_t(runs.size());
  }
  for (int d = depth_ - 1; d >= 0; --d) {
    const int n = 1 << d;
    any_[d].assign(size_t(n) * n * n, false);
    for (int z = 0; z < 2 * n; ++z)
      for (int y = 0; y < 2 * n; ++y)
        for (int x = 0; x < 2 * n; ++x) {
          if (any_[d + 1][CellIndex({x, y, z}, d + 1)]) {
            any_[d][CellIndex({x / 2, y / 2, z / 2}, d)] = true;
          }
        }
  }
}

std::span<const ChunkRegion::CellRun> ChunkRegion::RowRuns(int axis, int u, int v) const {
  if (count_ == 0) return {};
  assert(axis >= 0 && axis < 3);
  const size_t row = (size_t(v) << depth_) + size_t(u);
  const std::vector<uint32_t>& start = row_start_[axis];
  return std::span<const CellRun>(row_runs_[axis]).subspan(start[row], start[row + 1] - start[row]);
}

size_t ChunkRegion::memory_bytes() const {
  size_t n = sums_.capacity() * sizeof(uint32_t);
  for (const std::vector<bool>& bits : any_) n += bits.capacity() / 8;
  for (int axis = 0; axis < 3; ++axis) {
    n += row_start_[axis].capacity() * sizeof(uint32_t) +
         row_runs_[axis].capacity() * sizeof(CellRun);
  }
  return n;
}

bool ChunkRegion::Intersects(const ChunkNode& node) const {
  if (count_ == 0) return false;
  if (node.depth <= depth_) return any_[node.depth][CellIndex(node.local, node.depth)];
  const int sh = node.depth - depth_;
  const Eigen::Vector3i cell(node.local.x() >> sh, node.local.y() >> sh, node.local.z() >> sh);
  return any_[depth_][CellIndex(cell, depth_)];
}

bool ChunkRegion::IntersectsBox(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) const {
  if (count_ == 0 || !(lo.array() <= hi.array()).all()) return false;
  // The cells at depth() the box meets, as index ranges; cells are closed boxes, so a box
  // whose face lies on a cell border meets the cells on both sides.
  const double cell = kChunkSizeM / double(1 << depth_);
  // The cells the box meets, clipped to the region's bounding box, as ranges [c0, c1] of
  // indices relative to lo_.
  Eigen::Vector3i c0, c1;
  for (int a = 0; a < 3; ++a) {
    const double l = std::ceil(lo[a] / cell) - 1, h = std::floor(hi[a] / cell);
    if (h < lo_[a] || l > hi_[a]) return false;
    c0[a] = int(std::max(l, double(lo_[a]))) - lo_[a];
    c1[a] = int(std::min(h, double(hi_[a]))) - lo_[a];
  }
  const size_t sx = size_t(hi_.x() - lo_.x()) + 2, sy = size_t(hi_.y() - lo_.y()) + 2;
  const auto at = [&](int a, int b, int c) {
    return int64_t(sums_[size_t(a) + sx * (size_t(b) + sy * size_t(c))]);
  };
  const int x0 = c0.x(), y0 = c0.y(), z0 = c0.z();
  const int x1 = c1.x() + 1, y1 = c1.y() + 1, z1 = c1.z() + 1;
  const int64_t in = at(x1, y1, z1) - at(x0, y1, z1) - at(x1, y0, z1) - at(x1, y1, z0) +
                     at(x0, y0, z1) + at(x0, y1, z0) + at(x1, y0, z0) - at(x0, y0, z0);
  return in > 0;
}

std::string ChunkRegion::Encode() const {
  if (any_.empty()) return {};
  const std::vector<bool>& cells = any_[depth_];
  std::string bytes((cells.size() + 7) / 8, '\0');
  for (size_t i = 0; i < cells.size(); ++i) {
    if (cells[i]) bytes[i / 8] = char(uint8_t(bytes[i / 8]) | (1u << (i % 8)));
  }
  return bytes;
}

absl::Status ChunkRegion::CheckEncoding(int depth, std::string_view bits) {
  if (depth < 0 || depth > kMaxDepth) {
    return absl::InvalidArgumentError(
        absl::StrCat("chunk region: depth ", depth, " outside [0, ", kMaxDepth, "]"));
  }
  const size_t cells = size_t{1} << (3 * depth);
  if (bits.size() != (cells + 7) / 8) {
    return absl::InvalidArgumentError(absl::StrCat("chunk region: ", bits.size(),
                                                   " bytes for depth ", depth, " (expected ",
                                                   (cells + 7) / 8, ")"));
  }
  return absl::OkStatus();
}

absl::StatusOr<ChunkRegion> ChunkRegion::Decode(int depth, std::string_view bits) {
  if (absl::Status s = CheckEncoding(depth, bits); !s.ok()) return s;
  const size_t cells = size_t{1} << (3 * depth);
  std::vector<bool> set(cells, false);
  for (size_t i = 0; i < cells; ++i) set[i] = (uint8_t(bits[i / 8]) >> (i % 8)) & 1u;
  ChunkRegion region;
  region.depth_ = depth;
  region.Build(std::move(set));
  return region;
}

}  // namespace carvemap

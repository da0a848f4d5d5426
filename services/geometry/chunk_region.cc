#include "services/geometry/chunk_region.h"

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
  const int n = 1 << depth_;
  Eigen::Vector3i c0, c1;
  for (int a = 0; a < 3; ++a) {
    const double l = std::ceil(lo[a] / cell) - 1, h = std::floor(hi[a] / cell);
    if (h < 0 || l > n - 1) return false;
    c0[a] = int(std::max(l, 0.0));
    c1[a] = int(std::min(h, double(n - 1)));
  }
  // Depth-first over the nodes covering the ranges, only into nodes holding a cell.
  struct Frame {
    Eigen::Vector3i node;
    int depth;
  };
  Frame stack[8 * (kMaxDepth + 1)];
  int top = 0;
  stack[top++] = {Eigen::Vector3i::Zero(), 0};
  while (top > 0) {
    const Frame f = stack[--top];
    if (!any_[f.depth][CellIndex(f.node, f.depth)]) continue;
    if (f.depth == depth_) return true;
    const int sh = depth_ - f.depth - 1;
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector3i child = f.node * 2 + Eigen::Vector3i(i & 1, (i >> 1) & 1, i >> 2);
      bool meets = true;
      for (int a = 0; a < 3 && meets; ++a) {
        meets = (child[a] << sh) <= c1[a] && ((child[a] + 1) << sh) - 1 >= c0[a];
      }
      if (meets) stack[top++] = {child, f.depth + 1};
    }
  }
  return false;
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

absl::StatusOr<ChunkRegion> ChunkRegion::Decode(int depth, std::string_view bits) {
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
  std::vector<bool> set(cells, false);
  for (size_t i = 0; i < cells; ++i) set[i] = (uint8_t(bits[i / 8]) >> (i % 8)) & 1u;
  ChunkRegion region;
  region.depth_ = depth;
  region.Build(std::move(set));
  return region;
}

}  // namespace carvemap

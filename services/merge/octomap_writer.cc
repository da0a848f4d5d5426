#include "services/merge/octomap_writer.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <limits>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "storage/atomic_file.h"

namespace carvemap {

BtLabel BtLabelOf(const LeafStats& stats) {
  if (!stats.observed()) return BtLabel::kUnknown;
  return stats.interior() ? BtLabel::kFree : BtLabel::kOccupied;
}

float OtLogOddsOf(const LeafStats& stats) {
  const double occupied = std::clamp(1.0 - stats.p(), kOtMinProbability, 1.0 - kOtMinProbability);
  return static_cast<float>(std::log(occupied / (1.0 - occupied)));
}

namespace {

enum class Kind : uint8_t { kEmpty, kFree, kOccupied, kInner };

Kind KindOf(BtLabel label) {
  switch (label) {
    case BtLabel::kFree:
      return Kind::kFree;
    case BtLabel::kOccupied:
      return Kind::kOccupied;
    case BtLabel::kUnknown:
      break;
  }
  return Kind::kEmpty;
}

// What a subtree came out as: nothing (unknown), a leaf or an inner node, and (.ot) its value.
struct Node {
  Kind kind = Kind::kEmpty;
  float log_odds = 0;
};

// Wide enough for any uint32 node count; OctoMap reads the field with `>>`, so the spaces that
// pad it are harmless and let the count be filled in once the tree has been written.
constexpr int kSizeFieldWidth = 20;

// Appends to a file through a buffer, with the two operations the depth-first writer needs:
// patching an earlier inner node's 2 bytes once its children are known, and dropping the
// last node again (a rolled-back node is always the tail: its children wrote nothing).
class BodyFile {
 public:
  explicit BodyFile(std::string path) : path_(std::move(path)) {}
  ~BodyFile() {
    if (fd_ >= 0) ::close(fd_);
  }

  absl::Status Open() {
    fd_ = ::open(path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd_ < 0) return Errno("open");
    return absl::OkStatus();
  }
  [[nodiscard]] uint64_t Pos() const { return start_ + buf_.size(); }

  absl::Status Append(const void* data, size_t n) {
    buf_.append(static_cast<const char*>(data), n);
    return buf_.size() >= kFlushBytes ? Flush() : absl::OkStatus();
  }
  absl::Status Patch(uint64_t pos, const void* data, size_t n) {
    if (pos >= start_) {
      std::memcpy(buf_.data() + (pos - start_), data, n);
      return absl::OkStatus();
    }
    return PWrite(data, n, pos);
  }
  void Truncate(uint64_t pos) {
    if (pos >= start_) {
      buf_.resize(pos - start_);
    } else {
      buf_.clear();
      start_ = pos;
    }
  }
  absl::Status Flush() {
    if (absl::Status s = PWrite(buf_.data(), buf_.size(), start_); !s.ok()) return s;
    start_ += buf_.size();
    buf_.clear();
    return absl::OkStatus();
  }
  // Flushes, cuts the file at Pos() (earlier rollbacks may have left bytes past it) and
  // closes it.
  absl::Status Close() {
    if (absl::Status s = Flush(); !s.ok()) return s;
    if (::ftruncate(fd_, static_cast<off_t>(start_)) != 0) return Errno("truncate");
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) return Errno("close");
    return absl::OkStatus();
  }

 private:
  static constexpr size_t kFlushBytes = size_t{1} << 20;

  absl::Status PWrite(const void* data, size_t n, uint64_t pos) {
    const char* p = static_cast<const char*>(data);
    while (n > 0) {
      const ssize_t w = ::pwrite(fd_, p, n, static_cast<off_t>(pos));
      if (w < 0) {
        if (errno == EINTR) continue;
        return Errno("write");
      }
      p += w;
      n -= static_cast<size_t>(w);
      pos += static_cast<uint64_t>(w);
    }
    return absl::OkStatus();
  }
  absl::Status Errno(const char* what) const {
    return absl::UnavailableError(absl::StrCat(path_, ": ", what, ": ", std::strerror(errno)));
  }

  std::string path_;
  int fd_ = -1;
  std::string buf_;
  uint64_t start_ = 0;  // file offset of buf_[0]
};

struct SortedChunk {
  uint64_t code;  // Morton code of the chunk's OctoMap node index at depth 16 − k
  ChunkKey key;
};

// The two formats differ only in how a node is laid out; the depth-first walk is shared.
//
// .bt (OccupancyOcTreeBase::readBinaryNode): leaves have no bytes of their own, an inner node
// is 2 bytes of 2-bit child labels written before its children; 8 leaves of one label prune.
struct BtFormat {
  static constexpr size_t kInnerBytes = 2;
  static constexpr char kFirstLine[] = "# Octomap OcTree binary file\n";
  static Node Leaf(const LeafStats& stats) { return {KindOf(BtLabelOf(stats)), 0}; }
  static absl::Status WriteLeaf(BodyFile&, const Node&) { return absl::OkStatus(); }
  static bool Collapses(const std::array<Node, 8>& c) {
    return c[0].kind != Kind::kInner &&
           std::all_of(c.begin(), c.end(), [&](const Node& n) { return n.kind == c[0].kind; });
  }
  static absl::StatusOr<Node> FinishInner(BodyFile& body, uint64_t pos,
                                          const std::array<Node, 8>& children) {
    uint8_t bytes[2] = {0, 0};
    for (int i = 0; i < 8; ++i) {
      uint8_t bits = 0;  // low bit at 2(i mod 4), high bit at 2(i mod 4) + 1
      switch (children[i].kind) {
        case Kind::kEmpty:
          bits = 0b00;
          break;
        case Kind::kFree:
          bits = 0b01;
          break;
        case Kind::kOccupied:
          bits = 0b10;
          break;
        case Kind::kInner:
          bits = 0b11;
          break;
      }
      bytes[i / 4] |= static_cast<uint8_t>(bits << (2 * (i % 4)));
    }
    if (absl::Status s = body.Patch(pos, bytes, 2); !s.ok()) return s;
    return Node{Kind::kInner, 0};
  }
};

// .ot (OcTreeBaseImpl::readNodesRecurs with OcTreeNode::readData): every node, leaf or inner,
// is its log-odds (a float, host order as OctoMap writes it) and a byte of which children
// follow (bit i: child i), written before its children. An inner node's value is the largest
// of its children's (OctoMap's updateInnerOccupancy); 8 leaves of one value prune (prune()).
struct OtFormat {
  static constexpr size_t kInnerBytes = sizeof(float) + 1;
  static constexpr char kFirstLine[] = "# Octomap OcTree file\n";
  static Node Leaf(const LeafStats& stats) {
    if (!stats.observed()) return {};
    const float log_odds = OtLogOddsOf(stats);
    return {log_odds > 0 ? Kind::kOccupied : Kind::kFree, log_odds};
  }
  static absl::Status WriteLeaf(BodyFile& body, const Node& leaf) {
    char bytes[kInnerBytes] = {};
    std::memcpy(bytes, &leaf.log_odds, sizeof(float));
    return body.Append(bytes, sizeof bytes);
  }
  static bool Collapses(const std::array<Node, 8>& c) {
    return c[0].kind != Kind::kInner && std::all_of(c.begin(), c.end(), [&](const Node& n) {
             return n.kind != Kind::kInner && n.log_odds == c[0].log_odds;
           });
  }
  static absl::StatusOr<Node> FinishInner(BodyFile& body, uint64_t pos,
                                          const std::array<Node, 8>& children) {
    float max = -std::numeric_limits<float>::infinity();
    uint8_t present = 0;
    for (int i = 0; i < 8; ++i) {
      if (children[i].kind == Kind::kEmpty) continue;
      present |= static_cast<uint8_t>(1u << i);
      max = std::max(max, children[i].log_odds);
    }
    char bytes[kInnerBytes];
    std::memcpy(bytes, &max, sizeof(float));
    bytes[sizeof(float)] = static_cast<char>(present);
    if (absl::Status s = body.Patch(pos, bytes, sizeof bytes); !s.ok()) return s;
    return Node{Kind::kInner, max};
  }
};

template <typename Format>
class TreeWriter {
 public:
  TreeWriter(TileSet& tiles, BodyFile& body, const TileVisitor& visit)
      : tiles_(tiles),
        body_(body),
        visit_(visit),
        k_(tiles.grid().chunk_depth),
        chunk_level_(kOctomapTreeDepth - k_) {}

  absl::Status Run(std::vector<SortedChunk> chunks) {
    chunks_ = std::move(chunks);
    if (chunks_.empty()) return absl::OkStatus();
    // The root is never a leaf in either format (it is always read as an inner node), and it
    // could only become one if every chunk of the key space had a tile.
    absl::StatusOr<Node> root =
        WriteInner([&](int i) { return WriteAbove(1, Range(1, i, 0, chunks_.size())); },
                   /*may_collapse=*/false);
    if (!root.ok()) return root.status();
    if (root->kind == Kind::kInner) ++nodes_;
    return absl::OkStatus();
  }
  [[nodiscard]] uint64_t nodes() const { return nodes_; }
  [[nodiscard]] uint64_t tiles_read() const { return tiles_read_; }

 private:
  using ChildFn = std::function<absl::StatusOr<Node>(int)>;

  // Writes one inner node: a placeholder, then each child's subtree in child order (the order
  // OctoMap's readers recurse in), then the node's real bytes. A node whose children are all
  // unknown disappears; one whose 8 children are leaves that prune becomes that leaf.
  absl::StatusOr<Node> WriteInner(const ChildFn& child, bool may_collapse) {
    const uint64_t pos = body_.Pos();
    const char zero[Format::kInnerBytes] = {};
    if (absl::Status s = body_.Append(zero, sizeof zero); !s.ok()) return s;
    std::array<Node, 8> children;
    int present = 0;
    for (int i = 0; i < 8; ++i) {
      absl::StatusOr<Node> node = child(i);
      if (!node.ok()) return node.status();
      children[i] = *node;
      if (node->kind != Kind::kEmpty) ++present;
    }
    if (present == 0) {
      body_.Truncate(pos);
      return Node{};
    }
    if (may_collapse && present == 8 && Format::Collapses(children)) {
      body_.Truncate(pos);
      if (absl::Status s = Format::WriteLeaf(body_, children[0]); !s.ok()) return s;
      return children[0];
    }
    nodes_ += static_cast<uint64_t>(present);
    return Format::FinishInner(body_, pos, children);
  }

  struct Span {
    size_t lo, hi;
  };
  // The chunks of child `i`, at depth `depth`, of the node holding chunks [lo, hi) (sorted by
  // code, so every node's chunks are contiguous).
  Span Range(int depth, int i, size_t lo, size_t hi) const {
    const int shift = 3 * (chunk_level_ - depth);
    const uint64_t prefix = (chunks_[lo].code >> (shift + 3) << 3) | uint64_t(i);
    auto less = [&](const SortedChunk& c, uint64_t v) { return (c.code >> shift) < v; };
    auto b = std::lower_bound(chunks_.begin() + lo, chunks_.begin() + hi, prefix, less);
    auto e = std::lower_bound(b, chunks_.begin() + hi, prefix + 1, less);
    return {size_t(b - chunks_.begin()), size_t(e - chunks_.begin())};
  }

  // The node at OctoMap depth `depth` holding chunks [span.lo, span.hi).
  absl::StatusOr<Node> WriteAbove(int depth, Span span) {
    if (span.lo == span.hi) return Node{};
    if (depth == chunk_level_) return WriteChunk(chunks_[span.lo].key);
    return WriteInner(
        [&, span](int i) { return WriteAbove(depth + 1, Range(depth + 1, i, span.lo, span.hi)); },
        /*may_collapse=*/true);
  }

  absl::StatusOr<Node> WriteChunk(const ChunkKey& key) {
    absl::StatusOr<std::shared_ptr<const TileData>> tile = tiles_.Get(key);
    if (!tile.ok()) return tile.status();
    ++tiles_read_;
    if (visit_) {
      if (absl::Status s = visit_(**tile); !s.ok()) return s;
    }
    const TileData& t = **tile;
    first_cells_.resize(t.leaves.size());
    for (size_t i = 0; i < t.leaves.size(); ++i) {
      first_cells_[i] = MortonCode(t.leaves[i].node.local) << (3 * (k_ - t.leaves[i].node.depth));
    }
    return WriteInChunk(t, tiles_.PathOf(key), 0, 0, 0, t.leaves.size());
  }

  // The node of the chunk at local depth `depth` with Morton code `code`, holding rows
  // [lo, hi) of the tile (canonical order: by first finest cell, non-overlapping).
  absl::StatusOr<Node> WriteInChunk(const TileData& t, const std::string& path, int depth,
                                    uint64_t code, size_t lo, size_t hi) {
    if (lo == hi) return Node{};
    if (hi - lo == 1 && t.leaves[lo].node.depth == depth) {
      const Node leaf = Format::Leaf(t.leaves[lo].stats);
      if (leaf.kind != Kind::kEmpty) {
        if (absl::Status s = Format::WriteLeaf(body_, leaf); !s.ok()) return s;
      }
      return leaf;
    }
    for (size_t i = lo; i < hi; ++i) {
      if (t.leaves[i].node.depth <= depth) {  // ReadTile rejects overlaps; stay defensive
        return absl::DataLossError(absl::StrCat(path, ": /leaves row ", i, " overlaps others"));
      }
    }
    const int shift = 3 * (k_ - depth - 1);
    return WriteInner(
        [&, depth, code, lo, hi, shift](int i) -> absl::StatusOr<Node> {
          const uint64_t child = code * 8 + uint64_t(i);
          auto b = std::lower_bound(first_cells_.begin() + lo, first_cells_.begin() + hi,
                                    child << shift);
          auto e = std::lower_bound(b, first_cells_.begin() + hi, (child + 1) << shift);
          return WriteInChunk(t, path, depth + 1, child, size_t(b - first_cells_.begin()),
                              size_t(e - first_cells_.begin()));
        },
        /*may_collapse=*/true);
  }

  TileSet& tiles_;
  BodyFile& body_;
  const TileVisitor& visit_;
  const int k_;
  const int chunk_level_;  // OctoMap depth of chunk nodes
  std::vector<SortedChunk> chunks_;
  std::vector<uint64_t> first_cells_;  // of the tile being written
  uint64_t nodes_ = 0;
  uint64_t tiles_read_ = 0;
};

// Writes `path` in Format from every tile of `tiles` (WriteOctreeBt, WriteOctreeOt).
template <typename Format>
absl::StatusOr<OctomapFileStats> WriteOctomapFile(TileSet& tiles, const std::string& path,
                                                  const TileVisitor& visit) {
  const int k = tiles.grid().chunk_depth;
  const int chunk_level = kOctomapTreeDepth - k;
  // Our chunk c is OctoMap's node (c·2^k + 32768) / 2^k = c + 2^(15−k) at depth 16 − k.
  const int64_t offset = int64_t{kOctomapKeyOffset} >> k;
  const int64_t limit = int64_t{1} << chunk_level;
  std::vector<SortedChunk> chunks;
  chunks.reserve(tiles.chunks().size());
  for (const ChunkKey& c : tiles.chunks()) {
    const Eigen::Vector3i node = (c.cast<int64_t>().array() + offset).cast<int>();
    if ((node.array() < 0).any() || (node.cast<int64_t>().array() >= limit).any()) {
      return absl::OutOfRangeError(absl::StrCat(
          tiles.PathOf(c), ": chunk outside OctoMap's 16-level key space (chunk keys must be in [",
          -offset, ", ", limit - offset, ") at ", tiles.grid().resolution_m(), " m)"));
    }
    chunks.push_back({MortonCode(node), c});
  }
  std::sort(chunks.begin(), chunks.end(),
            [](const SortedChunk& a, const SortedChunk& b) { return a.code < b.code; });

  const std::string partial = PartialPath(path);
  BodyFile body(partial);
  absl::Status status = body.Open();
  OctomapFileStats stats;
  size_t size_field = 0;
  if (status.ok()) {
    std::string header = absl::StrCat(Format::kFirstLine, "id OcTree\nsize ");
    size_field = header.size();
    header += std::string(kSizeFieldWidth, ' ');
    header += absl::StrFormat("\nres %.17g\ndata\n", tiles.grid().resolution_m());
    status = body.Append(header.data(), header.size());
  }
  TreeWriter<Format> writer(tiles, body, visit);
  if (status.ok()) status = writer.Run(std::move(chunks));
  if (status.ok() && writer.nodes() > 0xffffffffULL) {
    // OctoMap reads the size as a 32-bit unsigned.
    status = absl::ResourceExhaustedError(absl::StrCat(
        path, ": ", writer.nodes(), " nodes exceed the 2^32 − 1 OctoMap's header can hold"));
  }
  if (status.ok()) {
    std::string count = std::to_string(writer.nodes());
    count.resize(kSizeFieldWidth, ' ');
    status = body.Patch(size_field, count.data(), count.size());
  }
  stats.bytes = body.Pos();
  if (status.ok()) status = body.Close();
  if (status.ok()) status = CommitPartial(path);
  if (!status.ok()) {
    std::remove(partial.c_str());
    return status;
  }
  stats.num_nodes = writer.nodes();
  stats.num_tiles = writer.tiles_read();
  return stats;
}

}  // namespace

absl::StatusOr<OctomapFileStats> WriteOctreeBt(TileSet& tiles, const std::string& path,
                                               const TileVisitor& visit) {
  return WriteOctomapFile<BtFormat>(tiles, path, visit);
}

absl::StatusOr<OctomapFileStats> WriteOctreeOt(TileSet& tiles, const std::string& path,
                                               const TileVisitor& visit) {
  return WriteOctomapFile<OtFormat>(tiles, path, visit);
}

}  // namespace carvemap

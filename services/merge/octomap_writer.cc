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
#include <optional>
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

// The values are .bt's 2-bit child codes.
enum class Kind : uint8_t { kEmpty = 0b00, kFree = 0b01, kOccupied = 0b10, kInner = 0b11 };

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
      bytes[i / 4] |= static_cast<uint8_t>(static_cast<uint8_t>(children[i].kind) << (2 * (i % 4)));
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

// One file of the walk: none when `body` is null.
struct Output {
  BodyFile* body = nullptr;
  uint64_t nodes = 0;  // the header's size: every node written, root included
};

// What a subtree came out as in each file.
struct Nodes {
  Node bt, ot;
};

// The depth-first walk over the tiles, writing both files on one read of each tile; each
// file has its own node layout and pruning (its Format), so a node may be a leaf in one and
// an inner node in the other.
class TreeWriter {
 public:
  TreeWriter(TileSet& tiles, Output& bt, Output& ot, const TileVisitor& visit)
      : tiles_(tiles),
        bt_(bt),
        ot_(ot),
        visit_(visit),
        k_(tiles.grid().chunk_depth),
        chunk_level_(kOctomapTreeDepth - k_) {}

  absl::Status Run(std::vector<SortedChunk> chunks) {
    chunks_ = std::move(chunks);
    if (chunks_.empty()) return absl::OkStatus();
    // The root is never a leaf in either format (it is always read as an inner node), and it
    // could only become one if every chunk of the key space had a tile.
    absl::StatusOr<Nodes> root =
        WriteInner([&](int i) { return WriteAbove(1, Range(1, i, 0, chunks_.size())); },
                   /*may_collapse=*/false);
    if (!root.ok()) return root.status();
    if (root->bt.kind == Kind::kInner) ++bt_.nodes;
    if (root->ot.kind == Kind::kInner) ++ot_.nodes;
    return absl::OkStatus();
  }
  [[nodiscard]] uint64_t tiles_read() const { return tiles_read_; }

 private:
  using ChildFn = std::function<absl::StatusOr<Nodes>(int)>;

  // An inner node's bytes are reserved before its children and filled in after them.
  template <typename Format>
  static absl::Status Reserve(Output& out, uint64_t& pos) {
    if (out.body == nullptr) return absl::OkStatus();
    pos = out.body->Pos();
    const char zero[Format::kInnerBytes] = {};
    return out.body->Append(zero, sizeof zero);
  }

  // A node whose children are all unknown disappears; one whose 8 children are leaves that
  // prune becomes that leaf; else its reserved bytes are filled in.
  template <typename Format>
  static absl::StatusOr<Node> Fill(Output& out, uint64_t pos, const std::array<Node, 8>& children,
                                   bool may_collapse) {
    if (out.body == nullptr) return Node{};
    const int present = static_cast<int>(std::count_if(
        children.begin(), children.end(), [](const Node& n) { return n.kind != Kind::kEmpty; }));
    if (present == 0) {
      out.body->Truncate(pos);
      return Node{};
    }
    if (may_collapse && present == 8 && Format::Collapses(children)) {
      out.body->Truncate(pos);
      if (absl::Status s = Format::WriteLeaf(*out.body, children[0]); !s.ok()) return s;
      return children[0];
    }
    out.nodes += static_cast<uint64_t>(present);
    return Format::FinishInner(*out.body, pos, children);
  }

  template <typename Format>
  static absl::StatusOr<Node> Leaf(Output& out, const LeafStats& stats) {
    if (out.body == nullptr) return Node{};
    const Node leaf = Format::Leaf(stats);
    if (leaf.kind != Kind::kEmpty) {
      if (absl::Status s = Format::WriteLeaf(*out.body, leaf); !s.ok()) return s;
    }
    return leaf;
  }

  // Writes one inner node in each file, its children's subtrees in child order (the order
  // OctoMap's readers recurse in) between its reserved bytes and their filling in.
  absl::StatusOr<Nodes> WriteInner(const ChildFn& child, bool may_collapse) {
    uint64_t bt_pos = 0, ot_pos = 0;
    if (absl::Status s = Reserve<BtFormat>(bt_, bt_pos); !s.ok()) return s;
    if (absl::Status s = Reserve<OtFormat>(ot_, ot_pos); !s.ok()) return s;
    std::array<Node, 8> bt, ot;
    for (int i = 0; i < 8; ++i) {
      absl::StatusOr<Nodes> nodes = child(i);
      if (!nodes.ok()) return nodes.status();
      bt[i] = nodes->bt;
      ot[i] = nodes->ot;
    }
    absl::StatusOr<Node> b = Fill<BtFormat>(bt_, bt_pos, bt, may_collapse);
    if (!b.ok()) return b.status();
    absl::StatusOr<Node> o = Fill<OtFormat>(ot_, ot_pos, ot, may_collapse);
    if (!o.ok()) return o.status();
    return Nodes{*b, *o};
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
  absl::StatusOr<Nodes> WriteAbove(int depth, Span span) {
    if (span.lo == span.hi) return Nodes{};
    if (depth == chunk_level_) return WriteChunk(chunks_[span.lo].key);
    return WriteInner(
        [&, span](int i) { return WriteAbove(depth + 1, Range(depth + 1, i, span.lo, span.hi)); },
        /*may_collapse=*/true);
  }

  absl::StatusOr<Nodes> WriteChunk(const ChunkKey& key) {
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
  absl::StatusOr<Nodes> WriteInChunk(const TileData& t, const std::string& path, int depth,
                                     uint64_t code, size_t lo, size_t hi) {
    if (lo == hi) return Nodes{};
    if (hi - lo == 1 && t.leaves[lo].node.depth == depth) {
      absl::StatusOr<Node> b = Leaf<BtFormat>(bt_, t.leaves[lo].stats);
      if (!b.ok()) return b.status();
      absl::StatusOr<Node> o = Leaf<OtFormat>(ot_, t.leaves[lo].stats);
      if (!o.ok()) return o.status();
      return Nodes{*b, *o};
    }
    for (size_t i = lo; i < hi; ++i) {
      if (t.leaves[i].node.depth <= depth) {  // ReadTile rejects overlaps; stay defensive
        return absl::DataLossError(absl::StrCat(path, ": /leaves row ", i, " overlaps others"));
      }
    }
    const int shift = 3 * (k_ - depth - 1);
    return WriteInner(
        [&, depth, code, lo, hi, shift](int i) -> absl::StatusOr<Nodes> {
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
  Output& bt_;
  Output& ot_;
  const TileVisitor& visit_;
  const int k_;
  const int chunk_level_;  // OctoMap depth of chunk nodes
  std::vector<SortedChunk> chunks_;
  std::vector<uint64_t> first_cells_;  // of the tile being written
  uint64_t tiles_read_ = 0;
};

// One OctoMap file being written: "<path>.partial", its header with the node count's field
// left blank until the tree is written, then a rename.
class OctomapFile {
 public:
  explicit OctomapFile(std::string path) : path_(std::move(path)), body_(PartialPath(path_)) {}

  absl::Status Start(const char* first_line, double resolution_m) {
    if (absl::Status s = body_.Open(); !s.ok()) return s;
    std::string header = absl::StrCat(first_line, "id OcTree\nsize ");
    size_field_ = header.size();
    header += std::string(kSizeFieldWidth, ' ');
    header += absl::StrFormat("\nres %.17g\ndata\n", resolution_m);
    return body_.Append(header.data(), header.size());
  }
  // Writes the count of `nodes`, then closes and commits the file.
  absl::Status Finish(uint64_t nodes) {
    if (nodes > 0xffffffffULL) {  // OctoMap reads the size as a 32-bit unsigned.
      return absl::ResourceExhaustedError(
          absl::StrCat(path_, ": ", nodes, " nodes exceed the 2^32 − 1 OctoMap's header can hold"));
    }
    std::string count = std::to_string(nodes);
    count.resize(kSizeFieldWidth, ' ');
    if (absl::Status s = body_.Patch(size_field_, count.data(), count.size()); !s.ok()) return s;
    bytes_ = body_.Pos();
    if (absl::Status s = body_.Close(); !s.ok()) return s;
    if (absl::Status s = CommitPartial(path_); !s.ok()) return s;
    committed_ = true;
    return absl::OkStatus();
  }
  // Removes what was written, committed or not.
  void Abandon() {
    std::remove(PartialPath(path_).c_str());
    if (committed_) std::remove(path_.c_str());
  }
  [[nodiscard]] BodyFile& body() { return body_; }
  [[nodiscard]] uint64_t bytes() const { return bytes_; }

 private:
  std::string path_;
  BodyFile body_;
  size_t size_field_ = 0;
  uint64_t bytes_ = 0;
  bool committed_ = false;
};

}  // namespace

absl::StatusOr<OctomapFilesStats> WriteOctomapFiles(TileSet& tiles, const std::string& bt_path,
                                                    const std::string& ot_path,
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

  std::optional<OctomapFile> bt_file, ot_file;
  Output bt, ot;
  absl::Status status;
  const double res = tiles.grid().resolution_m();
  if (!bt_path.empty()) {
    bt_file.emplace(bt_path);
    status = bt_file->Start(BtFormat::kFirstLine, res);
    bt.body = &bt_file->body();
  }
  if (status.ok() && !ot_path.empty()) {
    ot_file.emplace(ot_path);
    status = ot_file->Start(OtFormat::kFirstLine, res);
    ot.body = &ot_file->body();
  }
  TreeWriter writer(tiles, bt, ot, visit);
  if (status.ok()) status = writer.Run(std::move(chunks));
  if (status.ok() && bt_file) status = bt_file->Finish(bt.nodes);
  if (status.ok() && ot_file) status = ot_file->Finish(ot.nodes);
  if (!status.ok()) {  // neither file stands unless both do
    if (bt_file) bt_file->Abandon();
    if (ot_file) ot_file->Abandon();
    return status;
  }
  OctomapFilesStats stats;
  stats.num_tiles = writer.tiles_read();
  if (bt_file) stats.bt = {bt.nodes, bt_file->bytes()};
  if (ot_file) stats.ot = {ot.nodes, ot_file->bytes()};
  return stats;
}

}  // namespace carvemap

#include "storage/partial_sums.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <random>
#include <utility>

#include "absl/strings/str_cat.h"
#include "storage/atomic_file.h"
#include "storage/byte_shuffle.h"
#include "storage/crc32c.h"

namespace carvemap {
namespace {

// A temporary name of this writer's own: a worker declared lost may still be writing the same
// file when another one carves the slice again, and the two must not share a temporary file.
std::string TempPathFor(const std::string& path) {
  thread_local std::mt19937_64 random{std::random_device{}()};
  return absl::StrCat(path, ".", absl::Hex(random(), absl::kZeroPad16), ".tmp");
}

constexpr char kMagic[8] = {'C', 'M', 'P', 'A', 'R', 'T', 'L', '1'};
// Version 2 stores each section compressed (below); version 1 files still read.
constexpr uint32_t kVersion = 2;
constexpr size_t kHeaderBytes = 32;
constexpr size_t kLeafBytes = 36;
constexpr size_t kEntryBytes = 40;
constexpr size_t kTrailerBytes = 24;

void PutU32(uint32_t v, char* p) {
  for (int i = 0; i < 4; ++i) p[i] = char(v >> (8 * i));
}
void PutU64(uint64_t v, char* p) {
  for (int i = 0; i < 8; ++i) p[i] = char(v >> (8 * i));
}
uint32_t GetU32(const char* p) {
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= uint32_t(static_cast<unsigned char>(p[i])) << (8 * i);
  return v;
}
uint64_t GetU64(const char* p) {
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= uint64_t(static_cast<unsigned char>(p[i])) << (8 * i);
  return v;
}
void PutF64(double v, char* p) {
  uint64_t u;
  std::memcpy(&u, &v, 8);
  PutU64(u, p);
}
double GetF64(const char* p) {
  const uint64_t u = GetU64(p);
  double v;
  std::memcpy(&v, &u, 8);
  return v;
}

absl::Status IoError(std::string_view what, const std::string& path) {
  return absl::InternalError(
      absl::StrCat("partial sums ", std::string(what), " ", path, ": ", std::strerror(errno)));
}

absl::Status WriteAll(int fd, const char* data, size_t n, const std::string& path) {
  while (n > 0) {
    const ssize_t w = ::write(fd, data, n);
    if (w < 0) {
      if (errno == EINTR) continue;
      return IoError("write", path);
    }
    data += w;
    n -= size_t(w);
  }
  return absl::OkStatus();
}

// Reads exactly n bytes at `offset`, or says how many there were.
absl::StatusOr<size_t> ReadAt(int fd, char* out, size_t n, uint64_t offset,
                              const std::string& path) {
  size_t got = 0;
  while (got < n) {
    const ssize_t r = ::pread(fd, out + got, n - got, off_t(offset + got));
    if (r < 0) {
      if (errno == EINTR) continue;
      return IoError("read", path);
    }
    if (r == 0) break;
    got += size_t(r);
  }
  return got;
}

class Fd {
 public:
  explicit Fd(int fd) : fd_(fd) {}
  ~Fd() {
    if (fd_ >= 0) ::close(fd_);
  }
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  [[nodiscard]] int get() const { return fd_; }
  int release() { return std::exchange(fd_, -1); }

 private:
  int fd_;
};

uint32_t LocalCode(const Eigen::Vector3i& l) {
  return uint32_t(l.x()) | uint32_t(l.y()) << 10 | uint32_t(l.z()) << 20;
}

absl::Status Corrupt(const std::string& path, std::string_view what) {
  return absl::DataLossError(absl::StrCat("partial sums file ", path, ": ", std::string(what)));
}

// A section's leaf records as stored from version 2: byte j of every record, then byte j + 1,
// ... (a shuffle: the small counts and the sums' exponents line up), compressed by zstd at
// level 1. The sums' mantissas do not compress; on office2's simulated slices this halves the
// bytes (PARTIAL_FORMAT.md), for ~0.1 s of a core per 50 MB.
constexpr int kZstdLevel = 1;
// A stored section inflating past this ratio is damage, not sums (real ones compress ~2×):
// it bounds what a corrupt or hostile file makes the reader allocate.
constexpr uint64_t kMaxInflation = 1024;

absl::StatusOr<std::string> PackRecords(const std::vector<char>& records) {
  const size_t n = records.size() / kLeafBytes;
  std::vector<char> planes(records.size());
  ShuffleBytes(reinterpret_cast<const unsigned char*>(records.data()), n, kLeafBytes, n,
               reinterpret_cast<unsigned char*>(planes.data()));
  std::string stored(ZSTD_compressBound(planes.size()), '\0');
  const size_t got =
      ZSTD_compress(stored.data(), stored.size(), planes.data(), planes.size(), kZstdLevel);
  if (ZSTD_isError(got)) {
    return absl::InternalError(absl::StrCat("zstd: ", ZSTD_getErrorName(got)));
  }
  stored.resize(got);
  return stored;
}

// PackRecords undone: `leaves` records, or why the bytes are not them.
absl::StatusOr<std::vector<char>> UnpackRecords(const std::vector<char>& stored, uint64_t leaves) {
  const uint64_t bytes = leaves * kLeafBytes;
  const unsigned long long declared = ZSTD_getFrameContentSize(stored.data(), stored.size());
  if (declared != bytes) {
    return absl::DataLossError(absl::StrCat("its frame declares ", declared, " bytes, not ", bytes,
                                            " for ", leaves, " leaves"));
  }
  std::vector<char> planes(bytes);
  const size_t got = ZSTD_decompress(planes.data(), planes.size(), stored.data(), stored.size());
  if (ZSTD_isError(got) || got != bytes) {
    return absl::DataLossError(absl::StrCat("does not inflate to its leaves (",
                                            ZSTD_isError(got) ? ZSTD_getErrorName(got) : "short",
                                            ")"));
  }
  std::vector<char> records(bytes);
  UnshuffleBytes(reinterpret_cast<const unsigned char*>(planes.data()), size_t(leaves), kLeafBytes,
                 size_t(leaves), reinterpret_cast<unsigned char*>(records.data()));
  return records;
}

}  // namespace

struct PartialSumsWriter::Impl {
  std::string path, tmp;
  int depth = 0;
  uint32_t slice = 0;
  int fd = -1;
  uint64_t written = 0;
  std::vector<PartialSection> sections;
  std::vector<char> buffer;
  bool finished = false;
};

PartialSumsWriter::PartialSumsWriter(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

PartialSumsWriter::~PartialSumsWriter() {
  if (impl_->fd >= 0) ::close(impl_->fd);
  if (!impl_->finished) {
    std::error_code ec;
    std::filesystem::remove(impl_->tmp, ec);
  }
}

absl::StatusOr<std::unique_ptr<PartialSumsWriter>> PartialSumsWriter::Create(
    const std::string& path, int chunk_depth, uint32_t slice) {
  if (chunk_depth < kMinChunkDepth || chunk_depth > kMaxChunkDepth) {
    return absl::InvalidArgumentError(absl::StrCat("partial sums ", path, ": chunk depth ",
                                                   chunk_depth, " out of range"));
  }
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  impl->tmp = TempPathFor(path);
  impl->depth = chunk_depth;
  impl->slice = slice;
  impl->fd = ::open(impl->tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (impl->fd < 0) return IoError("create", impl->tmp);
  char header[kHeaderBytes] = {};
  std::memcpy(header, kMagic, 8);
  PutU32(kVersion, header + 8);
  PutU32(uint32_t(chunk_depth), header + 12);
  PutU32(slice, header + 16);
  PutU32(Crc32c(std::string_view(header, 28)), header + 28);
  if (absl::Status s = WriteAll(impl->fd, header, kHeaderBytes, impl->tmp); !s.ok()) return s;
  impl->written = kHeaderBytes;
  return std::unique_ptr<PartialSumsWriter>(new PartialSumsWriter(std::move(impl)));
}

absl::Status PartialSumsWriter::AddSection(const ChunkKey& chunk, uint64_t wedges,
                                           std::span<const TileLeaf> leaves) {
  Impl& m = *impl_;
  if (m.finished) return absl::FailedPreconditionError("partial sums: AddSection after Finish");
  const int n = 1 << m.depth;
  std::vector<const TileLeaf*> sorted;
  sorted.reserve(leaves.size());
  for (const TileLeaf& l : leaves) {
    if (l.node.depth != m.depth || (l.node.local.array() < 0).any() ||
        (l.node.local.array() >= n).any()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "partial sums ", m.path, ": a leaf of depth ", l.node.depth, " at (",
          l.node.local.x(), ",", l.node.local.y(), ",", l.node.local.z(), ") is not a finest leaf"));
    }
    sorted.push_back(&l);
  }
  std::sort(sorted.begin(), sorted.end(), [](const TileLeaf* a, const TileLeaf* b) {
    return LocalCode(a->node.local) < LocalCode(b->node.local);
  });
  m.buffer.assign(sorted.size() * kLeafBytes, 0);
  char* p = m.buffer.data();
  for (const TileLeaf* l : sorted) {
    PutU32(LocalCode(l->node.local), p);
    PutU32(l->stats.count, p + 4);
    PutU32(l->stats.points, p + 8);
    PutF64(l->stats.sum_w, p + 12);
    PutF64(l->stats.sum_wp, p + 20);
    PutF64(l->stats.sum_wp2, p + 28);
    p += kLeafBytes;
  }
  std::string stored;  // an empty section stores nothing
  if (!sorted.empty()) {
    absl::StatusOr<std::string> packed = PackRecords(m.buffer);
    if (!packed.ok()) {
      return absl::InternalError(
          absl::StrCat("partial sums ", m.path, ": ", packed.status().message()));
    }
    stored = *std::move(packed);
  }
  PartialSection s;
  s.chunk = chunk;
  s.wedges = wedges;
  s.leaves = sorted.size();
  s.offset = m.written;
  s.stored_bytes = stored.size();
  s.crc = Crc32c(stored);
  if (absl::Status st = WriteAll(m.fd, stored.data(), stored.size(), m.tmp); !st.ok()) return st;
  m.written += stored.size();
  m.sections.push_back(s);
  return absl::OkStatus();
}

absl::StatusOr<uint64_t> PartialSumsWriter::Finish() {
  Impl& m = *impl_;
  if (m.finished) return absl::FailedPreconditionError("partial sums: Finish called twice");
  std::vector<char> index(m.sections.size() * kEntryBytes);
  char* p = index.data();
  for (const PartialSection& s : m.sections) {
    for (int a = 0; a < 3; ++a) PutU32(uint32_t(s.chunk[a]), p + 4 * a);
    PutU64(s.wedges, p + 12);
    PutU64(s.leaves, p + 20);
    PutU64(s.offset, p + 28);
    PutU32(s.crc, p + 36);
    p += kEntryBytes;
  }
  char trailer[kTrailerBytes];
  PutU64(m.written, trailer);
  PutU64(m.sections.size(), trailer + 8);
  PutU32(Crc32c(std::string_view(index.data(), index.size())), trailer + 16);
  PutU32(Crc32c(std::string_view(trailer, 20)), trailer + 20);
  if (absl::Status s = WriteAll(m.fd, index.data(), index.size(), m.tmp); !s.ok()) return s;
  if (absl::Status s = WriteAll(m.fd, trailer, kTrailerBytes, m.tmp); !s.ok()) return s;
  if (::fsync(m.fd) != 0) return IoError("fsync", m.tmp);
  const int fd = std::exchange(m.fd, -1);
  if (::close(fd) != 0) return IoError("close", m.tmp);
  if (::rename(m.tmp.c_str(), m.path.c_str()) != 0) return IoError("rename", m.tmp);
  // The rename too must reach the disk before the slice is reported done (atomic_file.h).
  if (absl::Status s = SyncFolderOf(m.path); !s.ok()) {
    return s;
  }
  m.finished = true;
  return m.written + index.size() + kTrailerBytes;
}

absl::StatusOr<PartialSumsIndex> ReadPartialIndex(const std::string& path) {
  Fd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (fd.get() < 0) {
    if (errno == ENOENT) return absl::NotFoundError(absl::StrCat("partial sums file ", path,
                                                                 " does not exist"));
    return IoError("open", path);
  }
  struct stat st;
  if (::fstat(fd.get(), &st) != 0) return IoError("stat", path);
  const uint64_t size = uint64_t(st.st_size);
  if (size < kHeaderBytes + kTrailerBytes) {
    return Corrupt(path, absl::StrCat("truncated (", size, " bytes)"));
  }
  char header[kHeaderBytes];
  absl::StatusOr<size_t> got = ReadAt(fd.get(), header, kHeaderBytes, 0, path);
  if (!got.ok()) return got.status();
  if (std::memcmp(header, kMagic, 8) != 0) return Corrupt(path, "bad magic, not a partial sums file");
  if (GetU32(header + 28) != Crc32c(std::string_view(header, 28))) {
    return Corrupt(path, "header checksum mismatch");
  }
  PartialSumsIndex out;
  out.version = GetU32(header + 8);
  if (out.version < 1 || out.version > kVersion) {
    return Corrupt(path, absl::StrCat("unsupported version ", out.version,
                                      " (this build reads 1 to ", kVersion, ")"));
  }
  out.chunk_depth = int(GetU32(header + 12));
  out.slice = GetU32(header + 16);
  if (out.chunk_depth < kMinChunkDepth || out.chunk_depth > kMaxChunkDepth) {
    return Corrupt(path, absl::StrCat("chunk depth ", out.chunk_depth, " out of range"));
  }
  char trailer[kTrailerBytes];
  got = ReadAt(fd.get(), trailer, kTrailerBytes, size - kTrailerBytes, path);
  if (!got.ok()) return got.status();
  if (GetU32(trailer + 20) != Crc32c(std::string_view(trailer, 20))) {
    return Corrupt(path, "trailer checksum mismatch (unfinished or truncated)");
  }
  const uint64_t index_offset = GetU64(trailer), sections = GetU64(trailer + 8);
  if (index_offset < kHeaderBytes || sections > (size - kTrailerBytes) / kEntryBytes ||
      index_offset + sections * kEntryBytes + kTrailerBytes != size) {
    return Corrupt(path, absl::StrCat("index of ", sections, " sections at ", index_offset,
                                      " does not fit the file's ", size, " bytes"));
  }
  std::vector<char> index(sections * kEntryBytes);
  got = ReadAt(fd.get(), index.data(), index.size(), index_offset, path);
  if (!got.ok()) return got.status();
  if (*got != index.size() ||
      GetU32(trailer + 16) != Crc32c(std::string_view(index.data(), index.size()))) {
    return Corrupt(path, "index checksum mismatch");
  }
  uint64_t next = kHeaderBytes;
  const char* p = index.data();
  for (uint64_t i = 0; i < sections; ++i, p += kEntryBytes) {
    PartialSection s;
    for (int a = 0; a < 3; ++a) s.chunk[a] = int32_t(GetU32(p + 4 * a));
    s.wedges = GetU64(p + 12);
    s.leaves = GetU64(p + 20);
    s.offset = GetU64(p + 28);
    s.crc = GetU32(p + 36);
    // Sections follow one another from the header to the index: each one's stored bytes end
    // where the next begins (version 1: its leaf records, 36 bytes each).
    const uint64_t end = i + 1 < sections ? GetU64(p + kEntryBytes + 28) : index_offset;
    const auto out_of_place = [&] {
      return Corrupt(path, absl::StrCat("section ", i, " of chunk ", s.chunk.x(), ",",
                                        s.chunk.y(), ",", s.chunk.z(), " out of place"));
    };
    if (s.offset != next || end < next || end > index_offset) return out_of_place();
    s.stored_bytes = end - next;
    if (out.version == 1
            ? s.leaves > s.stored_bytes / kLeafBytes || s.stored_bytes != s.leaves * kLeafBytes
            : (s.leaves == 0) != (s.stored_bytes == 0) ||
                  s.leaves > s.stored_bytes * kMaxInflation / kLeafBytes) {
      return out_of_place();
    }
    next = end;
    out.sections.push_back(s);
  }
  if (next != index_offset) return Corrupt(path, "sections do not reach the index");
  return out;
}

absl::Status ReadPartialSection(const std::string& path, const PartialSumsIndex& index,
                                const PartialSection& section, std::vector<TileLeaf>& out) {
  Fd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (fd.get() < 0) return IoError("open", path);
  std::vector<char> bytes(section.stored_bytes);
  absl::StatusOr<size_t> got = ReadAt(fd.get(), bytes.data(), bytes.size(), section.offset, path);
  if (!got.ok()) return got.status();
  const std::string chunk =
      absl::StrCat(section.chunk.x(), ",", section.chunk.y(), ",", section.chunk.z());
  if (*got != bytes.size()) return Corrupt(path, absl::StrCat("chunk ", chunk, ": truncated"));
  if (Crc32c(std::string_view(bytes.data(), bytes.size())) != section.crc) {
    return Corrupt(path, absl::StrCat("chunk ", chunk, ": checksum mismatch"));
  }
  if (index.version >= 2 && section.leaves > 0) {
    absl::StatusOr<std::vector<char>> records = UnpackRecords(bytes, section.leaves);
    if (!records.ok()) {
      return Corrupt(path, absl::StrCat("chunk ", chunk, ": ", records.status().message()));
    }
    bytes = *std::move(records);
  }
  if (bytes.size() != section.leaves * kLeafBytes) {
    return Corrupt(path, absl::StrCat("chunk ", chunk, ": ", bytes.size(), " bytes for ",
                                      section.leaves, " leaves"));
  }
  const int n = 1 << index.chunk_depth;
  const char* p = bytes.data();
  for (uint64_t i = 0; i < section.leaves; ++i, p += kLeafBytes) {
    const uint32_t code = GetU32(p);
    TileLeaf leaf;
    leaf.node.depth = index.chunk_depth;
    leaf.node.local = Eigen::Vector3i(int(code & 1023), int((code >> 10) & 1023),
                                      int((code >> 20) & 1023));
    if ((leaf.node.local.array() >= n).any() || (code >> 30) != 0) {
      return Corrupt(path, absl::StrCat("chunk ", chunk, ": leaf ", i, " outside the chunk"));
    }
    leaf.stats.count = GetU32(p + 4);
    leaf.stats.points = GetU32(p + 8);
    leaf.stats.sum_w = GetF64(p + 12);
    leaf.stats.sum_wp = GetF64(p + 20);
    leaf.stats.sum_wp2 = GetF64(p + 28);
    if (!std::isfinite(leaf.stats.sum_w) || !std::isfinite(leaf.stats.sum_wp) ||
        !std::isfinite(leaf.stats.sum_wp2) || leaf.stats.sum_w < 0) {
      return Corrupt(path, absl::StrCat("chunk ", chunk, ": leaf ", i, " has bad sums"));
    }
    out.push_back(leaf);
  }
  return absl::OkStatus();
}

namespace {
constexpr char kRegionsMagic[8] = {'C', 'M', 'R', 'E', 'G', 'N', 'S', '1'};
}  // namespace

absl::Status WriteRegionsFile(const std::string& path, std::span<const RecarveChunk> regions) {
  std::vector<const RecarveChunk*> sorted;
  sorted.reserve(regions.size());
  for (const RecarveChunk& c : regions) {
    if (absl::Status s = ChunkRegion::CheckEncoding(c.depth, c.cells); !s.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": the region of chunk ", c.chunk.x(), ",", c.chunk.y(), ",",
                       c.chunk.z(), ": ", s.message()));
    }
    sorted.push_back(&c);
  }
  std::sort(sorted.begin(), sorted.end(), [](const RecarveChunk* a, const RecarveChunk* b) {
    return ChunkKeyLess{}(a->chunk, b->chunk);
  });
  for (size_t i = 1; i < sorted.size(); ++i) {
    if (sorted[i]->chunk == sorted[i - 1]->chunk) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": chunk ", sorted[i]->chunk.x(), ",", sorted[i]->chunk.y(), ",",
                       sorted[i]->chunk.z(), " is listed twice"));
    }
  }
  std::string bytes(kRegionsMagic, 8);
  char u[4];
  const auto put = [&](uint32_t v) {
    PutU32(v, u);
    bytes.append(u, 4);
  };
  put(uint32_t(sorted.size()));
  for (const RecarveChunk* c : sorted) {
    for (int a = 0; a < 3; ++a) put(uint32_t(c->chunk[a]));
    put(uint32_t(c->depth));
    put(uint32_t(c->cells.size()));
    bytes += c->cells;
  }
  put(Crc32c(bytes));
  const std::string tmp = TempPathFor(path);
  Fd fd(::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644));
  if (fd.get() < 0) return IoError("create", tmp);
  if (absl::Status s = WriteAll(fd.get(), bytes.data(), bytes.size(), tmp); !s.ok()) return s;
  if (::fsync(fd.get()) != 0) return IoError("fsync", tmp);
  if (::close(fd.release()) != 0) return IoError("close", tmp);
  if (::rename(tmp.c_str(), path.c_str()) != 0) return IoError("rename", tmp);
  return SyncFolderOf(path);
}

absl::StatusOr<RecarveRegionMap> ReadRegionsFile(const std::string& path) {
  Fd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (fd.get() < 0) {
    if (errno == ENOENT) return absl::NotFoundError(absl::StrCat("regions file ", path,
                                                                 " does not exist"));
    return IoError("open", path);
  }
  struct stat st;
  if (::fstat(fd.get(), &st) != 0) return IoError("stat", path);
  std::string bytes(size_t(st.st_size), '\0');
  absl::StatusOr<size_t> got = ReadAt(fd.get(), bytes.data(), bytes.size(), 0, path);
  if (!got.ok()) return got.status();
  const auto corrupt = [&path](std::string_view what) {
    return absl::DataLossError(absl::StrCat("regions file ", path, ": ", std::string(what)));
  };
  if (*got != bytes.size() || bytes.size() < 16 || std::memcmp(bytes.data(), kRegionsMagic, 8) != 0) {
    return corrupt("not a regions file, or truncated");
  }
  if (GetU32(bytes.data() + bytes.size() - 4) !=
      Crc32c(std::string_view(bytes.data(), bytes.size() - 4))) {
    return corrupt("checksum mismatch");
  }
  const char* p = bytes.data() + 8;
  const char* end = bytes.data() + bytes.size() - 4;
  const uint32_t count = GetU32(p);
  p += 4;
  RecarveRegionMap out;
  for (uint32_t i = 0; i < count; ++i) {
    if (end - p < 20) return corrupt(absl::StrCat("region ", i, " truncated"));
    ChunkKey chunk;
    for (int a = 0; a < 3; ++a) chunk[a] = int32_t(GetU32(p + 4 * a));
    const int depth = int(GetU32(p + 12));
    const uint32_t size = GetU32(p + 16);
    p += 20;
    if (uint64_t(end - p) < size) return corrupt(absl::StrCat("region ", i, " truncated"));
    const std::string_view cells(p, size);
    if (absl::Status s = ChunkRegion::CheckEncoding(depth, cells); !s.ok()) {
      return corrupt(absl::StrCat("region ", i, ": ", s.message()));
    }
    p += size;
    if (!out.emplace(chunk, RecarveChunk{chunk, depth, std::string(cells)}).second) {
      return corrupt(absl::StrCat("region ", i, ": chunk ", chunk.x(), ",", chunk.y(), ",",
                                  chunk.z(), " listed twice"));
    }
  }
  if (p != end) return corrupt("bytes after the last region");
  return out;
}

}  // namespace carvemap

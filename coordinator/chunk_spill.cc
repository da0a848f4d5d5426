#include "coordinator/chunk_spill.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <utility>

#include "absl/strings/str_cat.h"
#include "coordinator/chunk_binning.h"
#include "services/geometry/wedge_geometry.h"
#include "storage/crc32c.h"
#include "storage/wedge_codec.h"

namespace carvemap {
namespace {

constexpr char kMagic[8] = {'C', 'M', 'W', 'E', 'D', 'G', 'E', 'S'};
constexpr uint32_t kVersion = kChunkSpillVersion;
constexpr size_t kHeaderBytes = 48;

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

std::string EncodeHeader(const ChunkKey& chunk, uint64_t count, uint64_t payload_bytes,
                         uint32_t payload_crc) {
  std::string h(kHeaderBytes, '\0');
  std::memcpy(h.data(), kMagic, 8);
  PutU32(kVersion, h.data() + 8);
  for (int a = 0; a < 3; ++a) PutU32(uint32_t(chunk[a]), h.data() + 12 + 4 * a);
  PutU64(count, h.data() + 24);
  PutU64(payload_bytes, h.data() + 32);
  PutU32(payload_crc, h.data() + 40);
  PutU32(Crc32cExtend(0, std::string_view(h.data(), 44)), h.data() + 44);
  return h;
}

absl::Status IoError(std::string_view what, const std::string& path) {
  return absl::InternalError(
      absl::StrCat("chunk spill ", std::string(what), " ", path, ": ", std::strerror(errno)));
}

// Writes all of `data` at the file offset (pwrite) or the end (O_APPEND, offset < 0).
absl::Status WriteAll(int fd, std::string_view data, off_t offset, const std::string& path) {
  while (!data.empty()) {
    const ssize_t n = offset < 0 ? ::write(fd, data.data(), data.size())
                                 : ::pwrite(fd, data.data(), data.size(), offset);
    if (n < 0) {
      if (errno == EINTR) continue;
      return IoError("write", path);
    }
    data.remove_prefix(size_t(n));
    if (offset >= 0) offset += n;
  }
  return absl::OkStatus();
}

// Closes on every path, and reports close errors (delayed write errors on NFS show up there).
class Fd {
 public:
  Fd(int fd, std::string path) : fd_(fd), path_(std::move(path)) {}
  ~Fd() {
    if (fd_ >= 0) ::close(fd_);
  }
  [[nodiscard]] int get() const { return fd_; }
  absl::Status Close() {
    const int fd = std::exchange(fd_, -1);
    return ::close(fd) == 0 ? absl::OkStatus() : IoError("close", path_);
  }

 private:
  int fd_;
  std::string path_;
};

ChunkKey ToChunk(const std::array<int, 3>& k) { return ChunkKey(k[0], k[1], k[2]); }

}  // namespace

struct ChunkSpiller::ChunkState {
  WedgePayloadWriter writer;  // which rays and frames the chunk's payload already holds
  std::string buffer;        // records not yet on disk
  uint64_t wedge_count = 0;  // all records, buffered or written
  uint64_t written_bytes = 0;
  uint32_t crc = 0;          // of the written records
  bool file_started = false;
};

absl::Status ChunkSpillOptions::Validate() const {
  if (dir.empty()) return absl::InvalidArgumentError("chunk spill: dir is empty");
  if (memory_budget_bytes == 0) {
    return absl::InvalidArgumentError("chunk spill: memory_budget_bytes is 0");
  }
  if (!(sigmas >= 0 && sigmas <= 10)) {
    return absl::InvalidArgumentError(absl::StrCat("chunk spill: sigmas ", sigmas,
                                                   " is outside [0, 10]"));
  }
  return absl::OkStatus();
}

std::string ChunkSpillPath(std::string_view dir, const ChunkKey& chunk) {
  return absl::StrCat(std::string(dir), "/chunk_", chunk.x(), "_", chunk.y(), "_", chunk.z(), ".wedges");
}

absl::StatusOr<std::unique_ptr<ChunkSpiller>> ChunkSpiller::Create(
    const ChunkSpillOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  std::error_code ec;
  std::filesystem::create_directories(options.dir, ec);
  if (ec) {
    return absl::InternalError(
        absl::StrCat("chunk spill: cannot create ", options.dir, ": ", ec.message()));
  }
  return std::unique_ptr<ChunkSpiller>(new ChunkSpiller(options));
}

ChunkSpiller::ChunkSpiller(const ChunkSpillOptions& options) : options_(options) {}
ChunkSpiller::~ChunkSpiller() = default;

absl::Status ChunkSpiller::Add(const Wedge& wedge) {
  std::array<RayId, 4> ids;
  for (RayId& id : ids) {
    id.sensor = ~uint32_t{0};
    id.frame = anonymous_rays_++;  // its own frame: rays of one frame share their sensor
  }
  return Add(wedge, ids);
}

absl::Status ChunkSpiller::Add(const Wedge& wedge, std::span<const RayId> ids) {
  if (finished_) return absl::FailedPreconditionError("chunk spill: Add after Finish");
  if (absl::Status s = ValidateWedge(wedge); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("chunk spill: ", s.message()));
  }
  if (ids.size() < wedge.num_rays) {
    return absl::InvalidArgumentError(absl::StrCat("chunk spill: ", ids.size(), " ray ids for ",
                                                   int(wedge.num_rays), " rays"));
  }
  for (int r = 0; r < wedge.num_rays; ++r) {
    for (const Eigen::Vector3f& v : {wedge.rays[r].sensor_mean, wedge.rays[r].point_mean}) {
      if ((v.array().abs() >= float(kMaxWorldCoordinateM)).any()) {
        return absl::InvalidArgumentError(absl::StrCat(
            "chunk spill: wedge ray ", r, " reaches beyond ±", kMaxWorldCoordinateM, " m"));
      }
    }
  }
  uint64_t facets = 0;  // sent along: the worker rebuilds the hull without a search
  const std::vector<ChunkKey> chunks =
      ChunksOfWedge(MakeWedgeHull(wedge, options_.sigmas, &facets));
  for (const ChunkKey& c : chunks) {
    ChunkState& state = chunks_[{c.x(), c.y(), c.z()}];
    const size_t before = state.buffer.size();
    state.writer.Add(wedge, ids, state.buffer, facets);
    ++state.wedge_count;
    buffered_bytes_ += state.buffer.size() - before;
  }
  ++wedges_added_;
  records_ += chunks.size();
  if (buffered_bytes_ > options_.memory_budget_bytes) return FlushOverBudget();
  return absl::OkStatus();
}

absl::Status ChunkSpiller::FlushOverBudget() {
  // Largest buffers first, down to half the budget: one flush event writes few, large appends,
  // and the next one is at least half a budget of records away.
  std::vector<std::pair<size_t, const std::array<int, 3>*>> sizes;
  for (const auto& [key, state] : chunks_) {
    if (!state.buffer.empty()) sizes.emplace_back(state.buffer.size(), &key);
  }
  std::sort(sizes.begin(), sizes.end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first > b.first : *a.second < *b.second;
  });
  for (const auto& [size, key] : sizes) {
    if (buffered_bytes_ <= options_.memory_budget_bytes / 2) break;
    if (absl::Status s = FlushChunk(*key, chunks_.at(*key)); !s.ok()) return s;
  }
  return absl::OkStatus();
}

absl::Status ChunkSpiller::FlushChunk(const std::array<int, 3>& key, ChunkState& state) {
  if (state.buffer.empty() && state.file_started) return absl::OkStatus();
  const std::string path = ChunkSpillPath(options_.dir, ToChunk(key)) + ".tmp";
  // The first flush truncates, so a stale .tmp from an interrupted run is replaced; the header
  // is a placeholder until Finish knows the count and checksum.
  const int flags = state.file_started ? O_WRONLY | O_APPEND : O_WRONLY | O_CREAT | O_TRUNC;
  Fd fd(::open(path.c_str(), flags | O_CLOEXEC, 0644), path);
  if (fd.get() < 0) return IoError("open", path);
  if (!state.file_started) {
    if (absl::Status s = WriteAll(fd.get(), std::string(kHeaderBytes, '\0'), -1, path); !s.ok()) {
      return s;
    }
  }
  if (absl::Status s = WriteAll(fd.get(), state.buffer, -1, path); !s.ok()) return s;
  if (absl::Status s = fd.Close(); !s.ok()) return s;
  state.file_started = true;
  state.crc = Crc32cExtend(state.crc, state.buffer);
  state.written_bytes += state.buffer.size();
  buffered_bytes_ -= state.buffer.size();
  std::string().swap(state.buffer);  // give the capacity back, not just the size
  ++flushes_;
  return absl::OkStatus();
}

absl::StatusOr<std::vector<SpilledChunk>> ChunkSpiller::Finish() {
  if (finished_) return absl::FailedPreconditionError("chunk spill: Finish called twice");
  finished_ = true;
  std::vector<SpilledChunk> out;
  out.reserve(chunks_.size());
  for (auto& [key, state] : chunks_) {
    state.writer.Finish(state.buffer);  // the end record: a truncated payload shows
    if (absl::Status s = FlushChunk(key, state); !s.ok()) return s;
    const ChunkKey chunk = ToChunk(key);
    const std::string path = ChunkSpillPath(options_.dir, chunk);
    const std::string tmp = path + ".tmp";
    Fd fd(::open(tmp.c_str(), O_WRONLY | O_CLOEXEC), tmp);
    if (fd.get() < 0) return IoError("open", tmp);
    const std::string header =
        EncodeHeader(chunk, state.wedge_count, state.written_bytes, state.crc);
    if (absl::Status s = WriteAll(fd.get(), header, 0, tmp); !s.ok()) return s;
    if (::fsync(fd.get()) != 0) return IoError("fsync", tmp);
    if (absl::Status s = fd.Close(); !s.ok()) return s;
    if (::rename(tmp.c_str(), path.c_str()) != 0) return IoError("rename", tmp);
    out.push_back(SpilledChunk{chunk, state.wedge_count, kHeaderBytes + state.written_bytes, path});
  }
  chunks_.clear();
  // The renames are durable only once the directory is synced.
  Fd dir(::open(options_.dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC), options_.dir);
  if (dir.get() < 0) return IoError("open directory", options_.dir);
  if (::fsync(dir.get()) != 0) return IoError("fsync directory", options_.dir);
  if (absl::Status s = dir.Close(); !s.ok()) return s;
  return out;
}

absl::StatusOr<ChunkSpillFile> ReadChunkSpillFile(const std::string& path) {
  Fd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC), path);
  if (fd.get() < 0) {
    if (errno == ENOENT) return absl::NotFoundError(absl::StrCat("chunk spill file ", path,
                                                                 " does not exist"));
    return IoError("open", path);
  }
  // Reads up to `n` bytes into `out` (fewer only at the end of the file).
  const auto read_into = [&](char* out, size_t n) -> absl::StatusOr<size_t> {
    size_t got = 0;
    while (got < n) {
      const ssize_t r = ::read(fd.get(), out + got, n - got);
      if (r < 0) {
        if (errno == EINTR) continue;
        return IoError("read", path);
      }
      if (r == 0) break;
      got += size_t(r);
    }
    return got;
  };
  auto corrupt = [&path](auto&&... what) {
    return absl::DataLossError(absl::StrCat("chunk spill file ", path, ": ", what...));
  };
  char header[kHeaderBytes];
  absl::StatusOr<size_t> got = read_into(header, kHeaderBytes);
  if (!got.ok()) return got.status();
  if (*got < kHeaderBytes) {
    return corrupt("truncated header (", *got, " of ", kHeaderBytes, " bytes)");
  }
  if (std::memcmp(header, kMagic, 8) != 0) return corrupt("bad magic, not a spill file");
  if (GetU32(header + 44) != Crc32cExtend(0, std::string_view(header, 44))) {
    return corrupt("header checksum mismatch (unfinished or corrupt)");
  }
  if (const uint32_t v = GetU32(header + 8); v != kVersion) {
    return corrupt("unsupported version ", v, " (this build reads ", kVersion,
                   v < kVersion ? "; written by an older ingest: ingest the scan again)" : ")");
  }
  ChunkSpillFile file;
  for (int a = 0; a < 3; ++a) file.chunk[a] = int32_t(GetU32(header + 12 + 4 * a));
  file.wedge_count = GetU64(header + 24);
  const uint64_t payload_bytes = GetU64(header + 32);
  // The payload straight into its string (one byte more, to see a file longer than it says).
  struct stat st;
  if (::fstat(fd.get(), &st) != 0) return IoError("stat", path);
  if (uint64_t(st.st_size) != kHeaderBytes + payload_bytes) {
    const uint64_t has = uint64_t(std::max<off_t>(st.st_size, kHeaderBytes)) - kHeaderBytes;
    return corrupt("has ", has, " payload bytes, header says ", payload_bytes,
                   has < payload_bytes ? " (truncated)" : "");
  }
  file.payload.resize(payload_bytes + 1);
  got = read_into(file.payload.data(), payload_bytes + 1);
  if (!got.ok()) return got.status();
  if (*got != payload_bytes) {
    return corrupt("has ", *got, " payload bytes, header says ", payload_bytes,
                   *got < payload_bytes ? " (truncated)" : "");
  }
  file.payload.resize(payload_bytes);
  if (Crc32cExtend(0, file.payload) != GetU32(header + 40)) {
    return corrupt("payload checksum mismatch");
  }
  // Walk the records: structure and count must agree (values are checked by the decoder).
  absl::StatusOr<uint64_t> count = CountWedgeRecords(file.payload);
  if (!count.ok()) return corrupt(count.status().message());
  if (*count != file.wedge_count) {
    return corrupt("holds ", *count, " wedge records, header says ", file.wedge_count);
  }
  return file;
}

absl::StatusOr<std::vector<Wedge>> ReadChunkWedges(std::string_view dir, const ChunkKey& chunk) {
  const std::string path = ChunkSpillPath(dir, chunk);
  absl::StatusOr<ChunkSpillFile> file = ReadChunkSpillFile(path);
  if (!file.ok()) return file.status();
  if (file->chunk != chunk) {
    return absl::DataLossError(absl::StrCat("chunk spill file ", path, ": holds chunk ",
                                            file->chunk.x(), ",", file->chunk.y(), ",",
                                            file->chunk.z()));
  }
  absl::StatusOr<std::vector<Wedge>> wedges = DecodeWedges(file->payload);
  if (!wedges.ok()) {
    return absl::DataLossError(
        absl::StrCat("chunk spill file ", path, ": ", wedges.status().message()));
  }
  return wedges;
}

}  // namespace carvemap

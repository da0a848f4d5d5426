#include "storage/import/ros2_bag_reader.h"

#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <span>
#include <utility>

#include <sqlite3.h>
#include <zlib.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"
#include "storage/import/byte_reader.h"
#include "storage/import/decompress.h"

namespace carvemap {
namespace {

static_assert(std::endian::native == std::endian::little,
              "MCAP is little-endian; the reader copies numbers as they are");

constexpr char kMcapMagic[] = "\x89MCAP0\r\n";
constexpr size_t kMcapMagicSize = 8;
constexpr char kSqliteMagic[] = "SQLite format 3";  // then a NUL: 16 bytes
constexpr uint8_t kOpFooter = 0x02, kOpSchema = 0x03, kOpChannel = 0x04, kOpMessage = 0x05,
                  kOpChunk = 0x06, kOpDataEnd = 0x0F;
// A chunk's stated size is checked against these before it is allocated (writers make chunks
// of a few MiB; sensor data does not compress by more than this factor).
constexpr uint64_t kMaxChunkBytes = uint64_t{1} << 30;
constexpr uint64_t kMaxChunkRatio = 1000;

RosEncoding EncodingOf(absl::string_view name) {
  return name == "cdr"    ? RosEncoding::kCdr
         : name == "ros1" ? RosEncoding::kRos1
                          : RosEncoding::kUnknown;
}

uint32_t Crc32(uint32_t crc, std::span<const uint8_t> bytes) {
  // zlib's crc32 is MCAP's CRC-32 (the IEEE polynomial); fed in pieces below 4 GiB.
  while (!bytes.empty()) {
    const size_t n = std::min<size_t>(bytes.size(), 1u << 30);
    crc = static_cast<uint32_t>(crc32(crc, bytes.data(), static_cast<uInt>(n)));
    bytes = bytes.subspan(n);
  }
  return crc;
}

// Little-endian fields of an MCAP record's content.
using Fields = import_internal::SpanReader;

class McapParser {
 public:
  McapParser(const std::string& path, const BagMessageFn& fn, uint64_t* next_index,
             std::deque<BagConnection>* connections)
      : path_(path), fn_(fn), next_index_(next_index), connections_(connections) {}

  absl::Status Run() {
    absl::StatusOr<import_internal::ByteReader> r = import_internal::ByteReader::Open(path_);
    if (!r.ok()) return r.status();
    uint8_t magic[kMcapMagicSize];
    if (!r->ReadBytes(magic, kMcapMagicSize) ||
        std::memcmp(magic, kMcapMagic, kMcapMagicSize) != 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(path_, ": not an MCAP file (it does not start with MCAP's magic)"));
    }
    uint32_t crc = Crc32(0, std::span<const uint8_t>(magic, kMcapMagicSize));
    std::vector<uint8_t> content;
    while (true) {
      const uint64_t at = r->offset();
      uint8_t op = 0;
      uint64_t len = 0;
      if (!r->Read(op) || !r->Read(len) || len > r->remaining()) {
        return absl::DataLossError(absl::StrCat(
            path_, ": record at byte ", at,
            " runs past the end of the file before the data end record (an MCAP file cut short?)"));
      }
      content.resize(len);
      if (!r->ReadBytes(content.data(), len)) return CutShort(at);
      if (op == kOpDataEnd) {
        Fields f(content);
        uint32_t stated = 0;
        if (!f.Read(stated)) return Bad(at, "a data end record without its CRC");
        if (stated != 0 && stated != crc) {
          return Bad(at, absl::StrCat("the data section's CRC-32 is ", crc, ", the file says ",
                                      stated, " (a corrupt file)"));
        }
        return absl::OkStatus();
      }
      if (op == kOpFooter) return absl::OkStatus();  // no data end record: an older writer
      uint8_t head[9] = {op};
      std::memcpy(head + 1, &len, sizeof(len));  // little-endian, as read
      crc = Crc32(Crc32(crc, head), content);
      absl::Status s = op == kOpChunk ? Chunk(at, content) : Record(at, op, content);
      if (!s.ok()) return s;
    }
  }

 private:
  absl::Status Bad(uint64_t at, absl::string_view why) const {
    return absl::InvalidArgumentError(absl::StrCat(path_, ": record at byte ", at, ": ", why));
  }
  absl::Status CutShort(uint64_t at) const {
    return absl::DataLossError(
        absl::StrCat(path_, ": record at byte ", at,
                     " runs past the end of the file (an MCAP file cut short?)"));
  }

  absl::Status Chunk(uint64_t at, std::span<const uint8_t> content) {
    Fields f(content);
    uint64_t start = 0, end = 0, size = 0, records_len = 0;
    uint32_t stated_crc = 0;
    std::string compression;
    std::span<const uint8_t> data;
    if (!f.Read(start) || !f.Read(end) || !f.Read(size) || !f.Read(stated_crc) ||
        !f.String(compression) || !f.Read(records_len) || !f.Bytes(records_len, data)) {
      return Bad(at, "a chunk's fields run past its end");
    }
    if (size > kMaxChunkBytes || size > kMaxChunkRatio * data.size() + 4096) {
      return Bad(at, absl::StrCat("a chunk claims ", size, " bytes from ", data.size()));
    }
    std::span<const uint8_t> records = data;
    if (compression == "zstd" || compression == "lz4") {
      plain_.resize(size);
      absl::Status s = compression == "zstd" ? import_internal::DecompressZstd(data, plain_)
                                             : import_internal::DecompressLz4Frame(data, plain_);
      if (!s.ok()) return Bad(at, s.message());
      records = plain_;
    } else if (!compression.empty()) {
      return Bad(at, absl::StrCat("unknown chunk compression \"", compression,
                                  "\" (zstd, lz4 and none are read)"));
    } else if (size != data.size()) {
      return Bad(at, absl::StrCat("an uncompressed chunk of ", data.size(), " bytes says ", size));
    }
    if (stated_crc != 0 && Crc32(0, records) != stated_crc) {
      return Bad(at, absl::StrCat("the chunk's CRC-32 is ", Crc32(0, records), ", the file says ",
                                  stated_crc, " (a corrupt file)"));
    }
    // The inner records use the same layout; `at` stays the chunk's offset in errors.
    Fields c(records);
    while (c.left() > 0) {
      uint8_t op = 0;
      uint64_t len = 0;
      std::span<const uint8_t> body;
      if (!c.Read(op) || !c.Read(len) || !c.Bytes(len, body)) {
        return Bad(at, "a record inside the chunk runs past the chunk's end");
      }
      if (absl::Status s = Record(at, op, body); !s.ok()) return s;
    }
    return absl::OkStatus();
  }

  absl::Status Record(uint64_t at, uint8_t op, std::span<const uint8_t> content) {
    Fields f(content);
    if (op == kOpSchema) {
      uint16_t id = 0;
      std::string name;
      if (!f.Read(id) || !f.String(name)) return Bad(at, "a schema's fields run past its end");
      schemas_[id] = std::move(name);
    } else if (op == kOpChannel) {
      uint16_t id = 0, schema = 0;
      std::string topic, encoding;
      if (!f.Read(id) || !f.Read(schema) || !f.String(topic) || !f.String(encoding)) {
        return Bad(at, "a channel's fields run past its end");
      }
      if (channels_.contains(id)) return absl::OkStatus();
      auto s = schemas_.find(schema);
      if (schema != 0 && s == schemas_.end()) {
        return Bad(at, absl::StrCat("channel ", id, " (", topic, ") names schema ", schema,
                                    ", which no record declared"));
      }
      connections_->push_back(
          {id, topic, schema == 0 ? std::string() : s->second, "", EncodingOf(encoding)});
      channels_.emplace(id, &connections_->back());
    } else if (op == kOpMessage) {
      uint16_t channel = 0;
      uint32_t sequence = 0;
      uint64_t log_time = 0, publish_time = 0;
      if (!f.Read(channel) || !f.Read(sequence) || !f.Read(log_time) || !f.Read(publish_time)) {
        return Bad(at, "a message's fields run past its end");
      }
      auto c = channels_.find(channel);
      if (c == channels_.end()) {
        return Bad(at,
                   absl::StrCat("a message of channel ", channel, ", which no record declared"));
      }
      BagMessage m{c->second, log_time * 1e-9, f.Rest(), (*next_index_)++};
      return fn_(m);
    }
    return absl::OkStatus();  // attachments, metadata, indexes, statistics
  }

  const std::string& path_;
  const BagMessageFn& fn_;
  uint64_t* next_index_;
  std::deque<BagConnection>* connections_;
  std::map<uint16_t, std::string> schemas_;
  std::map<uint16_t, const BagConnection*> channels_;
  std::vector<uint8_t> plain_;
};

// rosbag2's sqlite3 storage.
absl::Status ReadDb3(const std::string& path, const BagMessageFn& fn, uint64_t* next_index,
                     std::deque<BagConnection>* connections) {
  sqlite3* raw = nullptr;
  // Read-only and immutable: nothing is written beside the bag (no journal, no lock).
  const std::string uri = absl::StrCat("file:", path, "?immutable=1");
  const int open_rc =
      sqlite3_open_v2(uri.c_str(), &raw, SQLITE_OPEN_READONLY | SQLITE_OPEN_URI, nullptr);
  const std::unique_ptr<sqlite3, decltype(&sqlite3_close)> db(raw, &sqlite3_close);
  auto error = [&](absl::string_view doing) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", doing, ": ",
                                                   db ? sqlite3_errmsg(db.get()) : "no memory",
                                                   " (not a rosbag2 sqlite3 bag?)"));
  };
  if (open_rc != SQLITE_OK) return error("cannot open");
  using Statement = std::unique_ptr<sqlite3_stmt, decltype(&sqlite3_finalize)>;
  auto prepare = [&](const char* sql) -> absl::StatusOr<Statement> {
    sqlite3_stmt* st = nullptr;
    if (sqlite3_prepare_v2(db.get(), sql, -1, &st, nullptr) != SQLITE_OK) {
      return error(absl::StrCat("cannot run \"", sql, "\""));
    }
    return Statement(st, &sqlite3_finalize);
  };
  auto text = [](sqlite3_stmt* st, int col) {
    const unsigned char* t = sqlite3_column_text(st, col);
    return t ? std::string(reinterpret_cast<const char*>(t)) : std::string();
  };
  absl::StatusOr<Statement> topics =
      prepare("SELECT id, name, type, serialization_format FROM topics");
  if (!topics.ok()) return topics.status();
  std::map<int64_t, const BagConnection*> by_id;
  int rc = 0;
  while ((rc = sqlite3_step(topics->get())) == SQLITE_ROW) {
    const int64_t id = sqlite3_column_int64(topics->get(), 0);
    connections->push_back({static_cast<uint32_t>(id), text(topics->get(), 1),
                            text(topics->get(), 2), "", EncodingOf(text(topics->get(), 3))});
    by_id[id] = &connections->back();
  }
  if (rc != SQLITE_DONE) return error("reading its topics");
  absl::StatusOr<Statement> messages =
      prepare("SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id");
  if (!messages.ok()) return messages.status();
  sqlite3_stmt* st = messages->get();
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    const int64_t topic = sqlite3_column_int64(st, 0);
    auto c = by_id.find(topic);
    if (c == by_id.end()) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": message ", *next_index,
                                                     " is of topic ", topic,
                                                     ", which the topics table lacks"));
    }
    const auto* data = static_cast<const uint8_t*>(sqlite3_column_blob(st, 2));
    const int n = sqlite3_column_bytes(st, 2);
    BagMessage m{c->second, sqlite3_column_int64(st, 1) * 1e-9,
                 std::span<const uint8_t>(data, data ? static_cast<size_t>(n) : 0),
                 (*next_index)++};
    if (absl::Status s = fn(m); !s.ok()) return s;
  }
  if (rc != SQLITE_DONE) return error("reading its messages");
  return absl::OkStatus();
}

enum class FileKind { kMcap, kSqlite, kOther };

FileKind KindOf(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  char head[16] = {};
  in.read(head, sizeof(head));
  if (in.gcount() >= static_cast<std::streamsize>(kMcapMagicSize) &&
      std::memcmp(head, kMcapMagic, kMcapMagicSize) == 0) {
    return FileKind::kMcap;
  }
  if (in.gcount() == 16 && std::memcmp(head, kSqliteMagic, 16) == 0) return FileKind::kSqlite;
  return FileKind::kOther;
}

// The files of a bag directory, in the order metadata.yaml lists them.
absl::StatusOr<std::vector<std::string>> DirectoryFiles(const std::string& dir) {
  const std::string meta = (std::filesystem::path(dir) / "metadata.yaml").string();
  std::ifstream in(meta);
  if (!in) return absl::NotFoundError(absl::StrCat(dir, ": a directory without metadata.yaml"));
  std::vector<std::string> files;
  std::string line;
  bool in_list = false;
  while (std::getline(in, line)) {
    absl::string_view l = absl::StripAsciiWhitespace(line);
    if (absl::ConsumePrefix(&l, "relative_file_paths:")) {
      in_list = true;
    } else if (in_list && absl::ConsumePrefix(&l, "- ")) {
      files.push_back(
          (std::filesystem::path(dir) / std::string(absl::StripAsciiWhitespace(l))).string());
    } else if (in_list && !l.empty()) {
      in_list = false;
    }
    if (absl::ConsumePrefix(&l, "compression_format:")) {
      l = absl::StripAsciiWhitespace(l);
      if (!l.empty() && l != "''" && l != "\"\"") {
        return absl::UnimplementedError(
            absl::StrCat(meta, ": the bag is compressed (", l,
                         "); `ros2 bag convert` without compression rewrites it"));
      }
    }
  }
  if (files.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(meta, ": no relative_file_paths listed"));
  }
  return files;
}

}  // namespace

bool IsRos2Bag(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    return std::filesystem::exists(std::filesystem::path(path) / "metadata.yaml", ec);
  }
  return KindOf(path) != FileKind::kOther;
}

absl::Status ReadRos2Bag(const std::string& path, const BagMessageFn& fn,
                         std::vector<BagConnection>* connections) {
  std::vector<std::string> files = {path};
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    absl::StatusOr<std::vector<std::string>> listed = DirectoryFiles(path);
    if (!listed.ok()) return listed.status();
    files = *std::move(listed);
  }
  // Each file declares its own topics; a deque keeps their addresses while messages point to
  // them.
  std::deque<BagConnection> all;
  uint64_t next_index = 0;
  for (const std::string& file : files) {
    if (!std::filesystem::is_regular_file(file, ec)) {
      return absl::NotFoundError(absl::StrCat(file, ": cannot open (no such file)"));
    }
    absl::Status s;
    switch (KindOf(file)) {
      case FileKind::kMcap:
        s = McapParser(file, fn, &next_index, &all).Run();
        break;
      case FileKind::kSqlite:
        s = ReadDb3(file, fn, &next_index, &all);
        break;
      case FileKind::kOther:
        s = absl::InvalidArgumentError(absl::StrCat(
            file, ": neither an MCAP file nor rosbag2's sqlite3 storage (by its first bytes)"));
        break;
    }
    if (!s.ok()) return s;
  }
  if (connections) {
    connections->clear();
    for (const BagConnection& c : all) {
      const bool seen = std::any_of(connections->begin(), connections->end(), [&](const auto& d) {
        return d.topic == c.topic && d.type == c.type;
      });
      if (!seen) connections->push_back(c);
    }
  }
  return absl::OkStatus();
}

}  // namespace carvemap

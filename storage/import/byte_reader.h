// Internal to the importers: sequential reads of fixed-size numbers from a binary file, with
// the byte offset and the remaining size known, so parsers can bound counts before allocating;
// and the same over bytes already in memory (records, chunks, messages).
#pragma once

#include <bit>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <memory>
#include <span>
#include <string>
#include <type_traits>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"

namespace carvemap::import_internal {

class ByteReader {
 public:
  // Opens `path` for reading; numbers are little-endian until set_big_endian(true).
  static absl::StatusOr<ByteReader> Open(const std::string& path) {
    std::FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
    ByteReader r(f);
    if (std::fseek(f, 0, SEEK_END) != 0) return absl::DataLossError(path + ": cannot seek");
    const long size = std::ftell(f);
    if (size < 0 || std::fseek(f, 0, SEEK_SET) != 0) {
      return absl::DataLossError(path + ": cannot seek");
    }
    r.size_ = static_cast<uint64_t>(size);
    return r;
  }

  void set_big_endian(bool big_endian) { big_endian_ = big_endian; }
  [[nodiscard]] uint64_t offset() const { return offset_; }
  [[nodiscard]] uint64_t size() const { return size_; }
  [[nodiscard]] uint64_t remaining() const { return size_ - offset_; }

  // Reads `n` raw bytes; false at end of file (the offset then stays where the read began).
  bool ReadBytes(void* out, size_t n) {
    if (n > remaining()) return false;
    if (std::fread(out, 1, n, file_.get()) != n) return false;
    offset_ += n;
    return true;
  }
  // Reads one byte as unsigned char, or EOF at the end (text parts of a file).
  int GetChar() {
    const int c = std::getc(file_.get());
    if (c != EOF) ++offset_;
    return c;
  }
  // Moves to byte `at`; false past the end.
  bool Seek(uint64_t at) {
    if (at > size_) return false;
    if (std::fseek(file_.get(), static_cast<long>(at), SEEK_SET) != 0) return false;
    offset_ = at;
    return true;
  }
  // Skips `n` bytes; false if fewer remain.
  bool Skip(uint64_t n) {
    if (n > remaining()) return false;
    if (std::fseek(file_.get(), static_cast<long>(n), SEEK_CUR) != 0) return false;
    offset_ += n;
    return true;
  }
  // Reads one arithmetic value in the file's byte order.
  template <typename T>
  bool Read(T& value) {
    static_assert(std::is_arithmetic_v<T>, "Read() takes numbers");
    unsigned char bytes[sizeof(T)];
    if (!ReadBytes(bytes, sizeof(T))) return false;
    if (big_endian_ != (std::endian::native == std::endian::big)) {
      for (size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(bytes[i], bytes[sizeof(T) - 1 - i]);
    }
    std::memcpy(&value, bytes, sizeof(T));
    return true;
  }

 private:
  struct Closer {
    void operator()(std::FILE* f) const { std::fclose(f); }
  };
  explicit ByteReader(std::FILE* f) : file_(f) {}
  std::unique_ptr<std::FILE, Closer> file_;
  uint64_t size_ = 0, offset_ = 0;
  bool big_endian_ = false;
};

// Little-endian reads from a byte span (the formats read this way are little-endian; the
// importers assert the host is). Each read fails, moving nothing, when too few bytes are left.
class SpanReader {
 public:
  explicit SpanReader(std::span<const uint8_t> d) : d_(d) {}
  [[nodiscard]] size_t left() const { return d_.size() - pos_; }

  template <typename T>
  bool Read(T& v) {
    static_assert(std::is_arithmetic_v<T>, "Read() takes numbers");
    if (sizeof(T) > left()) return false;
    std::memcpy(&v, d_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return true;
  }
  bool Bytes(uint64_t n, std::span<const uint8_t>& out) {
    if (n > left()) return false;
    out = d_.subspan(pos_, n);
    pos_ += n;
    return true;
  }
  // A u32 length, then that many bytes.
  bool String(std::string& s) {
    uint32_t n = 0;
    std::span<const uint8_t> b;
    if (!Read(n) || !Bytes(n, b)) return false;
    s.assign(reinterpret_cast<const char*>(b.data()), b.size());
    return true;
  }
  // Moves to the next multiple of `n` bytes from the span's start.
  bool Align(size_t n) {
    const size_t pad = (n - pos_ % n) % n;
    if (pad > left()) return false;
    pos_ += pad;
    return true;
  }
  std::span<const uint8_t> Rest() {
    std::span<const uint8_t> r = d_.subspan(pos_);
    pos_ = d_.size();
    return r;
  }

 private:
  std::span<const uint8_t> d_;
  size_t pos_ = 0;
};

}  // namespace carvemap::import_internal

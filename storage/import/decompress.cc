#include "storage/import/decompress.h"

#include <memory>

#include <bzlib.h>
#include <lz4frame.h>
#include <zstd.h>

#include "absl/strings/str_cat.h"

namespace carvemap::import_internal {
namespace {

absl::Status Short(const char* what, size_t size, absl::string_view why) {
  return absl::InvalidArgumentError(absl::StrCat("its ", what, " data does not decompress to its ",
                                                 size, " bytes", why.empty() ? "" : " (", why,
                                                 why.empty() ? "" : ")"));
}

}  // namespace

absl::Status DecompressBz2(std::span<const uint8_t> in, std::span<uint8_t> out) {
  unsigned int out_len = static_cast<unsigned int>(out.size());
  const int rc =
      BZ2_bzBuffToBuffDecompress(reinterpret_cast<char*>(out.data()), &out_len,
                                 const_cast<char*>(reinterpret_cast<const char*>(in.data())),
                                 static_cast<unsigned int>(in.size()), 0, 0);
  if (rc != BZ_OK || out_len != out.size()) {
    return Short("bz2", out.size(), absl::StrCat("bzip2 error ", rc));
  }
  return absl::OkStatus();
}

absl::Status DecompressLz4Frame(std::span<const uint8_t> in, std::span<uint8_t> out) {
  LZ4F_dctx* ctx = nullptr;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&ctx, LZ4F_VERSION))) {
    return absl::ResourceExhaustedError("cannot create an lz4 decompression context");
  }
  const std::unique_ptr<LZ4F_dctx, decltype(&LZ4F_freeDecompressionContext)> owner(
      ctx, &LZ4F_freeDecompressionContext);
  size_t in_at = 0, out_at = 0;
  while (in_at < in.size()) {
    size_t in_n = in.size() - in_at, out_n = out.size() - out_at;
    const size_t rc =
        LZ4F_decompress(ctx, out.data() + out_at, &out_n, in.data() + in_at, &in_n, nullptr);
    if (LZ4F_isError(rc)) return Short("lz4", out.size(), LZ4F_getErrorName(rc));
    in_at += in_n;
    out_at += out_n;
    if (rc == 0 || (in_n == 0 && out_n == 0)) break;  // the frame's end, or no progress
  }
  if (out_at != out.size() || in_at != in.size()) return Short("lz4", out.size(), "");
  return absl::OkStatus();
}

absl::Status DecompressZstd(std::span<const uint8_t> in, std::span<uint8_t> out) {
  const size_t n = ZSTD_decompress(out.data(), out.size(), in.data(), in.size());
  if (ZSTD_isError(n)) return Short("zstd", out.size(), ZSTD_getErrorName(n));
  if (n != out.size()) return Short("zstd", out.size(), "");
  return absl::OkStatus();
}

}  // namespace carvemap::import_internal

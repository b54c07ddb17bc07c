#include "core/io/gzip.h"

#include <algorithm>
#include <limits>

#include <fmt/format.h>
#include <zlib.h>

namespace distband {

bool isGzip(std::string_view b) { return b.size() >= 2 && uint8_t(b[0]) == 0x1f && uint8_t(b[1]) == 0x8b; }

Status gunzip(std::string_view in, uint64_t expected, std::string_view name, std::string* out) {
  if (expected > uint64_t(std::numeric_limits<size_t>::max() / 2))
    return Status::ResourceExhausted(fmt::format("{}: {} bytes to inflate is too large", name, expected));
  // The buffer grows as the data arrive (doubling, up to `expected`): a short stream whose header declares much never
  // costs what it declares.
  std::string result(
      size_t(std::min<uint64_t>(expected, std::max<uint64_t>(uint64_t(1) << 20, uint64_t(in.size()) * 4))), '\0');
  z_stream zs{};
  if (inflateInit2(&zs, 16 + MAX_WBITS) != Z_OK) return Status::Internal("zlib: inflateInit2 failed");
  size_t consumed = 0, produced = 0;
  Status status;
  for (;;) {
    if (produced == result.size() && result.size() < expected)
      result.resize(size_t(std::min<uint64_t>(expected, uint64_t(result.size()) * 2)));
    // zlib counts in uInt: feed and take at most 1 GiB at a time.
    const size_t in_left = in.size() - consumed, out_left = result.size() - produced;
    zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(in.data() + consumed));
    zs.avail_in = uInt(std::min<size_t>(in_left, size_t(1) << 30));
    // One byte of room beyond `expected` (a scratch byte) shows a stream that would inflate to more.
    char overflow = 0;
    const bool full = out_left == 0;
    zs.next_out = reinterpret_cast<Bytef*>(full ? &overflow : result.data() + produced);
    zs.avail_out = full ? 1 : uInt(std::min<size_t>(out_left, size_t(1) << 30));
    const uInt before_in = zs.avail_in, before_out = zs.avail_out;
    const int rc = inflate(&zs, Z_NO_FLUSH);
    consumed += before_in - zs.avail_in;
    const size_t made = before_out - zs.avail_out;
    if (full && made > 0) {
      status = Status::InvalidArgument(
          fmt::format("{}: the compressed data inflate to more than the {} bytes the header declares", name, expected));
      break;
    }
    if (!full) produced += made;
    if (rc == Z_STREAM_END) {
      // Another gzip member may follow (concatenated streams); anything else is an error.
      if (consumed == in.size()) break;
      if (!isGzip(in.substr(consumed))) {
        status = Status::InvalidArgument(
            fmt::format("{}: {} bytes after the compressed data are no gzip member", name, in.size() - consumed));
        break;
      }
      inflateReset(&zs);
      continue;
    }
    if (rc != Z_OK && rc != Z_BUF_ERROR) {
      status = Status::InvalidArgument(
          fmt::format("{}: corrupt gzip data ({})", name, zs.msg ? zs.msg : "zlib error " + std::to_string(rc)));
      break;
    }
    if (rc == Z_BUF_ERROR && zs.avail_in == 0 && consumed == in.size()) {
      status = Status::InvalidArgument(fmt::format("{}: the gzip data end early (truncated)", name));
      break;
    }
  }
  inflateEnd(&zs);
  if (!status.ok()) return status;
  if (produced != result.size())
    return Status::InvalidArgument(
        fmt::format("{}: the compressed data inflate to {} bytes, the header declares {}", name, produced, expected));
  *out = std::move(result);
  return Status::Ok();
}

Status gunzipPrefix(std::string_view in, size_t at_most, std::string_view name, std::string* out) {
  std::string result(at_most, '\0');
  z_stream zs{};
  if (inflateInit2(&zs, 16 + MAX_WBITS) != Z_OK) return Status::Internal("zlib: inflateInit2 failed");
  zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(in.data()));
  zs.avail_in = uInt(std::min<size_t>(in.size(), size_t(1) << 30));
  zs.next_out = reinterpret_cast<Bytef*>(result.data());
  zs.avail_out = uInt(at_most);
  int rc = Z_OK;
  while (zs.avail_out > 0 && rc == Z_OK) rc = inflate(&zs, Z_NO_FLUSH);
  const size_t produced = at_most - zs.avail_out;
  inflateEnd(&zs);
  if (rc != Z_OK && rc != Z_STREAM_END && !(rc == Z_BUF_ERROR && produced > 0))
    return Status::InvalidArgument(fmt::format("{}: corrupt gzip data", name));
  result.resize(produced);
  *out = std::move(result);
  return Status::Ok();
}

Status gzipCompress(std::string_view data, std::string* out) {
  z_stream zs{};
  if (deflateInit2(&zs, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY) != Z_OK)
    return Status::Internal("zlib: deflateInit2 failed");
  std::string result;
  size_t consumed = 0;
  char buffer[1 << 16];
  int rc = Z_OK;
  do {
    const size_t left = data.size() - consumed;
    zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data() + consumed));
    zs.avail_in = uInt(std::min<size_t>(left, size_t(1) << 30));
    const uInt before = zs.avail_in;
    const int flush = left <= (size_t(1) << 30) ? Z_FINISH : Z_NO_FLUSH;
    do {
      zs.next_out = reinterpret_cast<Bytef*>(buffer);
      zs.avail_out = sizeof buffer;
      rc = deflate(&zs, flush);
      result.append(buffer, sizeof buffer - zs.avail_out);
    } while (zs.avail_out == 0);
    consumed += before - zs.avail_in;
  } while (rc != Z_STREAM_END && rc >= 0);
  deflateEnd(&zs);
  if (rc != Z_STREAM_END) return Status::Internal("zlib: deflate failed");
  *out = std::move(result);
  return Status::Ok();
}

}  // namespace distband

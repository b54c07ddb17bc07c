// Gzip: bounded inflation of untrusted gzip streams and deflation of fields written compressed, in memory (zlib).
// Contract:
//   * isGzip(bytes): the stream starts with gzip's magic (0x1f 0x8b).
//   * gunzip(in, expected, name, out): inflates `in` — one gzip member, or several concatenated — into exactly
//     `expected` bytes. Its buffer grows as the data arrive, up to `expected` (the caller bounds it before, from a
//     header it checked against its limits; while growing the previous half is held too), so a short stream never
//     costs what its header declares and a gzip bomb at most that much: a stream that would inflate to more is
//     refused as soon as it does, one that ends short too; kInvalidArgument naming `name` and what was wrong (a
//     corrupt stream, trailing bytes that are no gzip member, a size other than expected).
//   * gunzipPrefix(in, at_most, name, out): the first min(at_most, the stream's length) inflated bytes (a header
//     read before the size of the rest is known); kInvalidArgument for a corrupt stream within them.
//   * gzipCompress(data, out): a gzip stream of `data` (zlib's default level), which gunzip reads back.
// Pure functions; thread-safe.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "core/status.h"

namespace distband {

bool isGzip(std::string_view bytes);

Status gunzip(std::string_view in, uint64_t expected, std::string_view name, std::string* out);

Status gunzipPrefix(std::string_view in, size_t at_most, std::string_view name, std::string* out);

Status gzipCompress(std::string_view data, std::string* out);

}  // namespace distband

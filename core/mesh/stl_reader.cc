// STL, binary or ascii. A file is binary when its size is exactly 84 + 50 x the triangle count at byte 80 (binary
// files may begin with "solid" too); otherwise it must be ascii (`solid` ... `facet normal` `outer loop` 3 x `vertex
// x y z` `endloop` `endfacet` ... `endsolid`), or it is rejected. Ascii triangles are counted in a first pass so the
// limit is checked before anything is allocated.
#include <cstring>

#include <fmt/format.h>

#include "core/mesh/internal/mesh_reader_parts.h"

namespace distband::mesh_internal {
namespace {

Status readBinary(std::string_view bytes, uint64_t n, const MeshReadLimits& limits, const Interrupter* interrupter,
                  RawMesh* out) {
  if (n > limits.max_triangles)
    return Status::ResourceExhausted(
        fmt::format("STL: the header declares {} triangles, more than the server's limit of {}", n, limits.max_triangles));
  out->vertices.reserve(size_t(3 * n));
  out->triangles.reserve(size_t(n));
  for (uint64_t t = 0; t < n; ++t) {
    if (t % kPollEvery == 0 && isInterrupted(interrupter)) return interrupter->status();
    const char* record = bytes.data() + 84 + 50 * t;
    float v[9];
    std::memcpy(v, record + 12, sizeof v);  // after the facet normal; little-endian like every x86/ARM host
    const uint32_t base = uint32_t(out->vertices.size());
    for (int k = 0; k < 3; ++k) out->vertices.push_back({double(v[3 * k]), double(v[3 * k + 1]), double(v[3 * k + 2])});
    out->triangles.push_back({base, base + 1, base + 2});
  }
  return Status::Ok();
}

Status readAscii(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out) {
  uint64_t facets = 0;
  {
    LineReader lines(bytes);
    std::string_view line;
    while (lines.next(&line)) {
      std::string_view rest = line;
      if (nextToken(&rest) == "facet") ++facets;
    }
  }
  if (facets > limits.max_triangles)
    return Status::ResourceExhausted(
        fmt::format("STL: the file has {} facets, more than the server's limit of {}", facets, limits.max_triangles));
  out->vertices.reserve(size_t(3 * facets));
  out->triangles.reserve(size_t(facets));

  LineReader lines(bytes);
  std::string_view line, rest;
  // The next token of the file, across lines; "" at the end.
  auto token = [&]() -> std::string_view {
    for (;;) {
      const std::string_view t = nextToken(&rest);
      if (!t.empty()) return t;
      if (!lines.next(&line)) return {};
      if (lines.number() % kPollEvery == 0 && isInterrupted(interrupter)) return {};
      rest = line;
    }
  };
  auto expect = [&](std::string_view want) -> Status {
    const std::string_view t = token();
    if (isInterrupted(interrupter)) return interrupter->status();
    if (t == want) return Status::Ok();
    return Status::InvalidArgument(fmt::format("STL line {}: expected '{}', found '{}'", lines.number(), want,
                                               t.empty() ? std::string("the end of the file") : meshExcerpt(t)));
  };
  if (Status s = expect("solid"); !s.ok()) return s;
  rest = {};  // the solid's name is the rest of its line
  for (;;) {
    const std::string_view t = token();
    if (isInterrupted(interrupter)) return interrupter->status();
    if (t.empty()) return Status::InvalidArgument("STL: the file ends without 'endsolid'");
    if (t == "endsolid") {
      rest = {};
      const std::string_view next = token();
      if (next.empty()) return Status::Ok();
      if (next != "solid")
        return Status::InvalidArgument(
            fmt::format("STL line {}: expected 'solid' or the end of the file, found '{}'", lines.number(), meshExcerpt(next)));
      rest = {};
      continue;
    }
    if (t != "facet")
      return Status::InvalidArgument(
          fmt::format("STL line {}: expected 'facet' or 'endsolid', found '{}'", lines.number(), meshExcerpt(t)));
    if (Status s = expect("normal"); !s.ok()) return s;
    for (int k = 0; k < 3; ++k) token();  // the normal is recomputed from the corners
    if (Status s = expect("outer"); !s.ok()) return s;
    if (Status s = expect("loop"); !s.ok()) return s;
    const uint32_t base = uint32_t(out->vertices.size());
    for (int k = 0; k < 3; ++k) {
      if (Status s = expect("vertex"); !s.ok()) return s;
      double c[3];
      for (double& x : c) {
        const std::string_view v = token();
        if (!parseDouble(v, &x))
          return Status::InvalidArgument(
              fmt::format("STL line {}: vertex coordinate '{}' is not a finite number", lines.number(), meshExcerpt(v)));
      }
      out->vertices.push_back({c[0], c[1], c[2]});
    }
    out->triangles.push_back({base, base + 1, base + 2});
    if (Status s = expect("endloop"); !s.ok()) return s;
    if (Status s = expect("endfacet"); !s.ok()) return s;
  }
}

}  // namespace

Status readStl(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out) {
  if (bytes.size() >= 84) {
    uint32_t n = 0;
    std::memcpy(&n, bytes.data() + 80, 4);
    if (bytes.size() == 84 + 50 * uint64_t(n)) return readBinary(bytes, n, limits, interrupter, out);
  }
  std::string_view head = bytes;
  if (nextToken(&head) == "solid") return readAscii(bytes, limits, interrupter, out);
  if (bytes.size() < 84)
    return Status::InvalidArgument(fmt::format("STL: {} bytes are neither an ascii STL nor a binary header", bytes.size()));
  uint32_t n = 0;
  std::memcpy(&n, bytes.data() + 80, 4);
  return Status::InvalidArgument(fmt::format(
      "STL (byte 80): a binary header declaring {} triangles needs {} bytes, but the file has {} (truncated or not STL)",
      n, 84 + 50 * uint64_t(n), bytes.size()));
}

}  // namespace distband::mesh_internal

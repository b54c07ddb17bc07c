// Stanford PLY: ascii, binary_little_endian and binary_big_endian. The header declares elements (name, count) and
// their properties (scalars, or lists with a count type and an item type). Geometry comes from the `vertex` element
// (scalar x, y, z of any numeric type) and the `face` element (a list named vertex_indices or vertex_index of an
// integer type); every other element and property is read past. Elements may come in any order: face indices are
// checked against the vertex count the header declares.
// Bounds: before an element is read, count x its smallest possible record must fit in the bytes that follow; every
// list count must fit in the bytes that follow before its items are read; vertex and face counts are checked against
// the limits before anything is allocated.
#include <algorithm>
#include <bit>
#include <cstring>

#include <fmt/format.h>

#include "core/io/ply_header.h"
#include "core/mesh/internal/mesh_reader_parts.h"

namespace distband::mesh_internal {
namespace {

using ply::Element;
using ply::Encoding;
using ply::Property;
using ply::sizeOf;

}  // namespace

Status readPly(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out) {
  Encoding encoding = Encoding::kAscii;
  std::vector<Element> elements;
  size_t data_offset = 0;
  uint64_t header_lines = 0;
  if (Status s = ply::parseHeader(bytes, &encoding, &elements, &data_offset, &header_lines); !s.ok()) return s;

  // The elements' smallest records: every scalar, and every list's count with no items (ascii: one digit and a
  // separator per value). What the header declares must fit in the bytes that follow it, before any limit applies.
  auto minRecord = [&](const Element& e) {
    uint64_t bytes_per_record = 0;
    for (const Property& p : e.properties)
      bytes_per_record += encoding == Encoding::kAscii ? 2 : sizeOf(p.list ? p.count_type : p.type);
    return bytes_per_record;
  };
  const uint64_t data_bytes = bytes.size() - data_offset;
  uint64_t need = 0;
  for (const Element& e : elements) {
    const uint64_t m = minRecord(e);
    if (m > 0 && e.count > (data_bytes + 1 - std::min(need, data_bytes + 1)) / m)
      return Status::InvalidArgument(fmt::format(
          "PLY element '{}': the header declares {} records of at least {} bytes but only {} bytes of data follow the "
          "header{}",
          meshExcerpt(e.name), e.count, m, data_bytes, need ? " and the elements before it" : ""));
    need += e.count * m;
  }
  uint64_t vertex_count = 0;
  bool have_vertex = false, have_face = false;
  for (const Element& e : elements) {
    if (e.name == "vertex") {
      if (e.x < 0 || e.y < 0 || e.z < 0)
        return Status::InvalidArgument("PLY: element 'vertex' lacks a scalar x, y or z property");
      have_vertex = true;
      vertex_count = e.count;
      if (e.count > limits.max_vertices)
        return Status::ResourceExhausted(fmt::format(
            "PLY: element 'vertex' declares {} vertices, more than the server's limit of {}", e.count, limits.max_vertices));
    }
    if (e.name == "face") {
      if (e.indices < 0)
        return Status::InvalidArgument("PLY: element 'face' lacks a vertex_indices (or vertex_index) list");
      have_face = true;
      if (e.count > limits.max_triangles)
        return Status::ResourceExhausted(fmt::format(
            "PLY: element 'face' declares {} faces, more than the server's limit of {}", e.count, limits.max_triangles));
    }
  }
  if (!have_vertex || !have_face) return Status::InvalidArgument("PLY: the file needs a 'vertex' and a 'face' element");

  ply::Cursor cursor(bytes.substr(data_offset), data_offset, header_lines, encoding);
  std::vector<uint32_t> corners;
  for (const Element& e : elements) {
    const uint64_t min_record = minRecord(e);
    if (min_record > 0 && e.count > (cursor.remaining() + 1) / min_record)
      return Status::InvalidArgument(fmt::format(
          "PLY element '{}': the header declares {} records of at least {} bytes but only {} bytes follow ({})",
          meshExcerpt(e.name), e.count, min_record, cursor.remaining(), cursor.where()));
    if (e.properties.empty()) continue;  // records of nothing take no bytes, however many are declared
    const bool vertex = e.name == "vertex", face = e.name == "face";
    if (vertex) out->vertices.reserve(size_t(e.count));
    if (face) out->triangles.reserve(size_t(e.count));
    for (uint64_t r = 0; r < e.count; ++r) {
      if (r % kPollEvery == 0 && isInterrupted(interrupter)) return interrupter->status();
      double xyz[3] = {0, 0, 0};
      for (int pi = 0; pi < int(e.properties.size()); ++pi) {
        const Property& p = e.properties[size_t(pi)];
        double d = 0;
        int64_t i = 0;
        std::string bad;
        auto fail = [&](const char* what) {
          const std::string where = cursor.where();
          return Status::InvalidArgument(
              bad.empty() ? fmt::format("PLY element '{}' {} ({}): the data ends inside property '{}' {}",
                                        meshExcerpt(e.name), r, where, meshExcerpt(p.name), what)
                          : fmt::format("PLY element '{}' {} ({}): property '{}' {} '{}' is not a finite number of its type",
                                        meshExcerpt(e.name), r, where, meshExcerpt(p.name), what, bad));
        };
        if (!p.list) {
          if (!cursor.read(p.type, &d, &i, &bad)) return fail("");
          if (vertex && pi == e.x) xyz[0] = d;
          if (vertex && pi == e.y) xyz[1] = d;
          if (vertex && pi == e.z) xyz[2] = d;
          continue;
        }
        if (!cursor.read(p.count_type, &d, &i, &bad)) return fail("count");
        const uint64_t item_bytes = encoding == Encoding::kAscii ? 2 : sizeOf(p.type);
        if (i < 0 || uint64_t(i) > (cursor.remaining() + 1) / item_bytes)
          return Status::InvalidArgument(
              fmt::format("PLY element '{}' {} ({}): list '{}' declares {} items but only {} bytes follow",
                          meshExcerpt(e.name), r, cursor.where(), meshExcerpt(p.name), i, cursor.remaining()));
        const bool indices = face && pi == e.indices;
        if (indices) corners.clear();
        for (int64_t k = 0, n = i; k < n; ++k) {
          if (!cursor.read(p.type, &d, &i, &bad)) return fail("item");
          if (!indices) continue;
          if (i < 0 || uint64_t(i) >= vertex_count)
            return Status::InvalidArgument(
                fmt::format("PLY element 'face' {} ({}): index {} is out of range (the header declares {} vertices)", r,
                            cursor.where(), i, vertex_count));
          corners.push_back(uint32_t(i));
        }
        if (indices) {
          if (corners.size() < 3) {
            ++out->non_triangles;
          } else if (Status s = addFan(corners.data(), corners.size(), limits.max_triangles,
                                       fmt::format("PLY element 'face' {}", r), out);
                     !s.ok()) {
            return s;
          }
        }
      }
      if (vertex) out->vertices.push_back({xyz[0], xyz[1], xyz[2]});
    }
  }
  if (encoding == Encoding::kAscii && !cursor.onlySpaceLeft())
    return Status::InvalidArgument(
        fmt::format("PLY ({}): unexpected data after the last element the header declares", cursor.where()));
  return Status::Ok();
}

}  // namespace distband::mesh_internal

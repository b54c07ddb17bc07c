// Wavefront OBJ: `v x y z [w | r g b]` vertices and `f` faces whose corners are `v`, `v/vt`, `v//vn` or `v/vt/vn`
// (1-based, or negative = relative to the vertices so far); a face with fewer than 3 corners is an error (a file cut
// inside a face line). `l` and `p` are counted as non-triangle primitives.
// Everything else — vt, vn, vp, g, o, s, mtllib, usemtl, call, csh, curves — is ignored: no statement ever makes
// the reader look at anything but the bytes it was given. A first pass counts vertices and fan triangles so that
// the limits are checked and the arrays sized before anything is stored.
#include <fmt/format.h>

#include "core/mesh/internal/mesh_reader_parts.h"

namespace distband::mesh_internal {
namespace {

std::string at(uint64_t line) { return fmt::format("OBJ line {}", line); }

}  // namespace

Status readObj(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out) {
  // Pass 1: counts.
  uint64_t vertices = 0, triangles = 0;
  {
    LineReader lines(bytes);
    std::string_view line;
    while (lines.next(&line)) {
      std::string_view rest = line;
      const std::string_view key = nextToken(&rest);
      if (key == "v") {
        ++vertices;
      } else if (key == "f") {
        uint64_t corners = 0;
        while (!nextToken(&rest).empty()) ++corners;
        if (corners >= 3) triangles += corners - 2;
      }
      if (lines.number() % kPollEvery == 0 && isInterrupted(interrupter)) return interrupter->status();
    }
  }
  if (vertices > limits.max_vertices)
    return Status::ResourceExhausted(
        fmt::format("OBJ: the file has {} vertices, more than the server's limit of {}", vertices, limits.max_vertices));
  if (triangles > limits.max_triangles)
    return Status::ResourceExhausted(fmt::format(
        "OBJ: the faces make {} triangles, more than the server's limit of {}", triangles, limits.max_triangles));
  out->vertices.reserve(vertices);
  out->triangles.reserve(triangles);

  // Pass 2: values.
  LineReader lines(bytes);
  std::string_view line;
  std::vector<uint32_t> corners;
  while (lines.next(&line)) {
    if (lines.number() % kPollEvery == 0 && isInterrupted(interrupter)) return interrupter->status();
    std::string_view rest = line;
    const std::string_view key = nextToken(&rest);
    if (key == "v") {
      double c[3];
      for (double& v : c) {
        const std::string_view t = nextToken(&rest);
        if (t.empty())
          return Status::InvalidArgument(fmt::format("{}: a vertex needs 3 coordinates: '{}'", at(lines.number()),
                                                     meshExcerpt(line)));
        if (!parseDouble(t, &v))
          return Status::InvalidArgument(fmt::format("{}: vertex coordinate '{}' is not a finite number",
                                                     at(lines.number()), meshExcerpt(t)));
      }
      out->vertices.push_back({c[0], c[1], c[2]});
    } else if (key == "f") {
      corners.clear();
      for (std::string_view t = nextToken(&rest); !t.empty(); t = nextToken(&rest)) {
        const std::string_view index_text = t.substr(0, t.find('/'));
        int64_t index = 0;
        if (!parseInt(index_text, &index) || index == 0)
          return Status::InvalidArgument(fmt::format("{}: face corner '{}' is not a vertex number (1-based, or negative)",
                                                     at(lines.number()), meshExcerpt(t)));
        const int64_t n = int64_t(out->vertices.size());
        const int64_t resolved = index > 0 ? index - 1 : n + index;
        if (resolved < 0 || resolved >= n)
          return Status::InvalidArgument(fmt::format("{}: face corner {} is out of range ({} vertices so far)",
                                                     at(lines.number()), index, n));
        corners.push_back(uint32_t(resolved));
      }
      if (corners.size() < 3) {
        return Status::InvalidArgument(fmt::format("{}: a face needs at least 3 corners, this one has {}: '{}'",
                                                   at(lines.number()), corners.size(), meshExcerpt(line)));
      } else if (Status s = addFan(corners.data(), corners.size(), limits.max_triangles, at(lines.number()), out);
                 !s.ok()) {
        return s;
      }
    } else if (key == "l" || key == "p") {
      ++out->non_triangles;
    }
  }
  return Status::Ok();
}

}  // namespace distband::mesh_internal

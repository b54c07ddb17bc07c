#include "core/mesh/mesh_reader.h"

#include <algorithm>
#include <cctype>

#include <fmt/format.h>

#include "core/io/text_scan.h"
#include "core/mesh/internal/mesh_reader_parts.h"

namespace distband {

std::string_view meshFormatName(MeshFormat format) {
  switch (format) {
    case MeshFormat::kObj: return "OBJ";
    case MeshFormat::kOff: return "OFF";
    case MeshFormat::kPly: return "PLY";
    case MeshFormat::kStl: return "STL";
  }
  return "?";
}

bool meshFormatFromPath(std::string_view path, MeshFormat* format) {
  const size_t dot = path.find_last_of('.');
  if (dot == std::string_view::npos || path.size() - dot != 4) return false;
  std::string ext(path.substr(dot + 1));
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext == "obj") *format = MeshFormat::kObj;
  else if (ext == "off") *format = MeshFormat::kOff;
  else if (ext == "ply") *format = MeshFormat::kPly;
  else if (ext == "stl") *format = MeshFormat::kStl;
  else return false;
  return true;
}

std::string meshExcerpt(std::string_view text) { return textExcerpt(text, kMeshExcerptBytes); }

uint64_t meshReadPeakBytes(uint64_t input_bytes) {
  // The densest inputs are text faces of long polygons (2 bytes per fan triangle) and short vertex lines (6 bytes per
  // vertex); readers and validation keep at most ~40 bytes per triangle and ~70 per vertex at once (see the test).
  return 24 * input_bytes + (uint64_t(1) << 20);
}

namespace mesh_internal {

Status addFan(const uint32_t* corners, size_t k, uint64_t max_triangles, std::string_view where, RawMesh* out) {
  for (size_t i = 1; i + 1 < k; ++i) {
    const uint32_t a = corners[0], b = corners[i], c = corners[i + 1];
    if (a == b || b == c || a == c) {
      ++out->degenerate;
      continue;
    }
    if (out->triangles.size() >= max_triangles)
      return Status::ResourceExhausted(
          fmt::format("{}: the mesh has more than {} triangles, the server's limit", where, max_triangles));
    out->triangles.push_back({a, b, c});
  }
  return Status::Ok();
}

}  // namespace mesh_internal

Status readMesh(std::string_view bytes, MeshFormat format, const MeshReadLimits& limits,
                const Interrupter* interrupter, TriangleMesh* mesh, MeshReport* report) {
  using namespace mesh_internal;
  if (bytes.empty()) return Status::InvalidArgument(fmt::format("{}: the file is empty", meshFormatName(format)));
  RawMesh raw;
  Status s;
  switch (format) {
    case MeshFormat::kObj: s = readObj(bytes, limits, interrupter, &raw); break;
    case MeshFormat::kOff: s = readOff(bytes, limits, interrupter, &raw); break;
    case MeshFormat::kPly: s = readPly(bytes, limits, interrupter, &raw); break;
    case MeshFormat::kStl: s = readStl(bytes, limits, interrupter, &raw); break;
  }
  if (!s.ok()) return s;
  if (isInterrupted(interrupter)) return interrupter->status();
  TriangleMesh m;
  m.vertices = std::move(raw.vertices);
  m.triangles = std::move(raw.triangles);
  MeshReport r;
  r.non_triangles = raw.non_triangles;
  if (Status s = validateMesh(&m, &r, interrupter); !s.ok())
    return isInterrupted(interrupter) ? s : s.withPrefix(meshFormatName(format));
  r.degenerate += raw.degenerate;
  if (uint64_t(r.vertices) > limits.max_vertices)
    return Status::ResourceExhausted(fmt::format("{}: the mesh has {} vertices, more than the server's limit of {}",
                                                 meshFormatName(format), r.vertices, limits.max_vertices));
  *mesh = std::move(m);
  if (report) *report = r;
  return Status::Ok();
}

}  // namespace distband

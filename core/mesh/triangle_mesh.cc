#include "core/mesh/triangle_mesh.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>

#include <fmt/format.h>
#include <tbb/parallel_sort.h>

#include "core/interruptible.h"
#include "core/io/input_file.h"
#include "core/mesh/mesh_reader.h"

namespace distband {
namespace {

// Bit patterns of a position (with -0 folded into +0), so that identical positions compare equal.
std::array<uint64_t, 3> positionBits(const Vec3d& v) {
  const double c[3] = {v.x + 0.0, v.y + 0.0, v.z + 0.0};
  std::array<uint64_t, 3> b;
  for (int i = 0; i < 3; ++i) std::memcpy(&b[i], &c[i], sizeof(double));
  return b;
}

}  // namespace

std::string MeshReport::summary() const {
  return fmt::format("{} vertices, {} triangles, {} degenerate skipped, {} boundary edges, {} non-manifold edges{}",
                     vertices, triangles, degenerate, boundary_edges, non_manifold_edges,
                     non_triangles ? fmt::format(", {} point/line primitives skipped", non_triangles) : "");
}

Status validateMesh(TriangleMesh* mesh, MeshReport* report, const Interrupter* interrupter) {
  MeshReport r;
  if (mesh->vertices.empty() || mesh->triangles.empty()) return Status::InvalidArgument("the mesh has no triangles");
  if (mesh->vertices.size() >= UINT32_MAX) return Status::InvalidArgument("the mesh has too many vertices");
  for (size_t i = 0; i < mesh->vertices.size(); ++i) {
    const Vec3d& v = mesh->vertices[i];
    if (!(std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z)))
      return Status::InvalidArgument(fmt::format("vertex {} has a non-finite coordinate ({}, {}, {})", i, v.x, v.y, v.z));
  }
  const size_t nv = mesh->vertices.size();
  for (size_t t = 0; t < mesh->triangles.size(); ++t)
    for (uint32_t idx : mesh->triangles[t])
      if (idx >= nv) return Status::InvalidArgument(fmt::format("triangle {} refers to vertex {} but there are {} vertices", t, idx, nv));
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);

  // Weld identical positions: sort vertex ids by position (4 bytes a vertex, not a hash table), map each to the
  // first of its run. Welded ids follow first use below, so the order of the input decides the output.
  std::vector<uint32_t> order(nv), remap(nv);
  std::iota(order.begin(), order.end(), 0u);
  const bool sorted = runInterruptible(interrupter, [&] {
    tbb::parallel_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
      const auto pa = positionBits(mesh->vertices[a]), pb = positionBits(mesh->vertices[b]);
      return pa != pb ? pa < pb : a < b;
    });
  });
  if (!sorted) return interruptedStatus(interrupter);
  for (size_t i = 0; i < nv;) {
    size_t j = i;
    const auto key = positionBits(mesh->vertices[order[i]]);
    while (j < nv && positionBits(mesh->vertices[order[j]]) == key) remap[order[j++]] = order[i];
    i = j;
  }
  std::vector<uint32_t>().swap(order);
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);

  // Drop degenerate triangles (repeated corner, or zero area relative to the longest edge), in place.
  size_t kept = 0;
  for (auto t : mesh->triangles) {
    for (auto& i : t) i = remap[i];
    bool degenerate = t[0] == t[1] || t[1] == t[2] || t[0] == t[2];
    if (!degenerate) {
      const Vec3d &a = mesh->vertices[t[0]], &b = mesh->vertices[t[1]], &c = mesh->vertices[t[2]];
      const double area2 = (b - a).cross(c - a).length();
      const double longest = std::max({(b - a).lengthSqr(), (c - b).lengthSqr(), (a - c).lengthSqr()});
      degenerate = !(area2 > 1e-12 * longest);
    }
    if (degenerate) ++r.degenerate;
    else mesh->triangles[kept++] = t;
  }
  mesh->triangles.resize(kept);
  mesh->triangles.shrink_to_fit();
  if (kept == 0) return Status::InvalidArgument(fmt::format("all {} triangles are degenerate (zero area)", r.degenerate));
  // Keep only referenced vertices, numbered by first use.
  std::vector<uint32_t>& used = remap;  // reused: old id -> new id
  std::fill(used.begin(), used.end(), UINT32_MAX);
  std::vector<Vec3d> vertices;
  for (auto& t : mesh->triangles)
    for (auto& i : t) {
      if (used[i] == UINT32_MAX) {
        used[i] = static_cast<uint32_t>(vertices.size());
        vertices.push_back(mesh->vertices[i]);
      }
      i = used[i];
    }
  std::vector<uint32_t>().swap(remap);
  std::vector<Vec3d>().swap(mesh->vertices);
  vertices.shrink_to_fit();
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);
  // Edge statistics.
  std::vector<uint64_t> edges;
  edges.reserve(mesh->triangles.size() * 3);
  for (const auto& t : mesh->triangles)
    for (int e = 0; e < 3; ++e) {
      const uint64_t a = t[e], b = t[(e + 1) % 3];
      edges.push_back(std::min(a, b) << 32 | std::max(a, b));
    }
  if (!runInterruptible(interrupter, [&] { tbb::parallel_sort(edges.begin(), edges.end()); })) return interruptedStatus(interrupter);
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    if (j - i == 1) ++r.boundary_edges;
    if (j - i > 2) ++r.non_manifold_edges;
    i = j;
  }
  r.bbox_min = r.bbox_max = vertices[0];
  for (const Vec3d& v : vertices) {
    r.bbox_min = {std::min(r.bbox_min.x, v.x), std::min(r.bbox_min.y, v.y), std::min(r.bbox_min.z, v.z)};
    r.bbox_max = {std::max(r.bbox_max.x, v.x), std::max(r.bbox_max.y, v.y), std::max(r.bbox_max.z, v.z)};
  }
  r.vertices = static_cast<int64_t>(vertices.size());
  r.triangles = static_cast<int64_t>(mesh->triangles.size());
  mesh->vertices = std::move(vertices);
  if (report) {
    r.non_triangles = report->non_triangles;
    *report = r;
  }
  return Status::Ok();
}

Status loadMesh(const std::string& path, TriangleMesh* mesh, MeshReport* report) {
  auto fail = [&](const std::string& problem) { return Status::InvalidArgument(fmt::format("{}: {}", path, problem)); };
  MeshFormat format;
  if (!meshFormatFromPath(path, &format))
    return fail("unsupported mesh format (expected .obj, .off, .ply or .stl)");
  std::string bytes;
  if (Status s = readWholeFile(path, kMaxMeshFileBytes, "a mesh", &bytes); !s.ok()) return s;
  if (bytes.empty()) return fail("the file is empty");
  MeshReadLimits limits;
  TriangleMesh loaded;
  MeshReport r;
  if (Status s = readMesh(bytes, format, limits, nullptr, &loaded, &r); !s.ok()) return s.withPrefix(path);
  *mesh = std::move(loaded);
  if (report) *report = r;
  return Status::Ok();
}

}  // namespace distband

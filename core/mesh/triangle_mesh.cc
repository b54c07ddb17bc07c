#include "core/mesh/triangle_mesh.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
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

// Makes the faces of every edge-manifold closed component whose two faces at some edge traverse it the same way
// consistent: breadth-first from the component's first face, a neighbour is flipped when it traverses the shared
// edge the same way as the face reached first; then the component is flipped whole if its signed volume is negative
// (outward). Components are faces connected through edges of exactly two uses; one with an edge of one use or of
// three or more (open, non-manifold), one that cannot be made consistent (non-orientable) or one that had no such
// edge is left as it is, so a consistent but inward part keeps its (inverted) sign, and the rest of the mesh may be
// anything. Returns the number of faces flipped, or -1 when interrupted (the mesh is then unspecified). Memory: 24
// bytes a triangle at the peak (half-edge order and mates), then 17.
int64_t repairOrientation(TriangleMesh* mesh, const Interrupter* interrupter) {
  auto& tris = mesh->triangles;
  const size_t nt = tris.size(), nh = 3 * nt;
  auto key = [&](uint32_t h) {
    const auto& t = tris[h / 3];
    return edgeKey(t[h % 3], t[(h % 3 + 1) % 3], false);
  };
  // mate[h]: the other half-edge of h's edge when exactly two use it, else kNoMate.
  constexpr uint32_t kNoMate = UINT32_MAX;
  std::vector<uint32_t> mate(nh, kNoMate);
  {
    std::vector<uint32_t> order(nh);
    std::iota(order.begin(), order.end(), 0u);
    const bool sorted = runInterruptible(interrupter, [&] {
      tbb::parallel_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
        const uint64_t ka = key(a), kb = key(b);
        return ka != kb ? ka < kb : a < b;
      });
    });
    if (!sorted) return -1;
    for (size_t i = 0; i < nh;) {
      size_t j = i + 1;
      while (j < nh && key(order[j]) == key(order[i])) ++j;
      if (j - i == 2) {
        mate[order[i]] = order[i + 1];
        mate[order[i + 1]] = order[i];
      }
      i = j;
    }
  }
  enum : uint8_t { kVisited = 1, kFlip = 2 };
  std::vector<uint8_t> state(nt, 0);
  std::vector<uint32_t> queue;  // the current component's faces in visiting order
  queue.reserve(nt);
  int64_t flipped = 0;
  size_t polled = 0;
  for (size_t seed = 0; seed < nt; ++seed) {
    if (state[seed] & kVisited) continue;
    queue.clear();
    queue.push_back(static_cast<uint32_t>(seed));
    state[seed] = kVisited;
    bool inconsistent = false, orientable = true, closed = true;
    for (size_t q = 0; q < queue.size(); ++q) {
      if (++polled % 65536 == 0 && isInterrupted(interrupter)) return -1;
      const uint32_t u = queue[q];
      for (uint32_t e = 0; e < 3; ++e) {
        const uint32_t g = mate[3 * u + e], v = g / 3;
        if (g == kNoMate) {
          closed = false;
          continue;
        }
        // Sharing the edge, the two faces run it the same way exactly when they start it at the same vertex.
        const bool same_way = tris[u][e] == tris[v][g % 3];
        inconsistent |= same_way;
        const uint8_t want = (state[u] & kFlip) ^ (same_way ? kFlip : 0);
        if (!(state[v] & kVisited)) {
          state[v] = kVisited | want;
          queue.push_back(v);
        } else if ((state[v] & kFlip) != want) {
          orientable = false;
        }
      }
    }
    if (!inconsistent || !orientable || !closed) continue;
    // Signed volume after the traversal's flips, relative to a vertex of the component (for precision).
    const Vec3d o = mesh->vertices[tris[queue[0]][0]];
    double volume6 = 0;
    for (uint32_t u : queue) {
      const Vec3d a = mesh->vertices[tris[u][0]] - o, b = mesh->vertices[tris[u][1]] - o,
                  c = mesh->vertices[tris[u][2]] - o;
      const double det = a.dot(b.cross(c));
      volume6 += (state[u] & kFlip) ? -det : det;
    }
    const uint8_t flip_if = volume6 < 0 ? 0 : kFlip;  // inward: flip the faces the traversal kept instead
    for (uint32_t u : queue)
      if ((state[u] & kFlip) == flip_if) {
        std::swap(tris[u][1], tris[u][2]);
        ++flipped;
      }
  }
  return flipped;
}

// The mesh's connected parts (findMeshParts) and whether the bounding boxes of some two parts intersect (touching
// counts): a sweep along the longest axis of the whole box that stops at the first such pair. Every vertex must be
// referenced. Parts whose boxes overlap along the sweep axis but nowhere else (slivers side by side) could make the
// sweep quadratic: past 64 box tests a part (plus 2^20) it answers "overlap", the conservative side (the automatic
// sign then takes the winding number, right on any mesh). Returns false when interrupted. Memory: 4 bytes a vertex
// and 52 a part (at most 17 a vertex: a part has 3 vertices or more).
bool findComponents(const TriangleMesh& mesh, const Interrupter* interrupter, int64_t* components, bool* overlap) {
  const size_t nv = mesh.vertices.size();
  std::vector<uint32_t> part;
  const int64_t count = findMeshParts(nv, mesh.triangles, &part, interrupter);
  if (count < 0) return false;
  *components = count;
  *overlap = false;
  if (count < 2) return true;
  constexpr double inf = std::numeric_limits<double>::infinity();
  std::vector<std::array<Vec3d, 2>> box(count, {Vec3d{inf, inf, inf}, Vec3d{-inf, -inf, -inf}});
  Vec3d lo = mesh.vertices[0], hi = lo;
  for (uint32_t v = 0; v < nv; ++v) {
    const Vec3d& p = mesh.vertices[v];
    auto& b = box[part[v]];
    b[0] = {std::min(b[0].x, p.x), std::min(b[0].y, p.y), std::min(b[0].z, p.z)};
    b[1] = {std::max(b[1].x, p.x), std::max(b[1].y, p.y), std::max(b[1].z, p.z)};
    lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
    hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
  }
  std::vector<uint32_t>().swap(part);
  const Vec3d extent = hi - lo;
  const int axis = extent.x >= extent.y && extent.x >= extent.z ? 0 : extent.y >= extent.z ? 1 : 2;
  auto along = [axis](const Vec3d& p) { return axis == 0 ? p.x : axis == 1 ? p.y : p.z; };
  std::vector<uint32_t> order(count);
  std::iota(order.begin(), order.end(), 0u);
  std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return along(box[a][0]) < along(box[b][0]); });
  std::vector<uint32_t> active;  // parts whose extent along the axis reaches the current one's start
  size_t polled = 0, tests = 0;
  const size_t max_tests = 64 * size_t(count) + (size_t(1) << 20);
  for (uint32_t c : order) {
    const auto& b = box[c];
    std::erase_if(active, [&](uint32_t a) { return along(box[a][1]) < along(b[0]); });
    for (uint32_t a : active) {
      const auto& o = box[a];
      if (o[0].x <= b[1].x && b[0].x <= o[1].x && o[0].y <= b[1].y && b[0].y <= o[1].y && o[0].z <= b[1].z &&
          b[0].z <= o[1].z) {
        *overlap = true;
        return true;
      }
    }
    polled += active.size() + 1;
    tests += active.size();
    if (tests > max_tests) {
      *overlap = true;
      return true;
    }
    if (polled >= 65536) {
      polled = 0;
      if (isInterrupted(interrupter)) return false;
    }
    active.push_back(c);
  }
  return true;
}

}  // namespace

int64_t findMeshParts(size_t vertex_count, const std::vector<std::array<uint32_t, 3>>& triangles,
                      std::vector<uint32_t>* part_out, const Interrupter* interrupter) {
  std::vector<uint32_t>& part = *part_out;  // union-find parents first, then each vertex's part
  part.resize(vertex_count);
  std::iota(part.begin(), part.end(), 0u);
  auto root = [&](uint32_t v) {
    while (part[v] != v) v = part[v] = part[part[v]];  // path halving
    return v;
  };
  size_t polled = 0;
  for (const auto& t : triangles) {
    if (++polled % 65536 == 0 && isInterrupted(interrupter)) return -1;
    for (int k = 1; k < 3; ++k) {
      const uint32_t a = root(t[0]), b = root(t[k]);
      if (a != b) part[std::max(a, b)] = std::min(a, b);  // a part's root is its lowest vertex
    }
  }
  // In ascending order every vertex's root is already final; then roots get ids in order and the rest their root's.
  for (size_t v = 0; v < vertex_count; ++v) part[v] = part[part[v]];
  uint32_t count = 0;
  for (size_t v = 0; v < vertex_count; ++v) part[v] = part[v] == v ? count++ : part[part[v]];
  return count;
}

std::string MeshReport::summary() const {
  return fmt::format(
      "{} vertices, {} triangles, {} degenerate skipped, {} boundary edges, {} non-manifold edges{}{}{}{}", vertices,
      triangles, degenerate, boundary_edges, non_manifold_edges,
      non_triangles ? fmt::format(", {} point/line primitives skipped", non_triangles) : "",
      reoriented_faces ? fmt::format(", {} faces re-oriented", reoriented_faces) : "",
      double_sided_faces ? fmt::format(", {} double-sided faces", double_sided_faces) : "",
      components > 1 ? fmt::format(", {} parts{}", components, components_overlap ? " (bounding boxes overlap)" : "")
                     : "");
}

int64_t findDoubleSidedFaces(const std::vector<std::array<uint32_t, 3>>& triangles, std::vector<uint8_t>* twin,
                             const Interrupter* interrupter) {
  // Each face as its sorted corners, which way round it runs them (an even or odd permutation) and its index.
  struct Face {
    uint32_t a, b, c, index_and_way;  // way in bit 31
  };
  if (triangles.size() >= (size_t(1) << 31)) return 0;  // beyond any mesh a reader accepts
  std::vector<Face> faces(triangles.size());
  for (size_t t = 0; t < triangles.size(); ++t) {
    const auto& v = triangles[t];
    // Sorting three items with swaps: each swap flips the permutation's parity.
    uint32_t x = v[0], y = v[1], z = v[2], way = 0;
    if (x > y) std::swap(x, y), way ^= 1;
    if (y > z) std::swap(y, z), way ^= 1;
    if (x > y) std::swap(x, y), way ^= 1;
    faces[t] = {x, y, z, uint32_t(t) | way << 31};
  }
  const auto corners = [](const Face& f) { return std::array<uint32_t, 3>{f.a, f.b, f.c}; };
  if (!runInterruptible(interrupter, [&] {
        tbb::parallel_sort(faces.begin(), faces.end(), [&](const Face& l, const Face& r) {
          return corners(l) != corners(r) ? corners(l) < corners(r) : l.index_and_way < r.index_and_way;
        });
      }))
    return -1;
  int64_t count = 0;
  for (size_t i = 0; i < faces.size();) {
    size_t j = i;
    uint32_t ways = 0;  // bit 0: some copy runs one way, bit 1: the other
    for (; j < faces.size() && corners(faces[j]) == corners(faces[i]); ++j)
      ways |= 1u << (faces[j].index_and_way >> 31);
    if (ways == 3) {
      count += int64_t(j - i);
      if (twin) {
        if (twin->empty()) twin->assign(triangles.size(), 0);
        for (size_t k = i; k < j; ++k) (*twin)[faces[k].index_and_way & 0x7FFFFFFFu] = 1;
      }
    }
    i = j;
  }
  return count;
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
  // Edge statistics, and (below kDirectedKeyVertexLimit vertices) whether some edge's two faces run it the same way.
  const bool directed = vertices.size() < kDirectedKeyVertexLimit;
  const uint64_t edge_mask = directed ? ~uint64_t(1) : ~uint64_t(0);
  int64_t same_way_edges = 0;
  {
    std::vector<uint64_t> edges;
    edges.reserve(mesh->triangles.size() * 3);
    for (const auto& t : mesh->triangles)
      for (int e = 0; e < 3; ++e) edges.push_back(edgeKey(t[e], t[(e + 1) % 3], directed));
    if (!runInterruptible(interrupter, [&] { tbb::parallel_sort(edges.begin(), edges.end()); }))
      return interruptedStatus(interrupter);
    for (size_t i = 0; i < edges.size();) {
      size_t j = i;
      while (j < edges.size() && (edges[j] & edge_mask) == (edges[i] & edge_mask)) ++j;
      if (j - i == 1) ++r.boundary_edges;
      if (j - i > 2) ++r.non_manifold_edges;
      if (j - i == 2 && edges[i] == edges[i + 1]) ++same_way_edges;
      i = j;
    }
  }
  r.bbox_min = r.bbox_max = vertices[0];
  for (const Vec3d& v : vertices) {
    r.bbox_min = {std::min(r.bbox_min.x, v.x), std::min(r.bbox_min.y, v.y), std::min(r.bbox_min.z, v.z)};
    r.bbox_max = {std::max(r.bbox_max.x, v.x), std::max(r.bbox_max.y, v.y), std::max(r.bbox_max.z, v.z)};
  }
  r.vertices = static_cast<int64_t>(vertices.size());
  r.triangles = static_cast<int64_t>(mesh->triangles.size());
  mesh->vertices = std::move(vertices);
  // Re-orient the closed parts with a face patch flipped against its neighbours (the signs would otherwise flip with
  // it), whatever the rest of the mesh is; the half-edge ids must fit 32 bits.
  if (same_way_edges > 0 && mesh->triangles.size() < UINT32_MAX / 3) {
    r.reoriented_faces = repairOrientation(mesh, interrupter);
    if (r.reoriented_faces < 0) return interruptedStatus(interrupter);
  }
  // On a closed mesh a double-sided face's three edges have no other face, so its corners have only its two copies
  // unless other faces are pinched to them: looked for only where some vertex has two faces (every vertex of a closed
  // surface has three or more), which spares the sort (0.3 s for 3.3 M triangles) on the meshes that have none.
  if (r.closed()) {
    std::vector<uint8_t> faces_at(mesh->vertices.size(), 0);  // counted up to 3
    for (const auto& t : mesh->triangles)
      for (uint32_t v : t) faces_at[v] += faces_at[v] < 3;
    if (std::find(faces_at.begin(), faces_at.end(), uint8_t(2)) != faces_at.end()) {
      r.double_sided_faces = findDoubleSidedFaces(mesh->triangles, nullptr, interrupter);
      if (r.double_sided_faces < 0) return interruptedStatus(interrupter);
    }
  }
  if (!findComponents(*mesh, interrupter, &r.components, &r.components_overlap)) return interruptedStatus(interrupter);
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

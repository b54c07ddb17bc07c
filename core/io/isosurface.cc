#include "core/io/isosurface.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iterator>
#include <string_view>
#include <unordered_map>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/io/temp_file.h"

namespace distband {
namespace {

using Tree = VdbTree<float>;

// A cell is the cube of the 8 voxels (m.x + i, m.y + j, m.z + k), i, j, k in {0, 1}; corner bit i | j << 1 | k << 2.
constexpr int kEdges[12][2] = {{0, 1}, {2, 3}, {4, 5}, {6, 7}, {0, 2}, {1, 3}, {4, 6}, {5, 7}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};

struct CellVertex {
  Coord cell;      // the cell's first voxel
  uint8_t inside;  // corner bits below D
  double x, y, z;  // the vertex, index space
};

// The 3x3x3 leaf-sized regions around one leaf: a leaf, or a tile's single value.
struct Neighbourhood {
  Coord origin;
  const Tree::Leaf* leaf[27];
  int64_t index[27];
  float tile[27];
  Neighbourhood(const Tree& tree, const Tree::Leaf& centre) : origin(centre.origin) {
    for (int n = 0; n < 27; ++n) {
      const Coord o{origin.x + 8 * (n % 3 - 1), origin.y + 8 * (n / 3 % 3 - 1), origin.z + 8 * (n / 9 - 1)};
      index[n] = tree.leafIndex(o);
      leaf[n] = index[n] >= 0 ? tree.leaves()[size_t(index[n])] : nullptr;
      tile[n] = leaf[n] ? 0.f : tree.value(o);
    }
  }
  // Region of a local coordinate in [-8, 16).
  static int region(int t) { return t < 0 ? 0 : (t < 8 ? 1 : 2); }
  int regionOf(int x, int y, int z) const { return region(x) + 3 * region(y) + 9 * region(z); }
  float value(int x, int y, int z) const {
    const int n = regionOf(x, y, z);
    return leaf[n] ? leaf[n]->values[size_t(brickOffset(x & 7, y & 7, z & 7))] : tile[n];
  }
};

}  // namespace

Status extractIsosurface(const VdbTree<float>& field, const Grid& grid, const IsosurfaceOptions& options,
                         TriangleMeshF* mesh) {
  mesh->vertices.clear();
  mesh->triangles.clear();
  const double d = options.distance_world;
  if (!std::isfinite(d)) return Status::InvalidArgument(fmt::format("isosurface distance must be finite (got {})", d));
  if (!field.sealed()) return Status::InvalidArgument("isosurface: the field is not finished (sealed)");
  const double background = std::abs(double(field.background()));
  if (!(std::abs(d) < background))
    return Status::InvalidArgument(fmt::format(
        "isosurface distance {} is not inside the field's limit (|D| must be < the grid background {}); "
        "query with a larger limit",
        d, background));
  const float iso = float(d);
  const auto& leaves = field.leaves();
  const size_t n = leaves.size();

  // 1. Per leaf: a vertex for every crossing cell it owns — the cells with a corner in the leaf, each owned by the
  // lowest-numbered leaf holding one of its corners, so every cell is meshed once.
  std::vector<std::vector<CellVertex>> cells(n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 8), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t li = r.begin(); li != r.end(); ++li) {
      const Neighbourhood nb(field, *leaves[li]);
      for (int x = -1; x < 8; ++x)
        for (int y = -1; y < 8; ++y)
          for (int z = -1; z < 8; ++z) {
            if (x < 0 || y < 0 || z < 0 || x == 7 || y == 7 || z == 7) {
              int64_t owner = -1;
              for (int c = 0; c < 8; ++c) {
                const int64_t i = nb.index[nb.regionOf(x + (c & 1), y + (c >> 1 & 1), z + (c >> 2))];
                if (i >= 0 && (owner < 0 || i < owner)) owner = i;
              }
              if (owner != int64_t(li)) continue;
            }
            float v[8];
            uint8_t inside = 0;
            for (int c = 0; c < 8; ++c) {
              v[c] = nb.value(x + (c & 1), y + (c >> 1 & 1), z + (c >> 2));
              if (v[c] < iso) inside |= uint8_t(1 << c);
            }
            if (inside == 0 || inside == 0xFF) continue;
            double sx = 0, sy = 0, sz = 0;
            int crossings = 0;
            for (const auto& e : kEdges) {
              if (((inside >> e[0]) & 1) == ((inside >> e[1]) & 1)) continue;
              const double t = std::clamp((double(iso) - v[e[0]]) / (double(v[e[1]]) - v[e[0]]), 0.0, 1.0);
              const int a = e[0], b = e[1];
              sx += (a & 1) + t * ((b & 1) - (a & 1));
              sy += (a >> 1 & 1) + t * ((b >> 1 & 1) - (a >> 1 & 1));
              sz += (a >> 2) + t * ((b >> 2) - (a >> 2));
              ++crossings;
            }
            const Coord m = nb.origin + Coord{x, y, z};
            cells[li].push_back({m, inside, m.x + sx / crossings, m.y + sy / crossings, m.z + sz / crossings});
          }
    }
  });

  // 2. Vertex ids in leaf order.
  std::vector<size_t> first(n + 1, 0);
  for (size_t li = 0; li < n; ++li) first[li + 1] = first[li] + cells[li].size();
  std::unordered_map<Coord, uint32_t, CoordHash> id_of;
  id_of.reserve(first[n]);
  mesh->vertices.resize(first[n]);
  const Vec3d origin = grid.origin();
  const Vec3d h = grid.spacing();
  for (size_t li = 0; li < n; ++li)
    for (size_t k = 0; k < cells[li].size(); ++k) {
      const CellVertex& cv = cells[li][k];
      const uint32_t id = uint32_t(first[li] + k);
      id_of.emplace(cv.cell, id);
      mesh->vertices[id] = {float(origin.x + h.x * cv.x), float(origin.y + h.y * cv.y), float(origin.z + h.z * cv.z)};
    }

  // 3. A quad for every crossing lattice edge, seen from the cell at its start: the 4 cells around the edge, counter-
  // clockwise seen from the outside (the edge's end where the field is larger).
  std::vector<std::vector<std::array<uint32_t, 3>>> faces(n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 8), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t li = r.begin(); li != r.end(); ++li)
      for (const CellVertex& cv : cells[li])
        for (int a = 0; a < 3; ++a) {
          const bool start_inside = cv.inside & 1;
          if (start_inside == bool((cv.inside >> (1 << a)) & 1)) continue;
          static constexpr Coord kAxis[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
          const Coord eb = kAxis[(a + 1) % 3], ec = kAxis[(a + 2) % 3];
          const Coord around[4] = {cv.cell, {cv.cell.x - eb.x, cv.cell.y - eb.y, cv.cell.z - eb.z},
                                   {cv.cell.x - eb.x - ec.x, cv.cell.y - eb.y - ec.y, cv.cell.z - eb.z - ec.z},
                                   {cv.cell.x - ec.x, cv.cell.y - ec.y, cv.cell.z - ec.z}};
          uint32_t q[4];
          bool complete = true;
          for (int k = 0; k < 4 && complete; ++k) {
            const auto it = id_of.find(around[start_inside ? k : (4 - k) % 4]);
            complete = it != id_of.end();
            if (complete) q[k] = it->second;
          }
          if (!complete) continue;  // a neighbouring cell outside every leaf (the band's clipped edge)
          auto dist2 = [&](uint32_t i, uint32_t j) {
            const auto &p = mesh->vertices[i], &o = mesh->vertices[j];
            return (p[0] - o[0]) * (p[0] - o[0]) + (p[1] - o[1]) * (p[1] - o[1]) + (p[2] - o[2]) * (p[2] - o[2]);
          };
          if (dist2(q[0], q[2]) <= dist2(q[1], q[3])) {
            faces[li].push_back({q[0], q[1], q[2]});
            faces[li].push_back({q[0], q[2], q[3]});
          } else {
            faces[li].push_back({q[0], q[1], q[3]});
            faces[li].push_back({q[1], q[2], q[3]});
          }
        }
  });
  size_t total = 0;
  for (const auto& f : faces) total += f.size();
  mesh->triangles.reserve(total);
  for (const auto& f : faces) mesh->triangles.insert(mesh->triangles.end(), f.begin(), f.end());
  return Status::Ok();
}

Status writeObj(const std::string& path, const TriangleMeshF& mesh, const std::string& comment) {
  for (const auto& t : mesh.triangles)
    for (uint32_t v : t)
      if (v >= mesh.vertices.size())
        return Status::InvalidArgument(fmt::format("OBJ: triangle refers to vertex {} of {}", v, mesh.vertices.size()));

  std::string tmp;
  std::FILE* file = nullptr;
  if (Status s = openTempBeside(path, "w", &tmp, &file); !s.ok()) return s;
  // Format in chunks: far faster than one stdio call per number for million-triangle meshes.
  fmt::memory_buffer buf;
  bool ok = true;
  auto flush = [&](bool force) {
    if (ok && (force || buf.size() > (1u << 20))) {
      ok = std::fwrite(buf.data(), 1, buf.size(), file) == buf.size();
      buf.clear();
    }
  };
  if (!comment.empty()) {
    size_t start = 0;
    while (start <= comment.size()) {
      const size_t end = comment.find('\n', start);
      const size_t stop = end == std::string::npos ? comment.size() : end;
      fmt::format_to(std::back_inserter(buf), "# {}\n", std::string_view(comment).substr(start, stop - start));
      if (end == std::string::npos) break;
      start = end + 1;
    }
  }
  fmt::format_to(std::back_inserter(buf), "# {} vertices, {} triangles\n", mesh.vertices.size(),
                 mesh.triangles.size());
  for (const auto& v : mesh.vertices) {
    fmt::format_to(std::back_inserter(buf), "v {} {} {}\n", v[0], v[1], v[2]);
    flush(false);
  }
  for (const auto& t : mesh.triangles) {
    fmt::format_to(std::back_inserter(buf), "f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    flush(false);
  }
  flush(true);
  return commitTemp(file, tmp, path,
                    ok ? Status::Ok()
                       : Status::IoError(fmt::format("cannot write '{}': {}", tmp, std::strerror(errno))));
}

Status writeIsosurfaceObj(const std::string& path, const VdbTree<float>& field, const Grid& grid,
                          const IsosurfaceOptions& options, TriangleMeshF* mesh_out) {
  TriangleMeshF local;
  TriangleMeshF* mesh = mesh_out ? mesh_out : &local;
  if (Status s = extractIsosurface(field, grid, options, mesh); !s.ok()) return s;
  const std::string name = options.field_name.empty() ? std::string("distance field") : options.field_name;
  return writeObj(path, *mesh,
                  fmt::format("distband isosurface of '{}' at distance {} (world units, negative inside)", name,
                              options.distance_world));
}

}  // namespace distband

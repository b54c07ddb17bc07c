#include "core/io/isosurface.h"

#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <iterator>
#include <string_view>

#include <fmt/format.h>

#include "core/io/temp_file.h"
#include <openvdb/tools/VolumeToMesh.h>

namespace distband {
namespace {

// volumeToMesh emits polygons clockwise when seen from the side where the field is larger (Houdini's
// convention); OBJ expects counter-clockwise front faces, so every polygon is reversed. Verified by the
// signed-volume check in tests/core/isosurface_test.cc.
constexpr bool kReverseWinding = true;

void addTriangle(TriangleMeshF* mesh, uint32_t a, uint32_t b, uint32_t c) {
  if (kReverseWinding)
    mesh->triangles.push_back({a, c, b});
  else
    mesh->triangles.push_back({a, b, c});
}

}  // namespace

std::string extractIsosurface(const openvdb::FloatGrid& grid, const IsosurfaceOptions& options,
                              TriangleMeshF* mesh) {
  mesh->vertices.clear();
  mesh->triangles.clear();
  const double d = options.distance_world;
  if (!std::isfinite(d)) return fmt::format("isosurface distance must be finite (got {})", d);
  if (!(options.adaptivity >= 0 && options.adaptivity <= 1))
    return fmt::format("isosurface adaptivity must be in [0, 1] (got {})", options.adaptivity);
  const double background = grid.background();
  if (!(std::abs(d) < background))
    return fmt::format(
        "isosurface distance {} is not inside the field's limit (|D| must be < the grid background {}); "
        "query with a larger limit",
        d, background);

  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> triangles;
  std::vector<openvdb::Vec4I> quads;
  try {
    openvdb::tools::volumeToMesh(grid, points, triangles, quads, d, options.adaptivity);
  } catch (const std::exception& e) {
    return fmt::format("isosurface extraction failed: {}", e.what());
  }
  mesh->vertices.reserve(points.size());
  for (const openvdb::Vec3s& p : points) mesh->vertices.push_back({p.x(), p.y(), p.z()});
  mesh->triangles.reserve(triangles.size() + 2 * quads.size());
  for (const openvdb::Vec3I& t : triangles) addTriangle(mesh, t[0], t[1], t[2]);
  for (const openvdb::Vec4I& q : quads) {
    addTriangle(mesh, q[0], q[1], q[2]);
    addTriangle(mesh, q[0], q[2], q[3]);
  }
  return {};
}

std::string writeObj(const std::string& path, const TriangleMeshF& mesh, const std::string& comment) {
  for (const auto& t : mesh.triangles)
    for (uint32_t v : t)
      if (v >= mesh.vertices.size())
        return fmt::format("OBJ: triangle refers to vertex {} of {}", v, mesh.vertices.size());

  std::string tmp;
  std::FILE* file = nullptr;
  if (std::string err = openTempBeside(path, "w", &tmp, &file); !err.empty()) return err;
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
  return commitTemp(file, tmp, path, ok ? "" : fmt::format("cannot write '{}': {}", tmp, std::strerror(errno)));
}

std::string writeIsosurfaceObj(const std::string& path, const openvdb::FloatGrid& grid,
                               const IsosurfaceOptions& options, TriangleMeshF* mesh_out) {
  TriangleMeshF local;
  TriangleMeshF* mesh = mesh_out ? mesh_out : &local;
  if (std::string err = extractIsosurface(grid, options, mesh); !err.empty()) return err;
  const std::string name = grid.getName().empty() ? std::string("distance field") : grid.getName();
  return writeObj(path, *mesh,
                  fmt::format("distband isosurface of '{}' at distance {} (world units, negative inside)", name,
                              options.distance_world));
}

}  // namespace distband

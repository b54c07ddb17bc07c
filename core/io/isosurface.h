// Isosurface: the surface at signed distance D of an OpenVDB level set, as a triangle mesh and as a Wavefront OBJ.
// Contract:
//   * extractIsosurface() runs openvdb::tools::volumeToMesh on `grid` at isovalue D (world units, negative
//     inside) and splits every quad into two triangles. Vertices are in world coordinates (the grid's
//     transform). Triangles are wound counter-clockwise seen from outside (the side where the field is larger),
//     the OBJ / OpenGL convention, so normals point away from the inside.
//   * D must be finite and |D| below the grid's background (the field's limit): beyond it the level set holds
//     no surface, and asking for one is reported as an error, not as an empty mesh. A D inside the limit that
//     meets no voxels gives an empty mesh (and an OBJ with no faces).
//   * writeIsosurfaceObj() writes "v x y z" lines then 1-based "f a b c" lines, through a temporary file in
//     the target's directory renamed over `path`, so an interrupted run never leaves a partial OBJ.
//   * Errors come back as a non-empty message; nothing is thrown for bad input or I/O.
// Thread-safety: re-entrant; `grid` is only read (volumeToMesh itself runs multi-threaded on TBB).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <openvdb/openvdb.h>

namespace distband {

struct TriangleMeshF {
  std::vector<std::array<float, 3>> vertices;     ///< world coordinates
  std::vector<std::array<uint32_t, 3>> triangles; ///< 0-based vertex indices, counter-clockwise from outside
};

struct IsosurfaceOptions {
  double distance_world = 0;  ///< the isovalue D
  /// volumeToMesh adaptivity in [0, 1]: 0 keeps every voxel's polygon, larger merges flat regions.
  double adaptivity = 0;
};

/// Extracts the isosurface. Returns "" on success (mesh filled), otherwise why not (mesh cleared).
std::string extractIsosurface(const openvdb::FloatGrid& grid, const IsosurfaceOptions& options,
                              TriangleMeshF* mesh);

/// Writes `mesh` as OBJ to `path` (temp file + rename). `comment` (optional) becomes "# ..." header lines.
std::string writeObj(const std::string& path, const TriangleMeshF& mesh, const std::string& comment = {});

/// extractIsosurface + writeObj. On success `mesh_out` (optional) receives the mesh written.
std::string writeIsosurfaceObj(const std::string& path, const openvdb::FloatGrid& grid,
                               const IsosurfaceOptions& options, TriangleMeshF* mesh_out = nullptr);

}  // namespace distband

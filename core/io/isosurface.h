// Isosurface: the surface at signed distance D of a level set (core/io/vdb_tree.h), as a triangle mesh and as a
// Wavefront OBJ.
// Contract:
//   * extractIsosurface() meshes the cells (cubes of 8 neighbouring voxels) whose values straddle D and that touch
//     a leaf of the tree, by surface nets: one vertex per such cell, at the mean of the points where its 12 edges cross
//     D (linear interpolation of the two voxel values), and one quad per lattice edge that crosses D, joining the
//     vertices of the 4 cells around that edge, split into two triangles along its shorter diagonal. So the mesh is
//     closed and consistently wound wherever the band is, vertices lie within their cells, and the work follows the
//     band's leaves. One vertex a cell means that a cell crossed by two sheets of the surface (a face whose corners
//     alternate in sign: thin features at the voxel scale) joins them at that vertex: a few edges there are shared
//     by four triangles (8 of ~1 M directed edges in the demo's bunny isosurface). Vertices are in world
//     coordinates (origin + voxel size × index, core/grid.h). Triangles are wound counter-clockwise seen from
//     outside (the side where the field is larger), the OBJ / OpenGL convention, so normals point away from the
//     inside. Output is deterministic (leaf order, then cell order), whatever the thread count.
//   * D must be finite and |D| below the tree's background (the field's limit): beyond it the level set holds no
//     surface, and asking for one is reported as an error, not as an empty mesh. A D inside the limit that meets no
//     voxels gives an empty mesh (and an OBJ with no faces). The tree must be sealed (and flood-filled).
//   * writeIsosurfaceObj() writes "v x y z" lines then 1-based "f a b c" lines, through a temporary file in
//     the target's directory renamed over `path`, so an interrupted run never leaves a partial OBJ.
//   * Errors come back as a Status; nothing is thrown for bad input or I/O. kInvalidArgument for a D that is not
//     finite or not inside the limit, an unsealed tree, or a triangle that refers to a missing vertex; kIoError when
//     the OS cannot create, write or rename the OBJ file (the message names the file and the OS's reason).
// Thread-safety: re-entrant; the tree is only read (cells are meshed in parallel on the caller's TBB arena).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/grid.h"
#include "core/io/vdb_tree.h"
#include "core/status.h"

namespace distband {

struct TriangleMeshF {
  std::vector<std::array<float, 3>> vertices;     ///< world coordinates
  std::vector<std::array<uint32_t, 3>> triangles; ///< 0-based vertex indices, counter-clockwise from outside
};

struct IsosurfaceOptions {
  double distance_world = 0;          ///< the isovalue D
  std::string field_name = "distance";  ///< named in the OBJ's header
};

/// Extracts the isosurface of `field`, whose index space is `grid`'s. Returns OK (mesh filled), otherwise
/// kInvalidArgument saying why not (mesh cleared).
Status extractIsosurface(const VdbTree<float>& field, const Grid& grid, const IsosurfaceOptions& options,
                         TriangleMeshF* mesh);

/// Writes `mesh` as OBJ to `path` (temp file + rename). `comment` (optional) becomes "# ..." header lines.
Status writeObj(const std::string& path, const TriangleMeshF& mesh, const std::string& comment = {});

/// extractIsosurface + writeObj. On success `mesh_out` (optional) receives the mesh written.
Status writeIsosurfaceObj(const std::string& path, const VdbTree<float>& field, const Grid& grid,
                          const IsosurfaceOptions& options, TriangleMeshF* mesh_out = nullptr);

}  // namespace distband

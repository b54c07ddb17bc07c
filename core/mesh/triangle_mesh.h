// TriangleMesh: an indexed triangle soup loaded from a file (OBJ, OFF, PLY, STL ascii/binary) and validated.
// Contract: after loadMesh() or validateMesh() succeed, the mesh is non-empty, every coordinate is finite, every
// index is < vertices.size(), no triangle has zero area, and vertices that share an exact position are welded
// (so edges shared by triangles from different file groups are recognised as shared). A closed (edge-manifold)
// component whose faces disagree on orientation (two faces running a shared edge the same way: a patch flipped
// against the rest, which would flip its signs) is re-oriented consistently and outward (positive signed volume);
// consistent components are never touched, so a wholly inward mesh stays inward, and a non-orientable component is
// left as it is. MeshReport says what was found, including what was dropped and re-oriented. Errors are a Status
// (kInvalidArgument for malformed input, kNotFound for a missing file, kIoError for a file that cannot be read, the
// interrupter's status when it stopped the work) whose message names the file and the problem; malformed input never
// asserts or crashes. Plain value types; not synchronised.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/interrupter.h"
#include "core/status.h"
#include "core/types.h"

namespace distband {

struct TriangleMesh {
  std::vector<Vec3d> vertices;                  ///< world coordinates
  std::vector<std::array<uint32_t, 3>> triangles;  ///< counter-clockwise seen from outside (outward normals)
};

struct MeshReport {
  int64_t vertices = 0;            ///< after welding identical positions
  int64_t triangles = 0;           ///< kept (non-degenerate) triangles
  int64_t degenerate = 0;          ///< zero-area triangles (repeated index or collinear corners), skipped
  int64_t non_triangles = 0;       ///< point/line primitives in the file, skipped
  int64_t boundary_edges = 0;      ///< edges used by exactly one kept triangle (0 for a closed mesh)
  int64_t non_manifold_edges = 0;  ///< edges used by more than two kept triangles
  int64_t reoriented_faces = 0;    ///< faces flipped to make closed components consistent and outward
  Vec3d bbox_min, bbox_max;        ///< world bounding box of the kept triangles' vertices

  bool closed() const { return boundary_edges == 0 && non_manifold_edges == 0; }
  std::string summary() const;     ///< one line for logs and the CLI
};

/// The largest mesh file loadMesh reads (a local file: the CLI, benches and tests; the server never reads files).
inline constexpr uint64_t kMaxMeshFileBytes = uint64_t(4) << 30;

/// Loads a regular file `path` (.obj .off .ply .stl, by extension) into memory and parses it with readMesh
/// (core/mesh/mesh_reader.h: polygons fanned, identical vertices welded, validated). On error the message is
/// "<path>: <problem>" and `mesh` is untouched. `report` may be null.
Status loadMesh(const std::string& path, TriangleMesh* mesh, MeshReport* report);

/// Validates an in-memory mesh in place: rejects an empty mesh, non-finite coordinates and out-of-range
/// indices; welds identical positions, drops degenerate triangles and unreferenced vertices, re-orients closed
/// components whose faces disagree (see the contract above), and fills `report` (may be null). On error the mesh
/// is unspecified (the interrupter's status when it stopped the work). Memory: ~40 bytes per vertex and 24 per
/// triangle beyond the mesh itself (the re-orientation, when needed, stays within that).
Status validateMesh(TriangleMesh* mesh, MeshReport* report, const Interrupter* interrupter = nullptr);

}  // namespace distband

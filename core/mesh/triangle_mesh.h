// TriangleMesh: an indexed triangle soup loaded from a file (OBJ, OFF, PLY, STL ascii/binary) and validated.
// Contract: after loadMesh() or validateMesh() succeed, the mesh is non-empty, every coordinate is finite, every
// index is < vertices.size(), no triangle has zero area, and vertices that share an exact position are welded
// (so edges shared by triangles from different file groups are recognised as shared). A closed (edge-manifold)
// component whose faces disagree on orientation (two faces running a shared edge the same way: a patch flipped
// against the rest, which would flip its signs) is re-oriented consistently and outward (positive signed volume),
// each component on its own (so an inward inner shell of a hollow part that has a flipped patch comes out outward);
// consistent components are never touched, so a wholly inward mesh stays inward, and a non-orientable component is
// left as it is. MeshReport says what was found, including what was dropped and re-oriented, and how many connected
// parts the mesh has and whether their bounding boxes overlap (closed parts that cross or nest: the automatic sign
// then takes the winding number, core/seeds/mesh_sign.h). Errors are a Status
// (kInvalidArgument for malformed input, kNotFound for a missing file, kIoError for a file that cannot be read, the
// interrupter's status when it stopped the work) whose message names the file and the problem; malformed input never
// asserts or crashes. Plain value types; not synchronised.
#pragma once

#include <algorithm>
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
  /// Faces listed twice over the same corners, once each way round (a double-sided sheet), counted on a closed mesh
  /// only: there they make an edge-closed part of no volume, which no pseudonormal signs right (`auto` then takes
  /// the winding number, in which the two cancel). Looked for where a vertex has only two faces: a pair whose three
  /// corners are each pinched to other faces is not counted.
  int64_t double_sided_faces = 0;
  int64_t components = 0;          ///< connected parts (triangles sharing a vertex are connected)
  bool components_overlap = false;  ///< the bounding boxes of some two parts intersect (touching counts)
  Vec3d bbox_min, bbox_max;        ///< world bounding box of the kept triangles' vertices

  bool closed() const { return boundary_edges == 0 && non_manifold_edges == 0; }
  std::string summary() const;     ///< one line for logs and the CLI
};

/// A key for the use of edge {a, b} by a triangle that runs it from a to b: the undirected edge in the high bits and,
/// when `directed` (both ids below kDirectedKeyVertexLimit), the direction (a > b) in bit 0, so that one sort both
/// groups an edge's uses and tells which way each runs (the edge statistics, the boundary chain of
/// core/mesh/winding_number.h).
inline constexpr uint64_t kDirectedKeyVertexLimit = uint64_t(1) << 31;
inline uint64_t edgeKey(uint64_t a, uint64_t b, bool directed) {
  return directed ? std::min(a, b) << 33 | std::max(a, b) << 1 | uint64_t(a > b)
                  : std::min(a, b) << 32 | std::max(a, b);
}

/// The connected parts of triangles over `vertex_count` vertices (triangles sharing a vertex are connected): sets
/// (*part)[v] to vertex v's part, parts numbered in the order of their lowest vertex (a vertex no triangle uses is a
/// part of its own), and returns the number of parts, or -1 when `interrupter` stopped it. Memory: `part` alone.
int64_t findMeshParts(size_t vertex_count, const std::vector<std::array<uint32_t, 3>>& triangles,
                      std::vector<uint32_t>* part, const Interrupter* interrupter = nullptr);

/// The triangles listed again over the same three corners the other way round (a double-sided sheet: their solid
/// angles cancel, and each is the other's nearest triangle everywhere): every copy of such a corner set, whichever way
/// it runs, gets (*twin)[t] = 1 when `twin` is not null. Returns how many, or -1 when `interrupter` stopped it; `twin`
/// is left empty when there are none. O(T log T), in parallel; 16 bytes a triangle while it runs.
int64_t findDoubleSidedFaces(const std::vector<std::array<uint32_t, 3>>& triangles, std::vector<uint8_t>* twin,
                             const Interrupter* interrupter = nullptr);

/// The largest mesh file loadMesh reads (a local file: the CLI, benches and tests; the server never reads files).
inline constexpr uint64_t kMaxMeshFileBytes = uint64_t(4) << 30;

/// Loads a regular file `path` (.obj .off .ply .stl, by extension) into memory and parses it with readMesh
/// (core/mesh/mesh_reader.h: polygons fanned, identical vertices welded, validated). On error the message is
/// "<path>: <problem>" and `mesh` is untouched. `report` may be null.
Status loadMesh(const std::string& path, TriangleMesh* mesh, MeshReport* report);

/// Validates an in-memory mesh in place: rejects an empty mesh, non-finite coordinates and out-of-range
/// indices; welds identical positions, drops degenerate triangles and unreferenced vertices, re-orients closed
/// components whose faces disagree (see the contract above), finds the connected parts and whether their bounding
/// boxes overlap, and fills `report` (may be null). On error the mesh is unspecified (the interrupter's status when
/// it stopped the work). Memory: ~40 bytes per vertex and 24 per triangle beyond the mesh itself (the
/// re-orientation, when needed, and the parts' boxes stay within that).
Status validateMesh(TriangleMesh* mesh, MeshReport* report, const Interrupter* interrupter = nullptr);

}  // namespace distband

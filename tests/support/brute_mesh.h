// Brute-force mesh oracles for tests and the bench: exact unsigned distance to a triangle mesh (a scan over every
// triangle) and the exact generalized winding number (a sum over every triangle).
// Contract: shares no code with core/ (its own closest-point routine: plane projection + edge clamping, a
// different algorithm from core/geometry.cc's region tests). O(T) per query, pure, thread-safe.
// Also analytic test shapes (sphere, box, torus) as triangle meshes with their exact signed distance.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/mesh/triangle_mesh.h"

namespace distband::testing {

/// Exact distance from p to the nearest triangle (world units), and that triangle's index in *tri if non-null.
double bruteDistance(const TriangleMesh& mesh, const Vec3d& p, uint32_t* tri = nullptr);
/// Exact generalized winding number at p (1 inside a closed outward mesh, 0 outside).
double bruteWinding(const TriangleMesh& mesh, const Vec3d& p);
/// Signed brute distance: negative where bruteWinding > 0.5.
double bruteSignedDistance(const TriangleMesh& mesh, const Vec3d& p);

/// UV sphere: `rings` latitude bands, `segments` longitude bands, outward orientation, closed.
TriangleMesh makeSphereMesh(const Vec3d& center, double radius, int rings, int segments);
double sphereSdf(const Vec3d& center, double radius, const Vec3d& p);
/// Axis-aligned box [lo, hi] as 12 triangles, outward, closed; its SDF is exact (no tessellation error).
TriangleMesh makeBoxMesh(const Vec3d& lo, const Vec3d& hi);
double boxSdf(const Vec3d& lo, const Vec3d& hi, const Vec3d& p);
/// Torus around the z axis through `center`: major radius R, minor radius r, closed, outward.
TriangleMesh makeTorusMesh(const Vec3d& center, double R, double r, int major_segments, int minor_segments);
double torusSdf(const Vec3d& center, double R, double r, const Vec3d& p);

}  // namespace distband::testing

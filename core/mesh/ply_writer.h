// PLY writer: a TriangleMesh as binary little-endian PLY with double coordinates.
// Contract: readMesh() of the result gives back the same vertices (bit for bit) and triangles, in the same order,
// for any mesh that readMesh() produced (welded, no degenerate triangle). A coordinator uses it to hand a parsed
// mesh on to its replicas in one canonical encoding whatever format the client uploaded. Pure; thread-safe.
#pragma once

#include <string>

#include "core/mesh/triangle_mesh.h"

namespace distband {

std::string encodeBinaryPly(const TriangleMesh& mesh);

}  // namespace distband

// Internals of core/mesh/mesh_reader: the raw mesh each format reader fills (their text scanning is
// core/io/text_scan.h's).
// Not part of the public API (only mesh_reader*.cc and tests include it).
#pragma once

#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <string_view>
#include <system_error>
#include <vector>

#include "core/interrupter.h"
#include "core/io/text_scan.h"
#include "core/mesh/mesh_reader.h"
#include "core/status.h"
#include "core/types.h"

namespace distband::mesh_internal {

/// What a reader produces before validation: vertices as read, polygons fanned into triangles.
struct RawMesh {
  std::vector<Vec3d> vertices;
  std::vector<std::array<uint32_t, 3>> triangles;
  int64_t non_triangles = 0;  ///< point and line primitives (and faces with fewer than 3 corners)
  int64_t degenerate = 0;     ///< fan triangles that repeat a corner, dropped while reading
};

Status readObj(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out);
Status readOff(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out);
Status readPly(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out);
Status readStl(std::string_view bytes, const MeshReadLimits& limits, const Interrupter* interrupter, RawMesh* out);

/// Polled every this many lines or records.
inline constexpr uint64_t kPollEvery = 1 << 16;

// Text scanning: core/io/text_scan.h.

/// Adds the fan of polygon `corners` (k >= 3) to `out`, dropping triangles that repeat a corner.
/// kResourceExhausted when the triangles would exceed `max_triangles`.
Status addFan(const uint32_t* corners, size_t k, uint64_t max_triangles, std::string_view where, RawMesh* out);

}  // namespace distband::mesh_internal

// Shared body of the mesh-format fuzz targets: readMesh on arbitrary bytes with small limits; an accepted mesh must
// satisfy the TriangleMesh contract (indices in range, finite coordinates, counts within the limits).
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "core/mesh/mesh_reader.h"

inline int fuzzMeshFormat(distband::MeshFormat format, const uint8_t* data, size_t size) {
  distband::MeshReadLimits limits;
  limits.max_vertices = 1 << 16;
  limits.max_triangles = 1 << 16;
  distband::TriangleMesh mesh;
  distband::MeshReport report;
  const distband::Status s = distband::readMesh(std::string_view(reinterpret_cast<const char*>(data), size), format,
                                                limits, nullptr, &mesh, &report);
  if (!s.ok()) {
    if (s.message().empty() || s.code() == distband::Status::Code::kInternal) __builtin_trap();
    return 0;
  }
  if (mesh.vertices.size() > limits.max_vertices || mesh.triangles.size() > limits.max_triangles) __builtin_trap();
  if (mesh.triangles.empty() || uint64_t(report.triangles) != mesh.triangles.size()) __builtin_trap();
  for (const auto& t : mesh.triangles)
    for (uint32_t i : t)
      if (i >= mesh.vertices.size()) __builtin_trap();
  for (const auto& v : mesh.vertices)
    if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z)) __builtin_trap();
  return 0;
}

#include "core/mesh/ply_writer.h"

#include <bit>
#include <cstring>

#include <fmt/format.h>

namespace distband {
namespace {

template <typename T>
void appendLittle(std::string& out, T value) {
  static_assert(std::endian::native == std::endian::little, "distband assumes a little-endian host");
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.append(bytes, sizeof(T));
}

}  // namespace

std::string encodeBinaryPly(const TriangleMesh& mesh) {
  std::string out = fmt::format(
      "ply\nformat binary_little_endian 1.0\ncomment distband canonical mesh\nelement vertex {}\n"
      "property double x\nproperty double y\nproperty double z\nelement face {}\n"
      "property list uchar uint vertex_indices\nend_header\n",
      mesh.vertices.size(), mesh.triangles.size());
  out.reserve(out.size() + mesh.vertices.size() * 24 + mesh.triangles.size() * 13);
  for (const Vec3d& v : mesh.vertices) {
    appendLittle(out, v.x);
    appendLittle(out, v.y);
    appendLittle(out, v.z);
  }
  for (const auto& t : mesh.triangles) {
    appendLittle(out, uint8_t(3));
    for (uint32_t i : t) appendLittle(out, i);
  }
  return out;
}

}  // namespace distband

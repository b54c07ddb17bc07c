#include "core/io/field_metadata.h"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/io/temp_file.h"

namespace distband {

std::string fieldMetadataJson(const FieldMetadata& m) {
  using nlohmann::json;
  auto finiteOrNull = [](double v) { return std::isfinite(v) ? json(v) : json(nullptr); };
  const Coord d = m.grid.dims();
  const Vec3d o = m.grid.origin();
  json j = {
      {"format", "distband-field/1"},
      {"data_file", m.data_file},
      {"dims", {d.x, d.y, d.z}},
      {"origin", {o.x, o.y, o.z}},
      {"voxel_size", m.grid.voxelSize()},
      {"spacing", {m.grid.spacing().x, m.grid.spacing().y, m.grid.spacing().z}},
      {"layout", "C order, shape (Z, Y, X): element [z][y][x] is voxel (x, y, z) at origin + spacing * (x, y, z)"},
      {"dtype", "float32"},
      {"units", "world"},
      {"signed", m.signed_distance},
      {"sign_convention", m.signed_distance ? "negative inside (OpenVDB)" : "unsigned"},
      {"limit", finiteOrNull(m.limit_world)},
      {"background", finiteOrNull(m.background_world)},
      {"stencil", m.stencil},
      {"mode", m.mode},
      {"segment_length", m.segment_length_world},
      {"voxels_delivered", m.voxels_delivered},
      {"seconds", m.seconds},
      {"complete", m.complete},
      {"segments", m.segments},
      {"complete_up_to", finiteOrNull(m.complete_up_to_world)},
      {"band_clipped", m.band_clipped},
  };
  if (!m.sign.empty()) {
    j["sign"] = {{"method", m.sign}, {"reason", m.sign_reason}};
    if (m.sign_shares.total() > 0)
      j["sign"]["voxels_by_test"] = {{"pseudonormal", m.sign_shares.pseudonormal},
                                     {"winding_certified", m.sign_shares.winding_certified},
                                     {"winding_per_voxel", m.sign_shares.winding_per_voxel},
                                     {"parity", m.sign_shares.parity}};
  }
  if (m.padding_voxels >= 0) j["padding_voxels"] = m.padding_voxels;
  if (!m.closest_file.empty()) j["closest"] = {{"data_file", m.closest_file}, {"feature", m.closest_feature}};
  return j.dump(2) + "\n";
}

Status writeFieldMetadata(const std::string& path, const FieldMetadata& meta) {
  const std::string text = fieldMetadataJson(meta);
  std::string tmp;  // atomic, like every output writer: a temporary beside the target, renamed over it
  std::FILE* f = nullptr;
  if (Status s = openTempBeside(path, "w", &tmp, &f); !s.ok()) return s;
  Status err;
  if (std::fwrite(text.data(), 1, text.size(), f) != text.size())
    err = Status::IoError(fmt::format("{}: write failed: {}", path, std::strerror(errno)));
  return commitTemp(f, tmp, path, err);
}

}  // namespace distband

#include "server/asset_parsing.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>

#include "core/grid.h"
#include "core/mesh/triangle_mesh.h"

namespace distband {

std::string_view meshFormatExtension(v1::MeshFormat format) {
  switch (format) {
    case v1::MESH_FORMAT_OBJ: return "obj";
    case v1::MESH_FORMAT_OFF: return "off";
    case v1::MESH_FORMAT_PLY: return "ply";
    case v1::MESH_FORMAT_STL: return "stl";
    default: return "";
  }
}

Status checkDims(const v1::Dims& d, std::string_view field) {
  for (auto [axis, v] : {std::pair{"x", d.x()}, {"y", d.y()}, {"z", d.z()}})
    if (v < 1 || v > uint32_t(kMaxGridDim))
      return Status::InvalidArgument(fmt::format("{}.{} must be in [1, {}] (got {})", field, axis, kMaxGridDim, v));
  return Status::Ok();
}

std::string meshAssetId(std::string_view bytes, v1::MeshFormat format) {
  return "mesh-" + sha256Hex({meshFormatExtension(format), ":", bytes});
}

std::string volumeAssetId(const v1::Dims& d, std::string_view bytes) {
  const std::string head = fmt::format("{},{},{}:", d.x(), d.y(), d.z());
  return "volume-" + sha256Hex({head, bytes});
}

namespace {

// A temporary file that removes itself; loadMesh wants a path with the right extension.
class TempFile {
 public:
  std::string create(std::string_view bytes, std::string_view ext) {
    std::string tmpl = (std::filesystem::temp_directory_path() / "distband-upload-XXXXXX.").string();
    tmpl += ext;
    const int fd = mkstemps(tmpl.data(), int(ext.size()) + 1);
    if (fd < 0) return fmt::format("cannot create a temporary file: {}", std::strerror(errno));
    path_ = tmpl;
    size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
      if (n <= 0) {
        ::close(fd);
        return fmt::format("cannot write a temporary file: {}", std::strerror(errno));
      }
      done += size_t(n);
    }
    ::close(fd);
    return {};
  }
  const std::string& path() const { return path_; }
  ~TempFile() {
    if (!path_.empty()) std::remove(path_.c_str());
  }

 private:
  std::string path_;
};

std::string replaceAll(std::string s, const std::string& from, const std::string& to) {
  if (from.empty()) return s;
  for (size_t pos = 0; (pos = s.find(from, pos)) != std::string::npos; pos += to.size()) s.replace(pos, from.size(), to);
  return s;
}

}  // namespace

uint64_t meshParsePeakBytes(uint64_t input_bytes) { return 64 * input_bytes + (uint64_t(1) << 20); }

Status parseMeshAsset(std::string_view bytes, v1::MeshFormat format, const std::string& name, std::string_view field,
                      const MeshLimits& limits, const Interrupter* interrupter, std::shared_ptr<const Asset>* out) {
  const std::string_view ext = meshFormatExtension(format);
  if (ext.empty())
    return Status::InvalidArgument(
        fmt::format("{}.format must be one of MESH_FORMAT_OBJ, _OFF, _PLY, _STL (got {})", field, int(format)));
  if (bytes.empty()) return Status::InvalidArgument(fmt::format("{}: the mesh data is empty", field));
  if (isInterrupted(interrupter)) return interrupter->status();
  TempFile file;
  if (std::string e = file.create(bytes, ext); !e.empty()) return Status::Internal(e);
  auto asset = std::make_shared<Asset>();
  auto mesh = std::make_shared<TriangleMesh>();
  std::string error = loadMesh(file.path(), mesh.get(), &asset->mesh_report);
  if (!error.empty()) {
    error = replaceAll(error, file.path(), name.empty() ? std::string("mesh") : name);
    return Status::InvalidArgument(fmt::format("{}: {}", field, error));
  }
  if (uint64_t(asset->mesh_report.triangles) > limits.max_triangles)
    return Status::ResourceExhausted(fmt::format("{}: the mesh has {} triangles, more than the server's limit of {}",
                                                 field, asset->mesh_report.triangles, limits.max_triangles));
  if (uint64_t(asset->mesh_report.vertices) > limits.max_vertices)
    return Status::ResourceExhausted(fmt::format("{}: the mesh has {} vertices, more than the server's limit of {}",
                                                 field, asset->mesh_report.vertices, limits.max_vertices));
  asset->kind = Asset::Kind::kMesh;
  asset->id = meshAssetId(bytes, format);
  asset->name = name;
  asset->mesh = std::move(mesh);
  *out = std::move(asset);
  return Status::Ok();
}

uint64_t volumeParsePeakBytes(uint64_t voxels) { return voxels + voxels / 256 + (uint64_t(1) << 16); }

Status parseVolumeAsset(const v1::Dims& dims, std::string bytes, const std::string& name, std::string_view field,
                        uint64_t max_voxels, const Interrupter* interrupter, std::shared_ptr<const Asset>* out) {
  if (Status s = checkDims(dims, fmt::format("{}.dims", field)); !s.ok()) return s;
  const uint64_t voxels = uint64_t(dims.x()) * dims.y() * dims.z();
  if (voxels > max_voxels)
    return Status::ResourceExhausted(fmt::format("{}.dims: {}x{}x{} = {} voxels exceeds the server's voxel budget of {}",
                                                 field, dims.x(), dims.y(), dims.z(), voxels, max_voxels));
  if (bytes.size() != voxels)
    return Status::InvalidArgument(
        fmt::format("{}: the mask has {} bytes but dims {}x{}x{} need exactly {} (one byte per voxel)", field,
                    bytes.size(), dims.x(), dims.y(), dims.z(), voxels));
  const Coord d{int32_t(dims.x()), int32_t(dims.y()), int32_t(dims.z())};
  auto footprint = std::make_shared<VolumeFootprint>();
  if (Status s = analyzeVolume(d, reinterpret_cast<const uint8_t*>(bytes.data()), interrupter, footprint.get());
      !s.ok())
    return s;
  if (footprint->seed_voxels == 0)
    return Status::InvalidArgument(fmt::format("{}: the mask has no nonzero (seed) voxel", field));
  auto asset = std::make_shared<Asset>();
  asset->kind = Asset::Kind::kVolume;
  asset->id = volumeAssetId(dims, bytes);
  asset->name = name;
  asset->dims = d;
  asset->mask = std::make_shared<const std::vector<uint8_t>>(bytes.begin(), bytes.end());
  asset->footprint = std::move(footprint);
  *out = std::move(asset);
  return Status::Ok();
}

}  // namespace distband

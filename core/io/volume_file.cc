#include "core/io/volume_file.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <sstream>
#include <vector>

#include <fmt/format.h>

#include "core/io/input_file.h"
#include "core/io/nifti.h"
#include "core/io/npy.h"
#include "core/io/nrrd.h"

namespace distband {
namespace {

std::string lower(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return out;
}

bool endsWith(const std::string& s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

template <class T>
T load(const char* p, bool swap) {
  T v;
  std::memcpy(&v, p, sizeof v);
  if (swap) {
    char b[sizeof v];
    std::memcpy(b, &v, sizeof v);
    std::reverse(b, b + sizeof v);
    std::memcpy(&v, b, sizeof v);
  }
  return v;
}

}  // namespace

std::string_view volumeFileFormatName(VolumeFileFormat format) {
  switch (format) {
    case VolumeFileFormat::kNpy:
      return "npy";
    case VolumeFileFormat::kNifti:
      return "nifti";
    case VolumeFileFormat::kNrrd:
      return "nrrd";
  }
  return "?";
}

std::optional<VolumeFileFormat> volumeFileFormatOf(std::string_view path) {
  const std::string p = lower(path);
  if (endsWith(p, ".npy")) return VolumeFileFormat::kNpy;
  if (endsWith(p, ".nii") || endsWith(p, ".nii.gz")) return VolumeFileFormat::kNifti;
  if (endsWith(p, ".nrrd") || endsWith(p, ".nhdr")) return VolumeFileFormat::kNrrd;
  return std::nullopt;
}

std::array<std::array<double, 4>, 3> volumeAffine(const VolumeGeometry& g) {
  if (g.affine) return *g.affine;
  return {{{g.spacing.x, 0, 0, g.origin.x}, {0, g.spacing.y, 0, g.origin.y}, {0, 0, g.spacing.z, g.origin.z}}};
}

VolumeGeometry overrideGeometry(VolumeGeometry g, const std::optional<Vec3d>& spacing,
                                const std::optional<Vec3d>& origin) {
  if (spacing) {
    const double old_s[3] = {g.spacing.x, g.spacing.y, g.spacing.z}, new_s[3] = {spacing->x, spacing->y, spacing->z};
    if (g.affine)
      for (int c = 0; c < 3; ++c)
        for (int r = 0; r < 3; ++r) (*g.affine)[size_t(r)][size_t(c)] *= new_s[c] / old_s[c];
    g.spacing = *spacing;
  }
  if (origin) {
    if (g.affine) {
      (*g.affine)[0][3] = origin->x;
      (*g.affine)[1][3] = origin->y;
      (*g.affine)[2][3] = origin->z;
    }
    g.origin = *origin;
  }
  return g;
}

Status axisAlignedGeometry(const std::array<std::array<double, 4>, 3>& a, std::string_view name, std::string_view what,
                           VolumeGeometry* out) {
  VolumeGeometry g = *out;
  double spacing[3];
  int world_axis[3];
  bool reoriented = false;
  for (int c = 0; c < 3; ++c) {  // column c: where array axis c points in the world
    const double x = a[0][size_t(c)], y = a[1][size_t(c)], z = a[2][size_t(c)];
    const double norm = std::sqrt(x * x + y * y + z * z);
    if (!(std::isfinite(norm) && norm > 0))
      return Status::InvalidArgument(fmt::format("{}: {} gives array axis {} no finite length", name, what, "xyz"[c]));
    const double v[3] = {x, y, z};
    int along = -1;
    for (int r = 0; r < 3; ++r)
      if (std::abs(v[r]) > 1e-6 * norm) {
        if (along >= 0)
          return Status::InvalidArgument(
              fmt::format("{}: {} is rotated or sheared (array axis {} is not along one world axis); only axis-aligned "
                          "directions are supported",
                          name, what, "xyz"[c]));
        along = r;
      }
    for (int p = 0; p < c; ++p)
      if (world_axis[p] == along)
        return Status::InvalidArgument(
            fmt::format("{}: {} puts array axes {} and {} along one world axis", name, what, "xyz"[p], "xyz"[c]));
    world_axis[c] = along;
    spacing[c] = norm;
    reoriented |= along != c || v[along] < 0;
  }
  g.spacing = {spacing[0], spacing[1], spacing[2]};
  g.origin = {a[0][3], a[1][3], a[2][3]};
  if (!(std::isfinite(g.origin.x) && std::isfinite(g.origin.y) && std::isfinite(g.origin.z)))
    return Status::InvalidArgument(fmt::format("{}: {} has a non-finite origin", name, what));
  g.affine = a;
  g.reoriented = reoriented;
  g.from_header = true;
  *out = g;
  return Status::Ok();
}

Status labelsFromElements(std::string_view data, const Coord& dims, char kind, int bytes, bool big_endian,
                          std::string_view name, LabelVolume* out) {
  const size_t count = size_t(dims.x) * dims.y * dims.z;
  if (data.size() != count * size_t(bytes))
    return Status::InvalidArgument(fmt::format("{}: {} data bytes, the header's {} voxels of {} bytes need {}", name,
                                               data.size(), count, bytes, count * size_t(bytes)));
  const bool swap = big_endian != (std::endian::native == std::endian::big) && bytes > 1;
  // Unsigned integers of 8, 16, 32 bits: the volume's own type.
  if (kind == 'u' && bytes <= 4) {
    auto copy = std::make_shared<std::vector<uint8_t>>(data.begin(), data.end());
    if (swap)
      for (size_t i = 0; i < copy->size(); i += size_t(bytes))
        std::reverse(copy->begin() + int64_t(i), copy->begin() + int64_t(i) + bytes);
    const VoxelType type = bytes == 1 ? VoxelType::kUint8 : bytes == 2 ? VoxelType::kUint16 : VoxelType::kUint32;
    return LabelVolume::make(dims, type, std::move(copy), out);
  }
  // Everything else: each value a non-negative integer below 2^32, into the smallest type holding the largest.
  auto value = [&](size_t i, double* v) {
    const char* p = data.data() + i * size_t(bytes);
    switch (kind) {
      case 'i':
        switch (bytes) {
          case 1:
            *v = double(int8_t(*p));
            return;
          case 2:
            *v = load<int16_t>(p, swap);
            return;
          case 4:
            *v = load<int32_t>(p, swap);
            return;
          default:
            *v = double(load<int64_t>(p, swap));
            return;
        }
      case 'u':
        *v = double(load<uint64_t>(p, swap));
        return;
      default:
        *v = bytes == 4 ? double(load<float>(p, swap)) : load<double>(p, swap);
        return;
    }
  };
  double largest = 0;
  for (size_t i = 0; i < count; ++i) {
    double v;
    value(i, &v);
    if (!(v >= 0 && v <= 4294967295.0 && v == std::floor(v)))
      return Status::InvalidArgument(fmt::format(
          "{}: voxel {} holds {:g}: a seed or label volume needs non-negative integer values below 2^32", name, i, v));
    largest = std::max(largest, v);
  }
  const VoxelType type = largest <= 255     ? VoxelType::kUint8
                         : largest <= 65535 ? VoxelType::kUint16
                                            : VoxelType::kUint32;
  const size_t w = voxelTypeBytes(type);
  auto labels = std::make_shared<std::vector<uint8_t>>(count * w);
  for (size_t i = 0; i < count; ++i) {
    double v;
    value(i, &v);
    const uint32_t u = uint32_t(v);
    std::memcpy(labels->data() + i * w, &u, w);  // little-endian host: the low bytes
  }
  return LabelVolume::make(dims, type, std::move(labels), out);
}

Status parseVolumeFile(std::string_view bytes, VolumeFileFormat format, std::string_view name,
                       const VolumeReadLimits& limits, VolumeImage* out) {
  switch (format) {
    case VolumeFileFormat::kNifti:
      return parseNifti(bytes, name, limits, out);
    case VolumeFileFormat::kNrrd:
      return parseNrrd(bytes, name, limits, nullptr, out);
    case VolumeFileFormat::kNpy:
      break;
  }
  NpyArray array;
  if (Status s = parseNpy(bytes, name, &array); !s.ok()) return s;
  VolumeImage image;
  if (Status s = npyVolume(std::move(array), name, &image.volume); !s.ok()) return s;
  if (uint64_t(image.volume.voxelCount()) > limits.max_voxels)
    return Status::ResourceExhausted(
        fmt::format("{}: {} voxels exceed the limit of {}", name, image.volume.voxelCount(), limits.max_voxels));
  *out = std::move(image);
  return Status::Ok();
}

Status readVolumeFile(const std::string& path, const VolumeReadLimits& limits, VolumeImage* out) {
  const std::optional<VolumeFileFormat> format = volumeFileFormatOf(path);
  if (!format)
    return Status::InvalidArgument(
        fmt::format("{}: not a volume file (expected .npy, .nii, .nii.gz, .nrrd or .nhdr)", path));
  if (*format == VolumeFileFormat::kNpy) {
    VolumeImage image;
    if (Status s = readNpyVolume(path, &image.volume); !s.ok()) return s;
    *out = std::move(image);
    return Status::Ok();
  }
  // The largest file a volume of the limits can come in (uncompressed, 8-byte elements, a generous header).
  const uint64_t max_bytes = limits.max_voxels * 8 + (uint64_t(1) << 20);
  std::string bytes;
  if (Status s = readWholeFile(path, max_bytes, "a volume", &bytes); !s.ok()) return s;
  if (*format == VolumeFileFormat::kNifti) return parseNifti(bytes, path, limits, out);
  // An .nhdr's data file: a plain file name beside the header, nothing else.
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  const NrrdDataFile detached = [&](const std::string& file, uint64_t max, std::string* data) {
    const std::filesystem::path p(file);
    if (file.empty() || p.has_parent_path() || p.is_absolute() || file == "." || file == "..")
      return Status::InvalidArgument(
          fmt::format("{}: data file '{}': only a file beside the header is read", path, file.substr(0, 64)));
    return readWholeFile((dir / p).string(), max, "a volume", data);
  };
  return parseNrrd(bytes, path, limits, &detached, out);
}

}  // namespace distband

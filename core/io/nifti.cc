#include "core/io/nifti.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <fmt/format.h>
#include <nifti1.h>
#include <nifti2.h>

#include "core/grid.h"
#include "core/io/gzip.h"
#include "core/io/temp_file.h"

namespace distband {
namespace {

/// Header extensions (between the header and vox_offset) are skipped; more than this is refused, so a short file
/// cannot declare gigabytes of them.
constexpr int64_t kMaxNiftiExtensionBytes = int64_t(64) << 20;

template <class T>
void swapInPlace(T* v, size_t n = 1) {
  for (size_t i = 0; i < n; ++i) {
    char b[sizeof(T)];
    std::memcpy(b, v + i, sizeof(T));
    std::reverse(b, b + sizeof(T));
    std::memcpy(v + i, b, sizeof(T));
  }
}

/// The header's fields this reader uses, from either version.
struct Header {
  int version = 0;
  int64_t dim[8] = {};
  int datatype = 0, bitpix = 0;
  double pixdim[8] = {};
  int64_t vox_offset = 0;
  double scl_slope = 0, scl_inter = 0;
  int qform_code = 0, sform_code = 0;
  double quatern[3] = {}, qoffset[3] = {};
  double srow[3][4] = {};
  bool big_endian = false;
};

// Both versions name their fields alike (NIfTI-2 widens them): one byte swap and one copy serve both. vox_offset is
// copied by the caller, which checks NIfTI-1's float offset.
template <class NiftiHeader>
void copyCommonFields(NiftiHeader& n, bool swap, int version, Header* h) {
  if (swap) {
    swapInPlace(n.dim, 8);
    swapInPlace(&n.datatype), swapInPlace(&n.bitpix);
    swapInPlace(n.pixdim, 8);
    swapInPlace(&n.vox_offset), swapInPlace(&n.scl_slope), swapInPlace(&n.scl_inter);
    swapInPlace(&n.qform_code), swapInPlace(&n.sform_code);
    swapInPlace(&n.quatern_b), swapInPlace(&n.quatern_c), swapInPlace(&n.quatern_d);
    swapInPlace(&n.qoffset_x), swapInPlace(&n.qoffset_y), swapInPlace(&n.qoffset_z);
    swapInPlace(n.srow_x, 4), swapInPlace(n.srow_y, 4), swapInPlace(n.srow_z, 4);
  }
  h->version = version;
  for (int i = 0; i < 8; ++i) h->dim[i] = n.dim[i], h->pixdim[i] = n.pixdim[i];
  h->datatype = n.datatype;
  h->bitpix = n.bitpix;
  h->scl_slope = n.scl_slope, h->scl_inter = n.scl_inter;
  h->qform_code = n.qform_code, h->sform_code = n.sform_code;
  h->quatern[0] = n.quatern_b, h->quatern[1] = n.quatern_c, h->quatern[2] = n.quatern_d;
  h->qoffset[0] = n.qoffset_x, h->qoffset[1] = n.qoffset_y, h->qoffset[2] = n.qoffset_z;
  for (int c = 0; c < 4; ++c) h->srow[0][c] = n.srow_x[c], h->srow[1][c] = n.srow_y[c], h->srow[2][c] = n.srow_z[c];
}

Status readHeader(std::string_view b, std::string_view name, Header* h) {
  if (b.size() < 4) return Status::InvalidArgument(fmt::format("{}: too short for a NIfTI header", name));
  int32_t size;
  std::memcpy(&size, b.data(), 4);
  bool swap = false;
  if (size != 348 && size != 540) {
    swapInPlace(&size);
    swap = true;
  }
  if (size != 348 && size != 540)
    return Status::InvalidArgument(fmt::format("{}: not a NIfTI file (sizeof_hdr is neither 348 nor 540)", name));
  h->big_endian = (std::endian::native == std::endian::little) == swap;
  if (size == 348) {
    if (b.size() < sizeof(nifti_1_header))
      return Status::InvalidArgument(fmt::format("{}: truncated NIfTI-1 header", name));
    nifti_1_header n;
    std::memcpy(&n, b.data(), sizeof n);
    if (std::memcmp(n.magic, "n+1\0", 4) != 0)
      return Status::InvalidArgument(fmt::format(
          "{}: NIfTI-1 magic is not \"n+1\" (a .hdr/.img pair is not read: give the single-file .nii)", name));
    copyCommonFields(n, swap, 1, h);
    if (!(std::isfinite(n.vox_offset) && n.vox_offset >= 0 && n.vox_offset <= 1e15 &&
          n.vox_offset == std::floor(n.vox_offset)))
      return Status::InvalidArgument(fmt::format("{}: vox_offset {} is not a byte offset", name, n.vox_offset));
    h->vox_offset = int64_t(n.vox_offset);
    return Status::Ok();
  }
  if (b.size() < sizeof(nifti_2_header))
    return Status::InvalidArgument(fmt::format("{}: truncated NIfTI-2 header", name));
  nifti_2_header n;
  std::memcpy(&n, b.data(), sizeof n);
  if (std::memcmp(n.magic, "n+2\0\r\n\032\n", 8) != 0)
    return Status::InvalidArgument(fmt::format(
        "{}: NIfTI-2 magic is not \"n+2\" (a .hdr/.img pair is not read: give the single-file .nii)", name));
  copyCommonFields(n, swap, 2, h);
  h->vox_offset = n.vox_offset;
  return Status::Ok();
}

/// (kind, bytes) of a NIfTI datatype this reader takes; false otherwise.
bool elementOf(int datatype, char* kind, int* bytes) {
  switch (datatype) {
    case NIFTI_TYPE_UINT8:
      *kind = 'u', *bytes = 1;
      return true;
    case NIFTI_TYPE_UINT16:
      *kind = 'u', *bytes = 2;
      return true;
    case NIFTI_TYPE_UINT32:
      *kind = 'u', *bytes = 4;
      return true;
    case NIFTI_TYPE_INT8:
      *kind = 'i', *bytes = 1;
      return true;
    case NIFTI_TYPE_INT16:
      *kind = 'i', *bytes = 2;
      return true;
    case NIFTI_TYPE_INT32:
      *kind = 'i', *bytes = 4;
      return true;
    case NIFTI_TYPE_FLOAT32:
      *kind = 'f', *bytes = 4;
      return true;
    case NIFTI_TYPE_FLOAT64:
      *kind = 'f', *bytes = 8;
      return true;
    default:
      return false;
  }
}

/// The voxel-to-world affine the header gives (NIfTI's methods 3, 2, 1 in that order of preference).
std::array<std::array<double, 4>, 3> affineOf(const Header& h, std::string* what) {
  std::array<std::array<double, 4>, 3> a{};
  if (h.sform_code > 0) {
    *what = "the sform";
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) a[size_t(r)][size_t(c)] = h.srow[r][c];
    return a;
  }
  if (h.qform_code > 0) {
    *what = "the qform";
    double b = h.quatern[0], c = h.quatern[1], d = h.quatern[2];
    double aa = 1.0 - (b * b + c * c + d * d);
    double q0;
    if (aa < 1e-7) {  // a = 0: the (b, c, d) of a 180-degree turn, normalised
      const double n = std::sqrt(b * b + c * c + d * d);
      if (n > 0) b /= n, c /= n, d /= n;
      q0 = 0;
    } else {
      q0 = std::sqrt(aa);
    }
    const double R[3][3] = {{q0 * q0 + b * b - c * c - d * d, 2 * (b * c - q0 * d), 2 * (b * d + q0 * c)},
                            {2 * (b * c + q0 * d), q0 * q0 + c * c - b * b - d * d, 2 * (c * d - q0 * b)},
                            {2 * (b * d - q0 * c), 2 * (c * d + q0 * b), q0 * q0 + d * d - c * c - b * b}};
    const double qfac = h.pixdim[0] < 0 ? -1.0 : 1.0;
    const double scale[3] = {h.pixdim[1], h.pixdim[2], qfac * h.pixdim[3]};
    for (int r = 0; r < 3; ++r) {
      for (int col = 0; col < 3; ++col) a[size_t(r)][size_t(col)] = R[r][col] * scale[col];
      a[size_t(r)][3] = h.qoffset[r];
    }
    return a;
  }
  *what = "the pixdims";
  for (int r = 0; r < 3; ++r) a[size_t(r)][size_t(r)] = h.pixdim[r + 1];
  return a;
}

}  // namespace

Status parseNifti(std::string_view bytes, std::string_view name, const VolumeReadLimits& limits, VolumeImage* out) {
  std::string inflated;
  std::string_view file = bytes;
  if (isGzip(bytes)) {
    // The header first (the size of the rest follows from it), then the whole stream, bounded by that size.
    if (Status s = gunzipPrefix(bytes, sizeof(nifti_2_header), name, &inflated); !s.ok()) return s;
    file = inflated;
  }
  Header h;
  if (Status s = readHeader(file, name, &h); !s.ok()) return s;
  const int64_t rank = h.dim[0];
  if (rank < 1 || rank > 7)
    return Status::InvalidArgument(fmt::format("{}: dim[0] is {}, not a rank in [1, 7]", name, rank));
  for (int i = 4; i <= rank; ++i)
    if (h.dim[i] != 1)
      return Status::InvalidArgument(
          fmt::format("{}: dimension {} has extent {}: a seed or label volume is 3-D (time or vector data are not)",
                      name, i, h.dim[i]));
  int64_t extent[3];
  for (int i = 0; i < 3; ++i) {
    extent[i] = i < rank ? h.dim[i + 1] : 1;
    if (extent[i] < 1 || extent[i] > kMaxGridDim)
      return Status::InvalidArgument(
          fmt::format("{}: dim[{}] is {}, not in [1, {}]", name, i + 1, extent[i], kMaxGridDim));
  }
  const uint64_t voxels = uint64_t(extent[0]) * uint64_t(extent[1]) * uint64_t(extent[2]);
  if (voxels > limits.max_voxels)
    return Status::ResourceExhausted(fmt::format("{}: {}x{}x{} = {} voxels exceed the limit of {}", name, extent[0],
                                                 extent[1], extent[2], voxels, limits.max_voxels));
  char kind;
  int width;
  if (!elementOf(h.datatype, &kind, &width))
    return Status::InvalidArgument(fmt::format(
        "{}: datatype {} is not a seed or label type (uint8/16/32, int8/16/32, float32/64)", name, h.datatype));
  if (h.bitpix != 8 * width)
    return Status::InvalidArgument(fmt::format("{}: bitpix {} does not match datatype {}", name, h.bitpix, h.datatype));
  if ((h.scl_slope != 0 && h.scl_slope != 1) || (h.scl_slope != 0 && h.scl_inter != 0) || std::isnan(h.scl_slope))
    return Status::InvalidArgument(
        fmt::format("{}: scaled data (scl_slope {:g}, scl_inter {:g}) are no labels", name, h.scl_slope, h.scl_inter));
  const int64_t header_bytes = h.version == 1 ? int64_t(sizeof(nifti_1_header)) : int64_t(sizeof(nifti_2_header));
  if (h.vox_offset < header_bytes)
    return Status::InvalidArgument(fmt::format("{}: vox_offset {} lies inside the header", name, h.vox_offset));
  if (h.vox_offset > header_bytes + kMaxNiftiExtensionBytes)
    return Status::InvalidArgument(fmt::format("{}: vox_offset {} leaves more than {} bytes of extensions", name,
                                               h.vox_offset, kMaxNiftiExtensionBytes));
  const uint64_t data_bytes = voxels * uint64_t(width);
  const uint64_t total = uint64_t(h.vox_offset) + data_bytes;
  if (isGzip(bytes)) {
    if (Status s = gunzip(bytes, total, name, &inflated); !s.ok()) return s;
    file = inflated;
  } else if (file.size() != total) {
    return Status::InvalidArgument(
        fmt::format("{}: {} bytes, the header declares {} (vox_offset {} + {} voxels of {} bytes){}", name, file.size(),
                    total, h.vox_offset, voxels, width, file.size() < total ? " (truncated)" : " (trailing bytes)"));
  }
  VolumeImage image;
  const Coord dims{int(extent[0]), int(extent[1]), int(extent[2])};
  if (Status s = labelsFromElements(file.substr(size_t(h.vox_offset), size_t(data_bytes)), dims, kind, width,
                                    h.big_endian, name, &image.volume);
      !s.ok())
    return s;
  std::string what;
  const auto affine = affineOf(h, &what);
  if (Status s = axisAlignedGeometry(affine, name, what, &image.geometry); !s.ok()) return s;
  *out = std::move(image);
  return Status::Ok();
}

Status writeNiftiField(const std::string& path, const std::vector<float>& values, const Coord& dims,
                       const VolumeGeometry& geometry) {
  if (int64_t(values.size()) != int64_t(dims.x) * dims.y * dims.z)
    return Status::InvalidArgument(
        fmt::format("{}: {} values do not fill dims {}x{}x{}", path, values.size(), dims.x, dims.y, dims.z));
  nifti_1_header h{};
  h.sizeof_hdr = 348;
  h.dim[0] = 3;
  h.dim[1] = short(dims.x), h.dim[2] = short(dims.y), h.dim[3] = short(dims.z);
  for (int i = 4; i < 8; ++i) h.dim[i] = 1;
  h.datatype = NIFTI_TYPE_FLOAT32;
  h.bitpix = 32;
  h.pixdim[0] = 1;
  h.pixdim[1] = float(geometry.spacing.x), h.pixdim[2] = float(geometry.spacing.y),
  h.pixdim[3] = float(geometry.spacing.z);
  h.vox_offset = 352;
  h.scl_slope = 1;
  h.xyzt_units = NIFTI_UNITS_MM;
  h.sform_code = NIFTI_XFORM_ALIGNED_ANAT;
  const auto a = volumeAffine(geometry);
  for (int c = 0; c < 4; ++c) {
    h.srow_x[c] = float(a[0][size_t(c)]);
    h.srow_y[c] = float(a[1][size_t(c)]);
    h.srow_z[c] = float(a[2][size_t(c)]);
  }
  std::snprintf(h.descrip, sizeof h.descrip, "distband distance field");
  std::memcpy(h.magic, "n+1\0", 4);
  std::string raw(352 + values.size() * sizeof(float), '\0');
  std::memcpy(raw.data(), &h, sizeof h);  // then 4 bytes of zeros: no extension
  if (!values.empty()) std::memcpy(raw.data() + 352, values.data(), values.size() * sizeof(float));
  std::string gz;
  if (Status s = gzipCompress(raw, &gz); !s.ok()) return s;
  std::string tmp;
  std::FILE* f = nullptr;
  if (Status s = openTempBeside(path, "wb", &tmp, &f); !s.ok()) return s;
  Status error;
  if (std::fwrite(gz.data(), 1, gz.size(), f) != gz.size())
    error = Status::IoError(fmt::format("{}: write failed", path));
  return commitTemp(f, tmp, path, error);
}

}  // namespace distband

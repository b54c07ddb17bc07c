// Volume files: seed and label volumes as medical imaging and microscopy keep them — NumPy (.npy), NIfTI-1/2 (.nii,
// .nii.gz: core/io/nifti.h) and NRRD (.nrrd, .nhdr with its data file: core/io/nrrd.h) — with where their voxels lie.
// Contract:
//   * VolumeImage: the labels (core/seeds/label_volume.h) and the geometry the file's header gives: the spacing and
//     origin along the array's axes (x fastest), and the header's voxel-to-world affine. Only axis-aligned directions
//     are accepted (each array axis along one world axis, possibly reversed or permuted; a rotated or sheared one is
//     refused, kInvalidArgument saying so): the distances a grid of that spacing gives are then the world's.
//   * Element types: unsigned integers of 8, 16 and 32 bits as they are; signed ones and floats when every value is a
//     non-negative integer that fits 32 bits (stored in the smallest unsigned type holding the largest; a label map
//     saved as float32 is common), kInvalidArgument naming the first that is not.
//   * Untrusted bytes: parseVolumeFile() reads a whole file image in memory and never opens a file (an NRRD header
//     naming a detached data file is refused); every declared size is checked against `limits` before anything is
//     allocated and against the bytes present after; compressed data inflate to at most the declared size (a gzip
//     bomb is refused as soon as it overflows). Errors name `name`, never quote more than a short excerpt.
//   * readVolumeFile(): the CLI's reader — the file at `path` (format from its extension), and for an .nhdr its data
//     file, which must lie in the header's directory (no other path is opened); kNotFound / kIoError from the OS.
//   * volumeAffine(): the 3x4 voxel-to-world matrix of a geometry (the header's, or spacing and origin).
//   * overrideGeometry(): the one place that decides a volume's grid spacing and origin: what the caller gives (the
//     CLI's --spacing / --voxel-size and --origin) over the header's, over kDefaultVoxelSize and (0, 0, 0).
// Pure functions; thread-safe.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "core/grid.h"
#include "core/seeds/label_volume.h"
#include "core/status.h"
#include "core/types.h"

namespace distband {

enum class VolumeFileFormat { kNpy, kNifti, kNrrd };

std::string_view volumeFileFormatName(VolumeFileFormat format);  ///< "npy", "nifti", "nrrd"
/// From a path's extension: .npy, .nii, .nii.gz, .nrrd, .nhdr (case-insensitive); nullopt otherwise.
std::optional<VolumeFileFormat> volumeFileFormatOf(std::string_view path);

/// Where a volume's voxels lie in the world.
struct VolumeGeometry {
  Vec3d spacing{kDefaultVoxelSize, kDefaultVoxelSize, kDefaultVoxelSize};  ///< along the array's x, y, z axes (> 0)
  Vec3d origin{0, 0, 0};                                                   ///< the world position of voxel (0, 0, 0)
  bool from_header = false;  ///< read from the file (false: a .npy, which has none)
  /// Rows of the header's 3x4 voxel-to-world matrix (NIfTI: RAS+ millimetres; NRRD: its space); from spacing and
  /// origin when absent.
  std::optional<std::array<std::array<double, 4>, 3>> affine;
  /// The affine's axes are not the array's in order, or point backwards: world = origin + spacing * index does not
  /// hold (distances do; a file written back with the affine keeps the layout).
  bool reoriented = false;
};

struct VolumeImage {
  LabelVolume volume;
  VolumeGeometry geometry;
};

struct VolumeReadLimits {
  uint64_t max_voxels = uint64_t(1) << 36;  ///< dims.x * dims.y * dims.z
};

Status parseVolumeFile(std::string_view bytes, VolumeFileFormat format, std::string_view name,
                       const VolumeReadLimits& limits, VolumeImage* out);

Status readVolumeFile(const std::string& path, const VolumeReadLimits& limits, VolumeImage* out);

std::array<std::array<double, 4>, 3> volumeAffine(const VolumeGeometry& geometry);

/// `file` with `spacing` and `origin` where given (each > 0 and finite: the caller checked them). A header's affine
/// keeps its axes' directions (a flip or permutation stays) with the new lengths and translation.
VolumeGeometry overrideGeometry(VolumeGeometry file, const std::optional<Vec3d>& spacing,
                                const std::optional<Vec3d>& origin);

/// The geometry of an affine's 3x3 part and translation: spacing = its column norms; kInvalidArgument when a column
/// is not along one world axis (within 1e-6 of its norm), two share one, or a norm is not finite and > 0. `what`
/// names the matrix in messages ("the sform", "space directions").
Status axisAlignedGeometry(const std::array<std::array<double, 4>, 3>& affine, std::string_view name,
                           std::string_view what, VolumeGeometry* out);

/// The elements of a file as labels: `count` elements of `kind` ('u' unsigned, 'i' signed, 'f' float) and `bytes`
/// (1, 2, 4 or 8), `big_endian` or not, from `data` (exactly count * bytes), converted as the contract says.
Status labelsFromElements(std::string_view data, const Coord& dims, char kind, int bytes, bool big_endian,
                          std::string_view name, LabelVolume* out);

}  // namespace distband

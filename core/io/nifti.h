// NIfTI: single-file NIfTI-1 and NIfTI-2 images (.nii, .nii.gz) read as seed or label volumes, and distance fields
// written back as .nii.gz with the input's affine. The header layouts are libnifti2's (nifti1.h, nifti2.h).
// Contract (the untrusted-input rules of core/io/volume_file.h):
//   * parseNifti(): either byte order, gzip-compressed or not; dim[0] of 3 (or more with every extra extent 1), each
//     extent in [1, kMaxGridDim] and their product within limits.max_voxels; vox_offset inside the file, at most 64 MiB
//     of extensions past the header and at least the header; the data exactly the declared voxels (trailing bytes
//     refused); a compressed file inflates to exactly vox_offset + the data. Element types: uint8/16/32, int8/16/32,
//     float32/64 as volume_file.h converts them; scaled data (scl_slope not 0 or 1, or scl_inter not 0) are refused
//     (they are no labels). The geometry: the sform when sform_code > 0, else the qform when qform_code > 0
//     (quaternion, qfac from pixdim[0]), else the pixdims; axis-aligned only. Returns kInvalidArgument
//     (kResourceExhausted beyond the limits) naming `name`.
//   * writeNiftiField(): a NIfTI-1 .nii.gz of float32 values (x fastest, dims), sform_code 2 with `geometry`'s
//     affine (volumeAffine) and the spacing as pixdims, so nibabel reads the same affine back; atomic (a temporary
//     beside the target, renamed over it); kIoError naming the path when the OS refuses.
// Pure functions; thread-safe.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "core/io/volume_file.h"
#include "core/status.h"

namespace distband {

Status parseNifti(std::string_view bytes, std::string_view name, const VolumeReadLimits& limits, VolumeImage* out);

Status writeNiftiField(const std::string& path, const std::vector<float>& values, const Coord& dims,
                       const VolumeGeometry& geometry);

}  // namespace distband

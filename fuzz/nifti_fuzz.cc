// Fuzz target: the NIfTI reader (core/io/nifti.h) on arbitrary bytes, gzip-compressed or not, under limits small
// enough that an input can only pass with a volume it really holds. On success the volume must be consistent (its
// dims within the limits, its bytes exactly voxels x element width, a positive finite spacing); on failure the Status
// must say the bytes are malformed (kInvalidArgument) or over a limit (kResourceExhausted), naming the input.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "core/io/nifti.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  distband::VolumeReadLimits limits;
  limits.max_voxels = uint64_t(1) << 20;  // 4 MiB of uint32 at most: an input cannot allocate more
  distband::VolumeImage image;
  const distband::Status status =
      distband::parseNifti(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.nii", limits, &image);
  if (!status.ok()) {
    using Code = distband::Status::Code;
    if (status.code() != Code::kInvalidArgument && status.code() != Code::kResourceExhausted) __builtin_trap();
    if (status.message().find("fuzz.nii") == std::string::npos) __builtin_trap();
    return 0;
  }
  const distband::LabelVolume& v = image.volume;
  if (uint64_t(v.voxelCount()) > limits.max_voxels) __builtin_trap();
  if (v.bytes().size() != uint64_t(v.voxelCount()) * v.elementBytes()) __builtin_trap();
  for (double s : {image.geometry.spacing.x, image.geometry.spacing.y, image.geometry.spacing.z})
    if (!(std::isfinite(s) && s > 0)) __builtin_trap();
  return 0;
}

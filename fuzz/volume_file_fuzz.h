// Shared body of the volume-file fuzz targets (NIfTI, NRRD): a parser on arbitrary bytes under limits small enough
// that an input can only pass with a volume it really holds. On success the volume must be consistent (its dims
// within the limits, its bytes exactly voxels x element width, a positive finite spacing); on failure the Status must
// say the bytes are malformed (kInvalidArgument) or over a limit (kResourceExhausted), naming the input.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "core/io/volume_file.h"

/// `parse(bytes, name, limits, &image)` is the reader under test; `name` is what its messages must name.
template <class Parse>
int fuzzVolumeFile(const char* name, const uint8_t* data, size_t size, Parse parse) {
  distband::VolumeReadLimits limits;
  limits.max_voxels = uint64_t(1) << 20;  // 4 MiB of uint32 at most: an input cannot allocate more
  distband::VolumeImage image;
  const distband::Status status =
      parse(std::string_view(reinterpret_cast<const char*>(data), size), name, limits, &image);
  if (!status.ok()) {
    using Code = distband::Status::Code;
    if (status.code() != Code::kInvalidArgument && status.code() != Code::kResourceExhausted) __builtin_trap();
    if (status.message().find(name) == std::string::npos) __builtin_trap();
    return 0;
  }
  const distband::LabelVolume& v = image.volume;
  if (uint64_t(v.voxelCount()) > limits.max_voxels) __builtin_trap();
  if (v.bytes().size() != uint64_t(v.voxelCount()) * v.elementBytes()) __builtin_trap();
  for (double s : {image.geometry.spacing.x, image.geometry.spacing.y, image.geometry.spacing.z})
    if (!(std::isfinite(s) && s > 0)) __builtin_trap();
  return 0;
}

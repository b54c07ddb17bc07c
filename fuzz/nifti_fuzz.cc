// Fuzz target: the NIfTI reader (core/io/nifti.h) on arbitrary bytes, gzip-compressed or not; what must hold is in
// volume_file_fuzz.h.
#include "core/io/nifti.h"
#include "fuzz/volume_file_fuzz.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return fuzzVolumeFile("fuzz.nii", data, size, [](auto bytes, auto name, const auto& limits, auto* image) {
    return distband::parseNifti(bytes, name, limits, image);
  });
}

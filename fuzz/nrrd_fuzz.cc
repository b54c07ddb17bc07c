// Fuzz target: the NRRD reader (core/io/nrrd.h) on arbitrary bytes, attached raw or gzip data (a detached data file is
// refused: no reader for one is given); what must hold is in volume_file_fuzz.h.
#include "core/io/nrrd.h"
#include "fuzz/volume_file_fuzz.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return fuzzVolumeFile("fuzz.nrrd", data, size, [](auto bytes, auto name, const auto& limits, auto* image) {
    return distband::parseNrrd(bytes, name, limits, nullptr, image);
  });
}

// Fuzz target: the STL reader (core/mesh/mesh_reader.h) on arbitrary bytes.
#include "fuzz/mesh_fuzz.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return fuzzMeshFormat(distband::MeshFormat::kStl, data, size);
}

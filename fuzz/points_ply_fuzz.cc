// Fuzz target: the .ply point-cloud reader (core/io/point_cloud.h) on arbitrary bytes (see point_cloud_fuzz.h).
#include "fuzz/point_cloud_fuzz.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return fuzzPointCloud(distband::PointFileFormat::kPly, data, size);
}

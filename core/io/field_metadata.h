// Field metadata: the JSON sidecar that tells a reader of a dense field file how to interpret it.
// Contract: describes one computed field — grid (dims, origin, voxel size), the array layout, units and sign
// convention, the distance limit and the background value stored beyond it, and how it was computed. Pure
// formatting; writeFieldMetadata() returns "" on success or a message naming the path. Thread-safe.
#pragma once

#include <cstdint>
#include <string>

#include "core/grid.h"

namespace distband {

struct FieldMetadata {
  Grid grid;
  std::string data_file;         ///< the field file this describes (name only, for the reader)
  bool signed_distance = false;  ///< negative inside (OpenVDB's convention)
  double limit_world = 0;        ///< +infinity: no limit
  double background_world = 0;   ///< value stored beyond the limit (negated inside when signed)
  std::string stencil;
  std::string mode;
  double segment_length_world = 0;
  int64_t voxels_delivered = 0;
  double seconds = 0;
};

/// The metadata as pretty-printed JSON text.
std::string fieldMetadataJson(const FieldMetadata& meta);

std::string writeFieldMetadata(const std::string& path, const FieldMetadata& meta);

}  // namespace distband

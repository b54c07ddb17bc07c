// Field metadata: the JSON sidecar that tells a reader of a dense field file how to interpret it.
// Contract: describes one computed field — grid (dims, origin, voxel size, and the spacing along each axis: on an
// anisotropic grid the voxel size is the smallest of them, the unit of the limit in voxels), the array layout, units and sign
// convention, the distance limit and the background value stored beyond it, and how it was computed. Pure
// formatting; writeFieldMetadata() writes atomically (a temporary beside the target, renamed over it) and returns
// OK, or kIoError with a message naming the file when the OS cannot create, write or rename it. Thread-safe.
#pragma once

#include <cstdint>
#include <string>

#include "core/grid.h"
#include "core/seeds/seeds.h"
#include "core/status.h"

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
  std::string sign;         ///< the sign method in force ("" when unsigned or not a mesh)
  std::string sign_reason;  ///< why (e.g. "auto: the mesh is closed")
  SignShares sign_shares;   ///< how many voxels each sign test decided (meshes; all 0 when not known)
  int padding_voxels = -1;  ///< the padding around the seeds' bounds (-1: not applicable, explicit dims)
  bool band_clipped = false;  ///< the padding was smaller than the limit in voxels
  /// False when the run was interrupted: the file holds the `segments` complete segments received, i.e. every voxel
  /// with |distance| <= complete_up_to_world; farther voxels hold the background.
  bool complete = true;
  int segments = 0;
  double complete_up_to_world = 0;
  std::string closest_file;     ///< the closest-feature array, if written (name only)
  std::string closest_feature;  ///< what its ids are: "triangle", "point" or "voxel"
};

/// The metadata as pretty-printed JSON text.
std::string fieldMetadataJson(const FieldMetadata& meta);

Status writeFieldMetadata(const std::string& path, const FieldMetadata& meta);

}  // namespace distband

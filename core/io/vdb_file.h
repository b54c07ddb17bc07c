// writeVdbFile: writes sealed VdbTrees (core/io/vdb_tree.h) as an OpenVDB file (format 224, as OpenVDB 10 writes it),
// without linking OpenVDB. Any OpenVDB 6+ reads it (tests read every file back with OpenVDB's own reader).
// Contract:
//   * One grid per VdbGridOut, in order: its tree's topology and leaf buffers, the transform (a scale by the spacing
//     plus a translation: OpenVDB's UniformScaleTranslateMap when the spacing is the same on every axis, else its
//     ScaleTranslateMap, so OpenVDB reads back each axis's voxel size), and its metadata — `metadata`, plus "class"
//     ("level set" when level_set), "name", and the statistics OpenVDB adds when it writes (file_bbox_min/max of
//     the active voxels, file_voxel_count, file_compression). Names must be unique.
//   * Compression is OpenVDB's default: inactive values are not stored when a node has at most two of them
//     (the inside/outside mask of a level set), and each node's stored values are Blosc-compressed (LZ4, byte
//     shuffle, level 9), leaves in parallel on the caller's TBB arena.
//   * Writes `path` directly (callers wanting atomicity write a temporary and rename it). Returns OK, or a Status
//     whose message names the path and the problem, never throwing for I/O: kInvalidArgument for a grid without
//     exactly one tree or with an unsealed tree (nothing is written then); kIoError when the OS cannot open or
//     write the file.
#pragma once

#include <cstdint>
#include <string>
#include <variant>
#include <vector>

#include "core/io/vdb_tree.h"
#include "core/status.h"
#include "core/types.h"

namespace distband {

/// A metadata value: OpenVDB's "bool", "int32", "int64", "string" or "vec3i".
using VdbMetaValue = std::variant<bool, int32_t, int64_t, std::string, Coord>;

struct VdbGridOut {
  std::string name;
  /// Exactly one tree, sealed (and flood-filled, for a level set).
  const VdbTree<float>* float_tree = nullptr;
  const VdbTree<int32_t>* int32_tree = nullptr;
  const VdbTree<int64_t>* int64_tree = nullptr;
  bool level_set = false;
  std::vector<std::pair<std::string, VdbMetaValue>> metadata;
};

struct VdbTransformOut {
  Vec3d spacing{1, 1, 1};  ///< the voxel's size along x, y and z
  Vec3d translation;  ///< world position of voxel (0, 0, 0)
};

Status writeVdbFile(const std::string& path, const std::vector<VdbGridOut>& grids, const VdbTransformOut& xform);

}  // namespace distband

// VdbFieldBuilder: assembles delivered bricks into an OpenVDB level-set FloatGrid and writes it as a .vdb file.
// Contract: construct with the Grid and the background (= the distance limit, world units; when it is not finite
// and > 0, e.g. an unlimited field, the grid's diagonal length is used instead); add() bricks or whole segments in any order, as they arrive (each brick becomes one leaf: brick origin =
// leaf origin, the masked voxels become active values). finish() (called by write() if needed) runs OpenVDB's
// signedFloodFill so every voxel never delivered reads +background outside and -background inside. The file
// holds one grid named "distance", class GRID_LEVEL_SET, with the linear transform voxel size h and translation
// = grid origin (so voxel (i,j,k) is at origin + h*(i,j,k), as in core/grid.h). write() goes through
// `path + ".tmp"` and a rename, so a reader never sees a half-written file. Not thread-safe; one builder per
// output (add(segment) fills the segment's leaves in parallel on the caller's TBB arena). The embedded CLI and the
// service's client both stream bricks into it.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "core/brick.h"
#include "core/grid.h"

namespace distband {

class VdbFieldBuilder {
 public:
  VdbFieldBuilder(const Grid& grid, float background);
  ~VdbFieldBuilder();
  VdbFieldBuilder(const VdbFieldBuilder&) = delete;
  VdbFieldBuilder& operator=(const VdbFieldBuilder&) = delete;

  /// Also build a grid "closest" of the bricks' closest-feature ids (Brick::closest): an Int32Grid, or an Int64Grid
  /// when `wide`, background -1, the same transform; write() stores it in the same file. Call before any add().
  void addClosestGrid(bool wide);
  void add(const Brick& brick);
  void add(const SegmentBricks& segment);
  /// Flood-fills the signs of undelivered voxels; further add() calls are not allowed afterwards.
  void finish();
  /// Writes the grid (finishing it first). Returns "" or a message naming the path and the problem.
  std::string write(const std::string& path);

  int64_t activeVoxels() const;
  /// The OpenVDB grid (an openvdb::FloatGrid), for callers that include OpenVDB themselves (e.g. the bench).
  /// Opaque here so this header stays free of OpenVDB.
  std::shared_ptr<void> gridHandle();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace distband

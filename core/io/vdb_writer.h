// VdbFieldBuilder: assembles delivered bricks into a level set with OpenVDB's tree shape (core/io/vdb_tree.h) and
// writes it as a .vdb file (core/io/vdb_file.h) — no OpenVDB library involved; OpenVDB reads the files (tests check
// every value it reads back against an OpenVDB-built, flood-filled grid of the same bricks).
// Contract: construct with the Grid and the background (= the distance limit, world units; when it is not finite and
// > 0, e.g. an unlimited field, the grid's diagonal length is used instead); add() bricks or whole segments in any
// order, as they arrive (each brick becomes one leaf: brick origin = leaf origin, the masked voxels become active
// values). finish() (called by write() if needed) flood-fills the signs as OpenVDB's signedFloodFill would, so every
// voxel never delivered reads +background outside and -background inside. The file holds one grid named "distance",
// class level set, with a transform of the grid's spacing and translation = grid origin (so voxel (i,j,k) is at
// origin + spacing*(i,j,k), as in core/grid.h), metadata "distband_dims" and, after setRunState(), "distband_complete" and
// "distband_segments". write() goes through `path + ".tmp"` and a rename, so a reader never sees a half-written file.
// Not thread-safe; one builder per output (add(segment) fills the segment's leaves in parallel on the caller's TBB
// arena). The embedded CLI and the service's client both stream bricks into it.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "core/brick.h"
#include "core/grid.h"
#include "core/io/vdb_tree.h"
#include "core/status.h"

namespace distband {

class VdbFieldBuilder {
 public:
  VdbFieldBuilder(const Grid& grid, float background);
  ~VdbFieldBuilder();
  VdbFieldBuilder(const VdbFieldBuilder&) = delete;
  VdbFieldBuilder& operator=(const VdbFieldBuilder&) = delete;

  /// Also build a grid "closest" of the bricks' closest-feature ids (Brick::closest): int32, or int64 when `wide`,
  /// background -1, the same transform; write() stores it in the same file. Call before any add().
  void addClosestGrid(bool wide);
  void add(const Brick& brick);
  void add(const SegmentBricks& segment);
  /// Whether the run delivered every segment, and how many it delivered (stored as metadata by write()).
  void setRunState(bool complete, int segments);
  /// Flood-fills the signs of undelivered voxels; further add() calls are not allowed afterwards.
  void finish();
  /// Writes the grid (finishing it first). Returns OK, or a Status whose message names the path and the problem:
  /// kIoError when the OS cannot write the temporary file or rename it over `path`.
  Status write(const std::string& path);

  int64_t activeVoxels() const { return distance_.activeVoxels(); }
  /// The distance at any voxel, delivered or not (after finish()).
  float value(const Coord& c) const { return distance_.value(c); }
  /// The field's tree (sealed and flood-filled after finish()), for isosurfaces.
  const VdbTree<float>& distance() const { return distance_; }
  const Grid& grid() const { return grid_; }

 private:
  template <class Tree>
  void addClosest(Tree& tree, const Brick& brick);
  void addClosest(const Brick& brick);

  Grid grid_;
  VdbTree<float> distance_;
  std::unique_ptr<VdbTree<int32_t>> closest32_;  // at most one of the two
  std::unique_ptr<VdbTree<int64_t>> closest64_;
  std::optional<std::pair<bool, int>> run_state_;
  bool finished_ = false;
};

}  // namespace distband

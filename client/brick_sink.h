// BrickSink: turns the stream of delivered bricks (from the in-process engine or, later, the service) into an
// output file. The writer is chosen by the output path's extension: ".npy" is a dense float32 array, ".vdb" an
// OpenVDB level set (core/io/vdb_writer.h), ".nii.gz" a NIfTI-1 float32 image with the layout's affine
// (core/io/nifti.h).
// Contract:
//   * openBrickSink() validates the path (known extension, writable location) before any compute starts and
//     returns "" or a message naming the path. add() may be called once per delivered segment, in order.
//     finish() writes the file and returns the writer's Status (core/io: kIoError when the OS cannot write the
//     file, with a message naming it); nothing is written before finish().
//   * Voxels never delivered hold `background` (the distance limit, or +infinity without one); in a signed
//     field, undelivered voxels labelled inside hold -background (OpenVDB's convention, negative inside).
//   * To add a format, implement BrickSink and add one branch to openBrickSink().
// Not thread-safe: feed it from one thread.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <initializer_list>
#include <memory>
#include <string>
#include <vector>

#include "core/brick.h"
#include "core/grid.h"
#include "core/seeds/label_volume.h"
#include "core/status.h"

namespace distband {

struct FieldLayout {
  Grid grid;
  float background = 0;                                ///< value of undelivered voxels (>= 0)
  bool signed_distance = false;
  LabelVolume inside;  ///< signed only: the seed volume, nonzero = inside (may be empty)
  /// Signed without labels (meshes): undelivered voxels take the sign of the nearest delivered voxel along their
  /// x row (the band encloses the surface, so a row enters and leaves the inside through delivered voxels).
  bool sign_from_band = false;
  /// .nii.gz: the input volume's voxel-to-world affine; unset: the grid's spacing and origin.
  std::optional<std::array<std::array<double, 4>, 3>> affine;
};

class BrickSink {
 public:
  virtual ~BrickSink() = default;
  virtual void add(const SegmentBricks& segment) = 0;
  virtual Status finish() = 0;
  /// What finish() writes, for logs: "field.npy (float32, shape (Z, Y, X) = (64, 64, 64))".
  virtual std::string description() const = 0;
};

std::string openBrickSink(const std::string& path, const FieldLayout& layout, std::unique_ptr<BrickSink>* out);

/// "" when `path` ends with one of `extensions` (e.g. {".png"}) and can be created or overwritten (its directory
/// exists and is writable), without touching it; otherwise "FLAG PATH: the problem".
std::string checkOutputPath(const std::string& flag, const std::string& path,
                            std::initializer_list<const char*> extensions);

}  // namespace distband

// PointFileOutputs: the files `distband at` writes, whether the results come from the in-process search or from a
// server's QueryPoints stream: one .npy per output, one row per query point in the query file's order.
//   --out D.npy (N,) distances   --closest-points CP.npy (N, 3)   --closest IDS.npy (N,)   --gradient G.npy (N, 3)
// Contract:
//   * checkPointOutputFlags() checks the flags before anything is read or sent: at least one output, each a writable
//     .npy path, no path named twice; "" or a message naming the flag.
//   * open() starts each file as a temporary beside it (core/io/npy.h's NpyRowWriter); append() adds a chunk's packed
//     results (core/points/point_results.h: values float32 or float64, the query points' type; ids int32, int64 for
//     voxels; -1 and NaN beyond the limit); finish() renames every file into place; a run that stops early leaves
//     no file (abandon(), or the destructor).
// Not thread-safe: one caller.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <CLI/CLI.hpp>

#include "core/io/npy.h"
#include "core/points/point_results.h"
#include "core/status.h"

namespace distband {

struct PointOutputFlags {
  std::string out, closest_points, closest, gradient;
};

void addPointOutputFlags(CLI::App* command, PointOutputFlags* flags);
std::string checkPointOutputFlags(const PointOutputFlags& flags);
/// The outputs the flags ask for besides the distance.
PointOutputs pointOutputsOf(const PointOutputFlags& flags);

class PointFileOutputs {
 public:
  Status open(const PointOutputFlags& flags, const PointPacking& packing);
  /// A chunk of `n` points: each array packed as open()'s packing says (empty for an output not asked for).
  Status append(size_t n, std::string_view distance, std::string_view closest_points, std::string_view features,
                std::string_view gradients);
  /// Renames every file into place; `lines` gets one "wrote ..." line per file.
  Status finish(std::vector<std::string>* lines);
  void abandon();
  int64_t rows() const { return rows_; }

 private:
  /// distance, closest points, features, gradients; null when not asked for.
  std::array<std::unique_ptr<NpyRowWriter>, 4> files_;
  int64_t rows_ = 0;
};

}  // namespace distband

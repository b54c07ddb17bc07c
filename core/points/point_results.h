// PointResultBuffer: one chunk's results of a point query held for queryPoints, and packed as the service sends them
// and `distband at` writes them: packed little-endian arrays, values as float32 or float64 (the query points' type),
// feature ids as int32 (triangles, points) or int64 (voxels).
// Contract: resize(n, outputs) sizes the arrays the outputs ask for (distance always); results() hands them to
// queryPoints; pack*() append the packed bytes of the first n entries. Not thread-safe (one chunk, one owner).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "core/points/point_query.h"
#include "core/types.h"

namespace distband {

/// The most points one chunk of a streamed point query holds (the service's QueryPoints, `distband at`): its reply
/// stays under 4 MiB at 64 bytes a point, so a chunk is small next to a server's stream buffer.
inline constexpr size_t kMaxChunkPoints = size_t(1) << 16;

/// Which outputs a point query computes besides the distance.
struct PointOutputs {
  bool closest_points = false;
  bool features = false;
  bool gradients = false;
};

/// How values and ids are packed.
struct PointPacking {
  bool doubles = false;   ///< float64 values (else float32)
  bool wide_ids = false;  ///< int64 ids (volumes' voxels; else int32)
};

class PointResultBuffer {
 public:
  void resize(size_t n, const PointOutputs& outputs);
  size_t size() const { return distance_.size(); }
  PointResults results();
  /// Packed bytes of each array (cleared first); an array not computed packs to nothing.
  void packDistance(const PointPacking& p, std::string* out) const { packValues(distance_.data(), size(), p, out); }
  void packClosestPoints(const PointPacking& p, std::string* out) const;
  void packFeatures(const PointPacking& p, std::string* out) const;
  void packGradients(const PointPacking& p, std::string* out) const;

  /// Packs `n` doubles as float32 or float64.
  static void packValues(const double* values, size_t n, const PointPacking& p, std::string* out);

 private:
  PointOutputs outputs_;
  std::vector<double> distance_;
  std::vector<Vec3d> closest_, gradient_;
  std::vector<int64_t> feature_;
};

}  // namespace distband

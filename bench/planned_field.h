// Planned fields: how every bench computes a field in this process, records what a run delivered, and decides
// whether a result is right.
//   * Planning: a bench states what it wants as a FieldRequest; planMeshField (gridForMesh with the request's limit,
//     then planField) or planGridField (planField on an explicit grid) make every other choice — grid, padding,
//     algorithm, stencil, sign, limit — exactly as `distband compute` and the server do, so a change of defaults in
//     core reaches the benches the day it lands. A bench that measures a specific algorithm asks for it through the
//     request (an explicit stencil, mode or second ring makes the planner run the band).
//   * Running: buildPlannedInputs (buildFieldInputs) and computePlanned (computeField with the plan's run options;
//     the bench sets only threads, interrupter and chunking), or runPlannedField for both.
//   * Recording: DeliveredField holds each voxel's delivered value (NaN: none) and how often it came, so a missing,
//     repeated or out-of-grid voxel is visible.
//   * Judging: compareFields names the first voxel (in z, y, x order) where two delivered fields differ beyond a
//     FieldTolerance; Verdict collects a bench's failures ("FAIL <case> [<grid>]: <what>" on stderr as they are
//     found) and gives the exit status: kExitWrong when anything failed. meshErrorBoundVoxels is the accuracy the
//     docs promise for a mesh field of a plan, the bound the mesh benches judge by.
// Bench code only; thread-safe where stated.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

#include "core/brick.h"
#include "core/field/compute_field.h"
#include "core/field/field_plan.h"
#include "core/grid.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/status.h"

namespace distband::bench {

/// Exit status of a bench that found a wrong or mismatched result (2 is a usage error, 3 a missed performance goal).
inline constexpr int kExitWrong = 1;

/// What the planner decided for one request: the grid (and, for meshes, its padding) and the plan.
struct PlannedField {
  Grid grid;
  GridPadding padding{-1, false};  ///< meshes: the padding gridForMesh chose; -1 for an explicit grid
  FieldPlan plan;
};

/// Meshes: gridForMesh(mesh, grid_options, request.limit()) then planField, as `distband compute --mesh` does.
Status planMeshField(const FieldRequest& request, const TriangleMesh& mesh, const MeshReport& report,
                     const MeshGridOptions& grid_options, PlannedField* out);

/// Points and volumes on an explicit grid: planField, as `distband compute --points/--volume` does. For points set
/// request.point_layout (pointLayout of the points) as the CLI and the server do: the planner's cost model reads it.
Status planGridField(const FieldRequest& request, const Grid& grid, PlannedField* out);

/// What a bench may choose about a run; everything else (limit, segments, closest features) is the plan's.
struct RunSettings {
  int threads = 0;                           ///< 0: the caller's TBB arena
  const Interrupter* interrupter = nullptr;  ///< polled while the inputs are built and while the field is computed
  size_t max_chunk_bricks = 0;               ///< 0: one callback per segment
};

/// buildFieldInputs for the whole grid.
Status buildPlannedInputs(const PlannedField& planned, const SeedSource& source, const Interrupter* interrupter,
                          FieldInputs* out);

/// computeField with planned.plan.runOptions() plus `settings`.
FieldRunResult computePlanned(const PlannedField& planned, FieldInputs inputs, const RunSettings& settings,
                              const SegmentCallback& on_segment);

struct PlannedRun {
  Status status;              ///< of building the inputs (a stopped build: the interrupter's status)
  FieldRunResult result;      ///< valid when status is OK
  double inputs_seconds = 0;  ///< buildFieldInputs
  double total_seconds = 0;   ///< inputs and computeField, callbacks included
};

/// buildPlannedInputs then computePlanned, timed.
PlannedRun runPlannedField(const PlannedField& planned, const SeedSource& source, const RunSettings& settings,
                           const SegmentCallback& on_segment);

/// "256x251x199 voxels of 0.00123, origin (-0.1, 0.02, -0.08)".
std::string gridText(const Grid& grid);

/// A delivered field on a grid. Not thread-safe.
class DeliveredField {
 public:
  DeliveredField() = default;
  explicit DeliveredField(const Grid& grid);
  void add(const SegmentBricks& bricks);
  void add(const Brick& brick);

  const Grid& grid() const { return grid_; }
  bool delivered(int64_t i) const { return times_[size_t(i)] > 0; }
  float value(int64_t i) const { return values_[size_t(i)]; }  ///< NaN when not delivered
  const std::vector<float>& values() const { return values_; }
  int64_t voxels() const { return voxels_; }    ///< distinct voxels delivered
  int64_t repeats() const { return repeats_; }  ///< deliveries of a voxel already delivered (the contract: none)
  int64_t outside() const { return outside_; }  ///< voxels delivered outside the grid (the contract: none)
  Coord firstRepeat() const { return first_repeat_; }
  Coord firstOutside() const { return first_outside_; }

 private:
  Grid grid_;
  std::vector<float> values_;
  std::vector<uint8_t> times_;  ///< saturates at 255
  int64_t voxels_ = 0, repeats_ = 0, outside_ = 0;
  Coord first_repeat_{-1, -1, -1}, first_outside_{-1, -1, -1};
};

/// When two delivered fields count as the same result.
struct FieldTolerance {
  /// 0: every voxel bit for bit. > 0: a voxel both deliver may differ by this much (voxels) and still count.
  double max_diff_voxels = 0;
  /// Of the voxels either field delivers, at least this fraction must be bit-identical (and delivered by both).
  double min_identical_fraction = 1.0;
  /// A voxel both deliver must have the same sign (ignored for |values| under 1e-6 voxel).
  bool same_sign = true;

  static FieldTolerance exact() { return {}; }
};

struct FieldDiff {
  bool ok = true;
  std::string grid_mismatch;  ///< set when the grids differ (then nothing else is compared)
  int64_t union_voxels = 0, identical = 0, missing = 0, extra = 0, beyond_tolerance = 0, sign_flips = 0;
  int64_t repeats = 0, outside = 0;  ///< of the compared field
  double max_diff_voxels = 0;        ///< over voxels both deliver
  /// The first voxel (z, y, x order) that breaks the tolerance, or, when only the identical fraction fails, the first
  /// one that is not identical; {-1,-1,-1} when none.
  Coord first{-1, -1, -1};
  float first_expected = std::numeric_limits<float>::quiet_NaN(), first_got = std::numeric_limits<float>::quiet_NaN();
  /// "identical" or e.g. "12 of 830112 voxels differ (max 0.5 voxel, 0 sign flips), 3 missing, 0 extra; first at
  /// (12, 40, 7): expected 0.0123, got none".
  std::string describe() const;
};

/// `got` against `expected`: grids must be equal (origin, voxel size and dims exactly); then every voxel of either.
FieldDiff compareFields(const DeliveredField& expected, const DeliveredField& got, const FieldTolerance& tolerance);

/// A bench's pass/fail record. Thread-safe.
class Verdict {
 public:
  explicit Verdict(std::string bench) : bench_(std::move(bench)) {}
  /// Records and prints "FAIL <case> [<grid>]: <what>" on stderr.
  void fail(std::string_view case_name, const Grid& grid, std::string_view what);
  void fail(std::string_view case_name, std::string_view what);
  /// fail() unless `diff` is ok.
  void check(std::string_view case_name, const FieldDiff& diff, const Grid& grid);
  bool ok() const;
  int failures() const;
  /// Prints "<bench>: PASS" or "<bench>: N failures (first: ...)" on stderr; 0 or kExitWrong.
  int finish() const;

 private:
  std::string bench_;
  mutable std::mutex mu_;
  std::vector<std::string> failures_;
};

/// The largest | |delivered| - exact distance | (voxels) the docs promise for a mesh field of this plan: triangle sites
/// (exact mode) with cubic26 0.05, with any other stencil 0.15 (the bound of the default fcc12:
/// tests/core/seeds/mesh_seeds_test.cc, the protocol's Stencil comment); closest-point sites (paper mode) 0.2
/// (docs/benchmarks.md: 0.074-0.153 measured on the Table 1 meshes at 64^3-256^3).
double meshErrorBoundVoxels(const FieldPlan& plan);

}  // namespace distband::bench

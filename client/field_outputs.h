// FieldOutputs: every file a distance-field command writes, shared by `distband compute` (the in-process engine)
// and `distband query` (a server's stream), so both take the same output flags and write the same files.
// Contract:
//   * checkOutputFlags() validates the flags before any upload or compute: each path's extension and writable
//     directory, the slice spec, the isosurface value (against the limit when it is given in world units), and
//     that a slice or isosurface has a finite limit (beyond it the field holds only the background). Messages name
//     the flag.
//   * open() once the grid and limit are known (the seeds, or the stream's header): resolves the slice against
//     the grid, checks the isosurface against the limit in force, and allocates what the files are built from.
//   * add() buffers delivered bricks; commitSegment() hands the buffered segment to the builders. Only committed
//     (complete) segments are ever written, so an interrupted run keeps every complete segment received and
//     nothing of a half-delivered one. Peak memory: the builders plus the open segment's bricks.
//   * finish() writes every file atomically (a temporary beside the target, renamed over it): the field (.npy or
//     .vdb or .nii.gz), the closest-feature ids (.npy: int32 for triangles and points, int64 for voxels and nearest
//     labels; -1 where nothing
//     was delivered; or, with --closest naming --out's .vdb, an Int32Grid/Int64Grid "closest" in that file), the
//     metadata JSON, the slice PNG and the isosurface OBJ. It returns the first error's message ("" when every
//     file was written; the writers' Status codes stay inside, the commands take messages); `lines` gets one
//     "wrote ..." line per file. When the run is incomplete and no --meta was given, the metadata is
//     written beside the field anyway (FIELD.json): an incomplete field must not pass for a complete one.
//   * describeField() says what the files describe from the plan the field was computed by (compute's own, or the
//     one query rebuilds from its stream's header), so both commands label their files alike; finishStoppedRun()
//     ends a run stopped by Ctrl-C or --deadline the same way for both (the complete segments kept).
// Not thread-safe: one caller.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <memory>
#include <string>
#include <vector>

#include "client/brick_sink.h"
#include "client/command.h"
#include "core/brick.h"
#include "core/field/field_plan.h"
#include "core/grid.h"
#include "core/mesh/mesh_grid.h"
#include "core/io/slice_png.h"
#include "core/status.h"

namespace distband {

/// The output flags as given on the command line.
struct OutputFlags {
  std::string out;                      ///< --out FIELD.npy | FIELD.vdb | FIELD.nii.gz
  std::string npy;                      ///< --npy FIELD.npy (a second, dense copy; may be empty)
  std::string meta;                     ///< --meta FIELD.json
  std::string closest;                  ///< --closest IDS.npy, or --out's FIELD.vdb (a grid beside the distances)
  std::string nearest_label;            ///< --nearest-label LABELS.npy, or --out's FIELD.vdb (volumes' seed field)
  std::vector<std::string> slice_png;   ///< --slice-png AXIS:INDEX PNG
  std::vector<std::string> isosurface;  ///< --isosurface D OBJ
};

/// Registers --out, --npy, --meta, --closest, --slice-png and --isosurface on a command (compute and query).
void addOutputFlags(CLI::App* command, OutputFlags* flags);

/// The warning both commands print when the grid's padding is below the limit (GridPadding::band_clipped).
std::string clippedBandWarning(int padding_voxels, double limit_voxels, bool padding_given);

/// What checkOutputFlags() parsed.
struct OutputPlan {
  OutputFlags flags;
  SliceSpec slice;
  double isosurface = 0;  ///< world units
  /// --nearest-label: the closest features asked for are the seeds' labels (written where flags.closest says).
  bool nearest_label = false;
  bool wants_closest() const { return !flags.closest.empty(); }
};

/// `limit_world`: the limit in world units when known (+infinity: none), or NaN when given in voxels (checked in
/// open()). Returns "" or a message naming the flag.
std::string checkOutputFlags(const OutputFlags& flags, double limit_world, OutputPlan* plan);

/// What the files describe: known once the grid is.
struct FieldDescription {
  Grid grid;
  double limit_world = 0;  ///< +infinity: no limit
  bool signed_distance = false;
  LabelVolume inside;  ///< see FieldLayout
  bool sign_from_band = false;                         ///< see FieldLayout
  std::string stencil, mode, sign, sign_reason;
  int padding_voxels = -1;  ///< -1: explicit dims
  bool band_clipped = false;
  double segment_length_world = 0;
  std::string closest_feature;  ///< "triangle", "point", "voxel", "label", or "" when the bricks carry none
  /// A volume file's voxel-to-world affine (NIfTI, NRRD): a .nii.gz field is written with it; unset: the grid's.
  std::optional<std::array<std::array<double, 4>, 3>> affine;
  std::string title;            ///< leads a slice picture's title (e.g. the input file's name)
};

/// What the files say about a field computed by `plan` on `grid`: compute's own plan, or the plan query's stream
/// header describes. `padding`: gridForMesh's (voxels -1 for an explicit lattice). `inside`: a volume where the
/// command holds it (compute), whose labels then sign the field; without it a signed field takes its signs from the
/// delivered band. `title` leads a slice's title.
FieldDescription describeField(const FieldPlan& plan, const Grid& grid, const GridPadding& padding, std::string title,
                               LabelVolume inside = {});

struct RunOutcome {
  bool complete = true;  ///< false: interrupted (only the committed segments are written)
  int64_t voxels = 0;
  double seconds = 0;
  SignShares sign_shares;  ///< meshes: how the voxels were signed (the metadata's sign.voxels_by_test)
};

class FieldOutputs {
 public:
  explicit FieldOutputs(OutputPlan plan);
  ~FieldOutputs();

  /// Returns "" or a message naming the flag (a slice outside the grid, an isosurface beyond the limit, ...).
  std::string open(const FieldDescription& field);
  void add(SegmentBricks&& batch);
  /// The buffered bricks form a complete segment whose |distance| range ends at `upper_world`.
  void commitSegment(double upper_world);
  int committedSegments() const { return segments_; }
  double completeUpTo() const { return complete_up_to_; }  ///< upper end of the last committed segment
  /// After an interrupted finish(): what was kept, for the user ("kept the 6 complete segments (...)").
  std::string keptSummary() const;
  std::string finish(const RunOutcome& run, std::vector<std::string>* lines);

 private:
  void build(const SegmentBricks& batch);
  Status writeClosest();

  OutputPlan plan_;
  FieldDescription field_;
  std::vector<SegmentBricks> open_segment_;
  int segments_ = 0;
  double complete_up_to_ = 0;
  std::unique_ptr<BrickSink> npy_;
  std::unique_ptr<BrickSink> nifti_;  ///< --out FIELD.nii.gz
  std::unique_ptr<class VdbFieldBuilder> vdb_;
  std::vector<int64_t> closest_;  ///< dense, x fastest
};

/// How a run ended before its end: the user asked (Ctrl-C) or --deadline passed.
enum class RunStop { kInterrupted, kDeadline };

/// Ends a run that stopped early, the same way for both commands: writes what finish() keeps (every complete segment,
/// marked complete=false), lists the files on `out`, says what was kept on `err` ("distband COMMAND: interrupted;
/// kept the 3 complete segments ..."); returns the exit code (130 interrupted, 1 deadline).
int finishStoppedRun(FieldOutputs& outputs, const RunOutcome& run, RunStop stop, std::string_view command,
                     const CliContext& ctx);

}  // namespace distband

#include "client/compute_command.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <optional>

#include <fmt/format.h>
#include <tbb/global_control.h>

#include "client/interrupt_watch.h"
#include "core/band/band_engine.h"
#include "core/field/compute_field.h"
#include "core/field/field_plan.h"
#include "core/io/volume_file.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/mesh_seeds.h"
#include "core/seeds/mesh_sign.h"

namespace distband {
namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

int usage(const CliContext& ctx, const std::string& message) {
  ctx.err << "distband compute: " << message << "\n";
  return kExitUsage;
}

/// The flags, checked: what to compute and where to write it.
struct ComputeSetup {
  FieldSpec spec;
  OutputPlan outputs;
};

/// The seeds read, the grid built, every choice made and the algorithm's inputs built.
struct SeedInput {
  Grid grid;
  GridPadding padding{-1, false};  ///< gridForMesh's; voxels -1 on an explicit lattice
  FieldPlan plan;
  FieldInputs inputs;
  LabelVolume volume;  ///< volumes
  VolumeGeometry geometry;                           ///< volumes: the file's header, with the flags' spacing and origin
  std::string description;                           ///< the seeds and grid, for the header line
};

/// Step 1: every flag and output path, before any file is read.
std::string checkComputeFlags(const ComputeArgs& a, ComputeSetup* setup) {
  if (std::string e = parseFieldFlags(a.field, &setup->spec); !e.empty()) return e;
  if (a.threads < 0) return fmt::format("--threads must be >= 0 (got {})", a.threads);
  setup->spec.request.closest_features = !a.outputs.closest.empty();
  setup->spec.request.nearest_label = !a.outputs.nearest_label.empty();
  return checkOutputFlags(a.outputs, setup->spec.outputLimit(), &setup->outputs);
}

/// The grid the flags ask for: the lattice (dims given, or the volume's), or gridForMesh around `bounds` (the mesh,
/// or the points as vertices) or --box.
Status buildGrid(const FieldSpec& spec, const TriangleMesh& bounds, const Coord& volume_dims, SeedInput* in) {
  if (!spec.grid.lattice) return gridForMesh(bounds, spec.meshGridOptions(), spec.request.limit(), &in->grid, &in->padding);
  if (spec.seeds == SeedKind::kVolume) {
    in->geometry = overrideGeometry(in->geometry, spec.grid.spacing, spec.grid.origin_given);
    in->grid = Grid(in->geometry.origin, in->geometry.spacing, volume_dims);
  } else if (spec.grid.spacing) {
    in->grid = Grid(spec.grid.origin, *spec.grid.spacing, *spec.grid.dims);
  } else {
    in->grid = Grid(spec.grid.origin, spec.grid.voxel_size, *spec.grid.dims);
  }
  return in->grid.validate();
}

std::string seedDescription(const FieldSpec& spec, const MeshReport& report, const SeedInput& in) {
  const Coord d = in.grid.dims();
  const std::string grid = fmt::format("{}x{}x{}", d.x, d.y, d.z);
  switch (spec.seeds) {
    case SeedKind::kMesh:
      return fmt::format("mesh {} ({}; grid {}, {}, sites {}, sign {} ({}))", spec.source, report.summary(), grid,
                         in.padding.voxels >= 0 ? fmt::format("padding {}", in.padding.voxels) : "explicit dims",
                         meshSiteModeName(in.plan.meshSeedOptions(in.grid).mode), in.plan.signName(),
                         in.plan.sign_reason);
    case SeedKind::kVolume:
      return fmt::format("volume {} ({}{}, {}{})", spec.source, grid,
                         in.grid.cubic() ? ""
                                         : fmt::format(", spacing {:g},{:g},{:g}", in.grid.spacing().x,
                                                       in.grid.spacing().y, in.grid.spacing().z),
                         in.plan.labels          ? "multi-label"
                         : in.plan.signedField() ? "signed"
                                                 : "unsigned",
                         in.plan.labels && in.plan.black_border ? ", black border" : "");
    case SeedKind::kPoints: break;
  }
  return fmt::format("{} point{} in {}", spec.points.size(), spec.points.size() == 1 ? "" : "s", grid);
}

/// Step 2: reads the seeds, builds the grid, plans the field (core's planner makes every choice left open) and builds
/// the algorithm's inputs, polling `interrupter`.
Status buildSeedInput(const FieldSpec& spec, const Interrupter* interrupter, SeedInput* in) {
  FieldRequest request = spec.request;
  TriangleMesh mesh;  // a mesh's triangles, or the points as vertices (gridForMesh reads only their bounds)
  MeshReport report;
  Coord volume_dims{};
  SeedSource source;
  if (spec.seeds == SeedKind::kMesh) {
    if (Status s = loadMesh(spec.source, &mesh, &report); !s.ok()) return s;
    source.mesh = &mesh;
  } else if (spec.seeds == SeedKind::kVolume) {
    VolumeImage image;
    if (Status s = readVolumeFile(spec.source, {}, &image); !s.ok()) return s;
    in->volume = std::move(image.volume);
    in->geometry = image.geometry;
    volume_dims = in->volume.dims();
    if (std::string e = checkMaskDims(spec, volume_dims); !e.empty()) return Status::InvalidArgument(e);
    source.volume = in->volume;
  } else {
    mesh.vertices = spec.points;
    request.point_layout = pointLayout(spec.points);  // the planner's cost model
    source.points = &spec.points;
  }
  if (Status s = buildGrid(spec, mesh, volume_dims, in); !s.ok()) return s;
  const MeshReport* mesh_report = spec.seeds == SeedKind::kMesh ? &report : nullptr;
  if (Status s = planField(request, in->grid, mesh_report, &in->plan); !s.ok()) return s;
  if (Status s = buildFieldInputs(in->plan, in->grid, nullptr, source, interrupter, &in->inputs); !s.ok())
    return s.withPrefix(spec.seeds == SeedKind::kPoints ? std::string("--points") : spec.source);
  in->description = seedDescription(spec, report, *in);
  return Status::Ok();
}

std::string rangeText(int index, double lower, double upper) {
  return fmt::format("{}{:g}, {:g}]", index == 0 ? "[" : "(", lower, upper);
}

/// Step 3: the header lines: what is computed, and how.
void printHeader(const SeedInput& in, int threads, const CliContext& ctx) {
  const FieldPlan& plan = in.plan;
  ctx.out << fmt::format("distband compute: {}, voxel size {:g}, mode {}, segment {}, limit {}, threads {}\n",
                         in.description, in.grid.voxelSize(), modeName(plan.mode),
                         plan.segment_length_world > 0 ? fmt::format("{:g}", plan.segment_length_world) : "none",
                         std::isfinite(plan.limit_world) ? fmt::format("{:g}", plan.limit_world) : "none",
                         threads > 0 ? std::to_string(threads) : std::string("all"))
          << algorithmLine(plan) << "\n";
  ctx.out.flush();
}

/// What the engine's run left for the finish.
struct EngineRun {
  FieldRunResult result;
  int64_t committed_voxels = 0;  ///< voxels of the complete segments (what an interrupted run keeps)
};

/// Step 4: runs the plan, logging each segment and handing it to the outputs. Returns kExitOk or the exit code of
/// a failed run (its message already written).
int runEngine(SeedInput& in, const FieldRunOptions& options, FieldOutputs& outputs, const CliContext& ctx,
              EngineRun* run) {
  auto t_segment = Clock::now();
  auto consume = [&](SegmentBricks&& seg) {
    int64_t voxels = 0;
    for (const Brick& b : seg.bricks) voxels += b.mask.count();
    ctx.out << fmt::format("segment {:>3}  {:<18} voxels {:>11}  bricks {:>8}  {:8.3f} s\n", seg.index,
                           rangeText(seg.index, seg.lower_world, seg.upper_world), voxels, seg.bricks.size(),
                           secondsSince(t_segment));
    ctx.out.flush();
    t_segment = Clock::now();
    const bool complete = seg.complete;
    const double upper = seg.upper_world;
    outputs.add(std::move(seg));
    if (complete) outputs.commitSegment(upper);
    run->committed_voxels += voxels;
  };
  try {
    run->result = computeField(in.plan, in.grid, std::move(in.inputs), options, consume);
  } catch (const std::invalid_argument& e) {
    return usage(ctx, e.what());
  } catch (const std::exception& e) {
    ctx.err << "distband compute: the engine failed: " << e.what() << "\n";
    return kExitFailure;
  }
  return kExitOk;
}

/// Step 5: writes every file (only the complete segments when the run stopped early) and the summary.
int finish(const EngineRun& engine, FieldOutputs& outputs, const InterruptWatch& watch, Clock::time_point t_start,
           const CliContext& ctx) {
  const FieldRunResult& result = engine.result;
  RunOutcome run;
  run.complete = !result.interrupted;
  run.voxels = result.interrupted ? engine.committed_voxels : result.voxels;
  run.seconds = result.seconds;
  run.sign_shares = result.sign_shares;
  if (result.interrupted)
    return finishStoppedRun(outputs, run, watch.deadlinePassed() ? RunStop::kDeadline : RunStop::kInterrupted,
                            "compute", ctx);
  const double engine_seconds = secondsSince(t_start);
  const auto t_write = Clock::now();
  std::vector<std::string> wrote;
  const std::string error = outputs.finish(run, &wrote);
  for (const std::string& line : wrote) ctx.out << line << "\n";
  if (!error.empty()) {
    ctx.err << "distband compute: " << error << "\n";
    return kExitFailure;
  }
  ctx.out << fmt::format(
      "done: {} voxels in {} segment{}, {} steps, {} updates, {} corrections, {} bricks allocated; engine {:.3f} s, "
      "total {:.3f} s (write {:.3f} s)\n",
      result.voxels, result.segments.size(), result.segments.size() == 1 ? "" : "s", result.steps, result.updates,
      result.corrections, result.bricks_allocated, result.seconds, engine_seconds + secondsSince(t_write),
      secondsSince(t_write));
  if (result.sign_shares.total() > 0) ctx.out << "sign: " << describeSignShares(result.sign_shares) << "\n";
  return kExitOk;
}

}  // namespace

int runCompute(const ComputeArgs& a, const CliContext& ctx) {
  const auto t_start = Clock::now();
  ComputeSetup setup;
  if (std::string e = checkComputeFlags(a, &setup); !e.empty()) return usage(ctx, e);
  if (Status s = loadSeedPoints(&setup.spec, nullptr); !s.ok()) return usage(ctx, s.message());
  const FieldSpec& spec = setup.spec;
  // --threads bounds the whole command (mesh validation, seeds, VDB assembly), not only the engine's arena.
  std::optional<tbb::global_control> parallelism;
  if (a.threads > 0) parallelism.emplace(tbb::global_control::max_allowed_parallelism, size_t(a.threads));

  InterruptWatch watch(ctx.interrupted, spec.deadline(t_start));
  SeedInput in;
  if (Status s = buildSeedInput(spec, &watch.interrupter(), &in); !s.ok()) {
    if (s.code() == Status::Code::kDeadlineExceeded) {
      ctx.err << "distband compute: the deadline (--deadline) passed before the first segment; nothing written\n";
      return kExitFailure;
    }
    if (s.code() != Status::Code::kCancelled) return usage(ctx, s.message());
    ctx.err << "distband compute: interrupted; nothing written\n";
    return kExitInterrupted;
  }
  FieldRunOptions options = in.plan.runOptions();
  options.threads = a.threads;
  if (Status s = validateRunOptions(in.grid, options); !s.ok()) return usage(ctx, s.message());
  if (in.padding.band_clipped)
    ctx.err << "distband compute: "
            << clippedBandWarning(in.padding.voxels, in.plan.limitVoxels(in.grid), spec.grid.padding.has_value())
            << "\n";
  FieldOutputs outputs(setup.outputs);
  const std::string title = std::filesystem::path(spec.source).filename().string();
  FieldDescription description = describeField(in.plan, in.grid, in.padding, title, in.volume);
  if (in.geometry.from_header) description.affine = volumeAffine(in.geometry);
  if (std::string e = outputs.open(description); !e.empty()) return usage(ctx, e);
  printHeader(in, a.threads, ctx);

  options.interrupter = &watch.interrupter();
  EngineRun engine;
  if (int code = runEngine(in, options, outputs, ctx, &engine); code != kExitOk) return code;
  return finish(engine, outputs, watch, t_start, ctx);
}

CliCommand registerComputeCommand(CLI::App& app, const CliContext& context) {
  auto args = std::make_shared<ComputeArgs>();
  CLI::App* cmd = app.add_subcommand("compute", "Compute a distance field in-process and write it to a file");
  addFieldFlags(cmd, &args->field, AssetSeeds::kNo);
  cmd->add_option("--threads", args->threads, "Worker threads for the whole command (0: all cores)")->default_val(0);
  addOutputFlags(cmd, &args->outputs);
  return {cmd, [args, &context] { return runCompute(*args, context); }};
}

}  // namespace distband

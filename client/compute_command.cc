#include "client/compute_command.h"
#include "client/interrupt_watch.h"

#include <charconv>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <optional>

#include <fmt/format.h>
#include <tbb/global_control.h>

#include "client/brick_sink.h"
#include "core/band/band_engine.h"
#include "core/field/field_plan.h"
#include "core/field/compute_field.h"
#include "core/io/field_metadata.h"
#include "core/io/npy.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/mesh_seeds.h"

namespace distband {
namespace {

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

std::vector<std::string_view> split(std::string_view s, char sep) {
  std::vector<std::string_view> parts;
  size_t start = 0;
  for (;;) {
    const size_t at = s.find(sep, start);
    parts.push_back(s.substr(start, at == std::string_view::npos ? std::string_view::npos : at - start));
    if (at == std::string_view::npos) return parts;
    start = at + 1;
  }
}

bool parseDouble(std::string_view s, double* out) {
  s = trim(s);
  if (s.empty()) return false;
  if (s.front() == '+') s.remove_prefix(1);
  const auto r = std::from_chars(s.data(), s.data() + s.size(), *out);
  return r.ec == std::errc() && r.ptr == s.data() + s.size() && std::isfinite(*out);
}

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// The grid, the plan and the algorithm's inputs, built from the command's input flags.
struct SeedInput {
  Grid grid;
  FieldInputs inputs;
  std::shared_ptr<const std::vector<uint8_t>> mask;  ///< volume input only
  bool signed_distance = false;
  bool mesh = false;
  std::string description;
  FieldPlan plan;                  ///< every choice made (core's planner), once the grid is known
  GridPadding padding{-1, false};  ///< meshes: the padding used (-1: explicit dims)
};

Status buildMeshInput(const ComputeArgs& a, const FieldRequest& field, const Interrupter* interrupter,
                      SeedInput* in) {
  auto usage = [](std::string m) { return Status::InvalidArgument(std::move(m)); };
  if (!a.dims.empty()) return usage("--dims does not apply to --mesh (use --resolution or --voxel-size)");
  if ((a.resolution_given || a.resolution != 0) && a.resolution < 2)
    return usage(fmt::format("--resolution must be at least 2 voxels (got {})", a.resolution));
  if ((a.resolution > 0) == a.voxel_size_given) return usage("--mesh needs exactly one of --resolution N or --voxel-size H");
  if (a.padding < -1 || a.padding > kMaxPaddingVoxels)
    return usage(fmt::format("--padding must be in [0, {}] voxels (got {})", kMaxPaddingVoxels, a.padding));
  TriangleMesh mesh;
  MeshReport report;
  if (Status s = loadMesh(a.mesh, &mesh, &report); !s.ok()) return s;
  MeshGridOptions go;
  go.resolution = a.resolution;
  go.voxel_size = a.voxel_size_given ? a.voxel_size : 0;
  if (a.padding >= 0) go.padding_voxels = a.padding;
  if (Status s = gridForMesh(mesh, go, field.limit(), &in->grid, &in->padding); !s.ok()) return s;
  if (Status s = planField(field, in->grid, &report, &in->plan); !s.ok()) return s;
  SeedSource source;
  source.mesh = &mesh;
  if (Status s = buildFieldInputs(in->plan, in->grid, nullptr, source, interrupter, &in->inputs); !s.ok())
    return s.withPrefix(a.mesh);
  in->signed_distance = in->plan.signedField();
  in->mesh = true;
  const Coord d = in->grid.dims();
  in->description = fmt::format("mesh {} ({}; grid {}x{}x{}, padding {}, sites {}, sign {} ({}))", a.mesh,
                                report.summary(), d.x, d.y, d.z, in->padding.voxels,
                                meshSiteModeName(in->plan.meshSeedOptions(in->grid).mode), in->plan.signName(),
                                in->plan.sign_reason);
  return Status::Ok();
}

Status buildSeedInput(const ComputeArgs& a, const FieldRequest& field, const Interrupter* interrupter,
                      SeedInput* in) {
  auto usage = [](std::string m) { return Status::InvalidArgument(std::move(m)); };
  const int sources = int(!a.volume.empty()) + int(!a.points.empty()) + int(!a.mesh.empty());
  if (sources != 1)
    return usage("give exactly one seed source: --volume MASK.npy, --points \"x,y,z;...\" or --mesh FILE");
  if (a.signed_distance && a.volume.empty()) return usage("--signed needs --volume (meshes take --sign)");
  if (!(std::isfinite(a.voxel_size) && a.voxel_size > 0))
    return usage(fmt::format("--voxel-size must be finite and > 0 (got {})", a.voxel_size));
  if (!a.mesh.empty()) return buildMeshInput(a, field, interrupter, in);
  if (a.resolution != 0) return usage("--resolution applies to --mesh only");
  in->signed_distance = a.signed_distance;
  Vec3d origin;
  if (std::string e = parseVec3(a.origin, "--origin", &origin); !e.empty()) return usage(e);
  const double voxel_size = a.voxel_size;
  Coord dims{};
  const bool have_dims = !a.dims.empty();
  if (have_dims)
    if (std::string e = parseDims(a.dims, &dims); !e.empty()) return usage(e);
  SeedSource source;
  std::vector<Vec3d> points;
  FieldRequest request = field;
  if (!a.volume.empty()) {
    auto mask = std::make_shared<std::vector<uint8_t>>();
    Coord mask_dims;
    if (Status s = readNpyMask(a.volume, mask.get(), &mask_dims); !s.ok()) return s;
    if (have_dims && !(dims == mask_dims))
      return usage(fmt::format("--dims {}x{}x{} disagrees with {} of shape (Z, Y, X) = ({}, {}, {})", dims.x, dims.y,
                               dims.z, a.volume, mask_dims.z, mask_dims.y, mask_dims.x));
    dims = mask_dims;
    source.mask = in->mask = mask;
    in->description = fmt::format("volume {} ({}x{}x{}, {})", a.volume, mask_dims.x, mask_dims.y, mask_dims.z,
                                  a.signed_distance ? "signed" : "unsigned");
  } else {
    if (!have_dims) return usage("--points needs --dims X,Y,Z");
    if (std::string e = parsePointList(a.points, &points); !e.empty()) return usage(e);
    request.point_layout = pointLayout(points);  // the planner's cost model
    source.points = &points;
    in->description = fmt::format("{} point{} in {}x{}x{}", points.size(), points.size() == 1 ? "" : "s", dims.x,
                                  dims.y, dims.z);
  }
  in->grid = Grid(origin, voxel_size, dims);
  if (Status s = in->grid.validate(); !s.ok()) return s;
  if (Status s = planField(request, in->grid, nullptr, &in->plan); !s.ok()) return s;
  if (Status s = buildFieldInputs(in->plan, in->grid, nullptr, source, interrupter, &in->inputs); !s.ok())
    return s.withPrefix(a.volume.empty() ? std::string("--points") : a.volume);
  return Status::Ok();
}

std::string rangeText(int index, double lower, double upper) {
  return fmt::format("{}{:g}, {:g}]", index == 0 ? "[" : "(", lower, upper);
}

}  // namespace

std::string parseVec3(std::string_view text, std::string_view flag, Vec3d* out) {
  const std::vector<std::string_view> parts = split(text, ',');
  double v[3];
  if (parts.size() != 3) return fmt::format("{} '{}': expected three comma-separated numbers x,y,z", flag, text);
  for (int i = 0; i < 3; ++i)
    if (!parseDouble(parts[i], &v[i]))
      return fmt::format("{} '{}': '{}' is not a finite number", flag, text, trim(parts[i]));
  *out = {v[0], v[1], v[2]};
  return {};
}

std::string parseDims(std::string_view text, Coord* out) {
  const std::vector<std::string_view> parts = split(text, ',');
  if (parts.size() != 3) return fmt::format("--dims '{}': expected three comma-separated integers X,Y,Z", text);
  int v[3];
  for (int i = 0; i < 3; ++i) {
    const std::string_view p = trim(parts[i]);
    const auto r = std::from_chars(p.data(), p.data() + p.size(), v[i]);
    if (p.empty() || r.ec != std::errc() || r.ptr != p.data() + p.size())
      return fmt::format("--dims '{}': '{}' is not an integer", text, p);
    if (v[i] < 1 || v[i] > kMaxGridDim)
      return fmt::format("--dims '{}': every extent must be in [1, {}]", text, kMaxGridDim);
  }
  *out = {v[0], v[1], v[2]};
  return {};
}

std::string parsePointList(std::string_view text, std::vector<Vec3d>* out) {
  std::vector<Vec3d> points;
  int n = 0;
  for (std::string_view item : split(text, ';')) {
    ++n;
    if (trim(item).empty()) continue;  // allows a trailing ';'
    Vec3d p;
    if (std::string e = parseVec3(item, fmt::format("--points (point {})", n), &p); !e.empty()) return e;
    points.push_back(p);
  }
  if (points.empty()) return "--points: no point given (expected \"x,y,z;x,y,z;...\")";
  *out = std::move(points);
  return {};
}

int runCompute(const ComputeArgs& a, const CliContext& ctx) {
  const auto t_start = Clock::now();
  auto usage = [&](const std::string& msg) {
    ctx.err << "distband compute: " << msg << "\n";
    return kExitUsage;
  };

  // What the flags ask for; core's planner (planField) makes every choice left open, once the grid is known.
  FieldRequest field;
  field.seeds = !a.mesh.empty() ? SeedKind::kMesh : !a.volume.empty() ? SeedKind::kVolume : SeedKind::kPoints;
  if (a.stencil != "auto") {
    field.stencil = parseStencil(a.stencil);
    if (!field.stencil)
      return usage(fmt::format("--stencil '{}': expected auto, cubic26, cubic18, cubic6 or fcc12", a.stencil));
  }
  // Meshes: exact-feature (alias exact) propagates closest triangles to convergence; paper propagates closest points
  // with the paper's lifespan band.
  PropagationMode mode;
  if (field.seeds == SeedKind::kMesh && a.mode == "exact-feature") mode = PropagationMode::kExact;
  else if (!parseMode(a.mode, &mode))
    return usage(field.seeds == SeedKind::kMesh
                     ? fmt::format("--mode '{}': expected exact-feature (or exact) or paper for a mesh", a.mode)
                     : fmt::format("--mode '{}': expected exact or paper", a.mode));
  field.mode = mode;
  if (field.seeds == SeedKind::kMesh) {
    SignMethod sign;
    if (!parseSignMethod(a.sign, &sign))
      return usage(fmt::format("--sign '{}': expected auto, pseudonormal, winding, parity or unsigned", a.sign));
    field.mesh_sign = sign;
    // The second-ring correction costs several times the propagation on triangle sites for ~0.01 voxel: opt-in.
    if (a.second_ring) field.second_ring = true;
  }
  field.inside_negative = a.signed_distance;
  if (std::isnan(a.limit) || a.limit <= 0) return usage(fmt::format("--limit must be > 0 (got {})", a.limit));
  if (a.limit_voxels != 0 && !(a.limit_voxels > 0 && std::isfinite(a.limit_voxels)))
    return usage(fmt::format("--limit-voxels must be finite and > 0 (got {})", a.limit_voxels));
  if (!(a.segment >= 0) || std::isinf(a.segment))
    return usage(fmt::format("--segment must be finite and >= 0 (got {})", a.segment));
  if (a.threads < 0) return usage(fmt::format("--threads must be >= 0 (got {})", a.threads));
  // --threads bounds the whole command (mesh validation, seeds, VDB assembly), not only the engine's arena.
  std::optional<tbb::global_control> parallelism;
  if (a.threads > 0) parallelism.emplace(tbb::global_control::max_allowed_parallelism, size_t(a.threads));
  field.limit_world = a.limit;
  field.limit_voxels = a.limit_voxels;
  field.segment_length_world = a.segment;
  field.closest_features = !a.outputs.closest.empty();

  OutputPlan plan;
  const double limit_flag = a.limit_voxels > 0 ? std::numeric_limits<double>::quiet_NaN() : a.limit;
  if (std::string e = checkOutputFlags(a.outputs, limit_flag, &plan); !e.empty()) return usage(e);

  InterruptWatch watch(ctx.interrupted);
  SeedInput in;
  if (Status s = buildSeedInput(a, field, &watch.interrupter(), &in); !s.ok()) {
    if (s.code() == Status::Code::kCancelled) {
      ctx.err << "distband compute: interrupted; nothing written\n";
      return kExitInterrupted;
    }
    return usage(s.message());
  }
  const double limit = in.plan.limit_world;  // world units, whichever unit the flag used
  FieldRunOptions options = in.plan.runOptions();
  options.threads = a.threads;
  if (Status s = validateRunOptions(in.grid, options); !s.ok()) return usage(s.message());
  if (in.padding.band_clipped)
    ctx.err << "distband compute: " << clippedBandWarning(in.padding.voxels, limit / in.grid.voxelSize(), a.padding >= 0)
            << "\n";

  const StencilKind stencil = in.plan.stencil;
  FieldDescription description;
  description.grid = in.grid;
  description.limit_world = limit;
  description.signed_distance = in.signed_distance;
  description.inside = in.mask;
  description.sign_from_band = in.mesh && in.signed_distance;
  description.stencil = std::string(stencilName(stencil));
  description.mode = std::string(modeName(in.plan.mode));
  if (in.signed_distance) description.sign = std::string(in.plan.signName());
  description.sign_reason = in.plan.sign_reason;
  description.padding_voxels = in.padding.voxels;
  description.band_clipped = in.padding.band_clipped;
  description.segment_length_world = a.segment;
  description.closest_feature = std::string(in.plan.closestFeatureName());
  description.title = std::filesystem::path(!a.mesh.empty() ? a.mesh : a.volume).filename().string();
  FieldOutputs outputs(plan);
  if (std::string e = outputs.open(description); !e.empty()) return usage(e);

  ctx.out << fmt::format("distband compute: {}, voxel size {:g}, {}, mode {}, segment {}, limit {}, threads {}\n",
                         in.description, in.grid.voxelSize(),
                         in.plan.algorithm == FieldAlgorithm::kSeparable
                             ? std::string(in.plan.seeds == SeedKind::kPoints
                                               ? "algorithm separable (exact point EDT over the whole grid)"
                                           : std::isfinite(limit)
                                               ? "algorithm separable (exact EDT over the bricks within the limit)"
                                               : "algorithm separable (exact EDT over the whole grid)")
                             : fmt::format("stencil {}", stencilName(stencil)),
                         modeName(in.plan.mode),
                         a.segment > 0 ? fmt::format("{:g}", a.segment) : std::string("none"),
                         std::isfinite(limit) ? fmt::format("{:g}", limit) : std::string("none"),
                         a.threads > 0 ? std::to_string(a.threads) : std::string("all"));
  ctx.out.flush();

  options.interrupter = &watch.interrupter();
  auto t_segment = Clock::now();
  int64_t committed_voxels = 0;
  FieldRunResult result;
  try {
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
      committed_voxels += voxels;
    };
    result = computeField(in.plan, in.grid, std::move(in.inputs), options, consume);
  } catch (const std::invalid_argument& e) {
    return usage(e.what());
  } catch (const std::exception& e) {
    ctx.err << "distband compute: the engine failed: " << e.what() << "\n";
    return kExitFailure;
  }
  const double engine_seconds = secondsSince(t_start);
  const auto t_write = Clock::now();
  RunOutcome run;
  run.complete = !result.interrupted;
  run.voxels = result.interrupted ? committed_voxels : result.voxels;
  run.seconds = result.seconds;
  std::vector<std::string> wrote;
  const std::string error = outputs.finish(run, &wrote);
  for (const std::string& line : wrote) ctx.out << line << "\n";
  if (result.interrupted) {
    ctx.err << "distband compute: interrupted; " << (error.empty() ? outputs.keptSummary() : error) << "\n";
    return kExitInterrupted;
  }
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
  return kExitOk;
}

CliCommand registerComputeCommand(CLI::App& app, const CliContext& context) {
  auto args = std::make_shared<ComputeArgs>();
  CLI::App* cmd = app.add_subcommand("compute", "Compute a distance field in-process and write it to a file");
  auto* volume = cmd->add_option("--volume", args->volume, "Seed mask: .npy uint8/bool, shape (Z, Y, X); nonzero = seed");
  auto* sgn = cmd->add_flag("--signed", args->signed_distance, "Signed distance to the mask boundary (negative inside)");
  auto* points = cmd->add_option("--points", args->points, "Seed points in world coordinates: \"x,y,z;x,y,z\"");
  volume->excludes(points);
  sgn->needs(volume);
  cmd->add_option("--dims", args->dims, "Grid dims X,Y,Z (required with --points; taken from the mask otherwise)");
  auto* mesh = cmd->add_option("--mesh", args->mesh, "Triangle mesh (OBJ, OFF, PLY, STL): signed distance to it");
  mesh->excludes(volume);
  mesh->excludes(points);
  cmd->add_option("--resolution", args->resolution, "Mesh: voxels along the longest side of the padded box (N^3)");
  cmd->add_option("--padding", args->padding,
                  "Mesh: margin around the mesh in voxels (default: at least 3 and at least the limit)");
  cmd->add_option("--sign", args->sign,
                  "Mesh: auto (pseudonormal for a closed mesh, winding for an open one) | pseudonormal | winding | "
                  "parity | unsigned")
      ->default_val("auto");
  cmd->add_flag("--second-ring", args->second_ring, "Mesh: also run the engine's second-ring correction (slower)");
  cmd->add_option("--voxel-size", args->voxel_size, "Voxel size in world units (default 1; meshes: or --resolution)")
      ->default_val(1.0);
  cmd->add_option("--origin", args->origin, "World position of voxel (0,0,0): x,y,z")->default_val("0,0,0");
  cmd->add_option("--stencil", args->stencil,
                  "auto (fcc12 for meshes in exact-feature mode, else cubic26) | cubic26 | cubic18 | cubic6 | fcc12")
      ->default_val("auto");
  cmd->add_option("--mode", args->mode,
                  "exact (default) | paper (the SMI 2009 lifespan method); meshes: exact-feature | paper")
      ->default_val("exact");
  cmd->add_option("--segment", args->segment, "Segment length in world units (0: one segment)")->default_val(0);
  CLI::Option* limit = cmd->add_option("--limit", args->limit, "Distance limit in world units (default: none)");
  cmd->add_option("--limit-voxels", args->limit_voxels, "Distance limit in voxels of the grid (instead of --limit)")
      ->excludes(limit);
  cmd->add_option("--threads", args->threads, "Worker threads (0: all cores)")->default_val(0);
  addOutputFlags(cmd, &args->outputs);
  return {cmd, [args, &context, cmd]() {
            args->voxel_size_given = cmd->count("--voxel-size") > 0;
            args->resolution_given = cmd->count("--resolution") > 0;
            return runCompute(*args, context);
          }};
}

}  // namespace distband

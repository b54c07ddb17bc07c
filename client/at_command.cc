#include "client/at_command.h"

#include <chrono>
#include <cmath>
#include <optional>

#include <fmt/format.h>
#include <tbb/global_control.h>

#include "client/interrupt_watch.h"
#include "core/mesh/triangle_mesh.h"
#include "core/points/point_plan.h"

namespace distband {
namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

int usage(const CliContext& ctx, const std::string& message) {
  ctx.err << "distband at: " << message << "\n";
  return kExitUsage;
}

/// How a stopped run ends: nothing is written.
int stopped(const InterruptWatch& watch, const CliContext& ctx) {
  if (watch.deadlinePassed()) {
    ctx.err << "distband at: the deadline (--deadline) passed; nothing written\n";
    return kExitFailure;
  }
  ctx.err << "distband at: interrupted; nothing written\n";
  return kExitInterrupted;
}

int runInProcess(const AtArgs& a, const CliContext& ctx) {
  const auto t_start = Clock::now();
  AtSetup setup;
  if (std::string e = checkAtFlags(a, false, &setup); !e.empty()) return usage(ctx, e);
  FieldSpec& spec = setup.spec;
  std::optional<tbb::global_control> parallelism;
  if (a.threads > 0) parallelism.emplace(tbb::global_control::max_allowed_parallelism, size_t(a.threads));
  InterruptWatch watch(ctx.interrupted, spec.deadline(t_start));
  const Interrupter* interrupter = &watch.interrupter();

  // The seeds, the plan (core decides what the flags leave open) and the search they imply.
  if (Status s = loadSeedPoints(&spec, interrupter); !s.ok()) return usage(ctx, s.message());
  TriangleMesh mesh;
  MeshReport report;
  PointSeedSource source;
  std::string seeds;
  if (spec.seeds == SeedKind::kMesh) {
    if (Status s = loadMesh(spec.source, &mesh, &report); !s.ok()) return usage(ctx, s.message());
    source.mesh = &mesh;
    seeds = fmt::format("mesh {} ({})", spec.source, report.summary());
  } else if (spec.seeds == SeedKind::kVolume) {
    VolumeImage image;
    if (Status s = readVolumeFile(spec.source, {}, &image); !s.ok()) return usage(ctx, s.message());
    const Coord dims = image.volume.dims();
    if (std::string e = checkMaskDims(spec, dims); !e.empty()) return usage(ctx, e);
    const VolumeGeometry geometry = overrideGeometry(image.geometry, spec.grid.spacing, spec.grid.origin_given);
    double h = 0;
    if (std::string e = cubicVolumeLattice(geometry, spec.source, &h); !e.empty()) return usage(ctx, e);
    source.mask = image.volume.seedMask();
    source.lattice = Grid(geometry.origin, h, dims);
    seeds = fmt::format("volume {} ({}x{}x{}, voxel size {:g}, origin ({:g}, {:g}, {:g}))", spec.source, dims.x, dims.y,
                        dims.z, h, geometry.origin.x, geometry.origin.y, geometry.origin.z);
  } else {
    source.points = &spec.points;
    seeds = fmt::format("{} seed point{}", spec.points.size(), spec.points.size() == 1 ? "" : "s");
  }
  PointPlan plan;
  if (Status s = planPoints(spec.request, spec.seeds == SeedKind::kMesh ? &report : nullptr,
                            spec.seeds == SeedKind::kVolume ? &source.lattice : nullptr, &plan);
      !s.ok())
    return usage(ctx, s.message());
  const auto t_search = Clock::now();
  PointSearch search;
  if (Status s = completePointSearch(plan, source, interrupter, &search); !s.ok()) {
    if (interrupter->interrupted()) return stopped(watch, ctx);
    return usage(ctx, s.message());
  }
  const std::optional<uint64_t> count = setup.points->declaredCount();
  ctx.out << fmt::format("distband at: {}; query points {} ({}{}); limit {}; threads {}\n", seeds, a.at,
                         count ? fmt::format("{} points, ", *count) : "", setup.packing.doubles ? "float64" : "float32",
                         std::isfinite(plan.limit_world) ? fmt::format("{:g}", plan.limit_world) : "none",
                         a.threads > 0 ? std::to_string(a.threads) : std::string("all"))
          << fmt::format("sign: {} ({}); search built in {:.3f} s\n", plan.signName(), plan.sign_reason,
                         secondsSince(t_search));
  ctx.out.flush();

  // The chunks: read, searched, packed and appended in the query file's order.
  PointFileOutputs outputs;
  if (Status s = outputs.open(a.outputs, setup.packing); !s.ok()) {
    ctx.err << "distband at: " << s.message() << "\n";
    return kExitFailure;
  }
  const PointOutputs wanted = pointOutputsOf(a.outputs);
  const auto t_compute = Clock::now();
  std::vector<Vec3d> chunk;
  PointResultBuffer results;
  std::string packed[4];
  for (;;) {
    chunk.clear();
    if (Status s = setup.points->next(size_t(a.chunk_points), &chunk); !s.ok()) return usage(ctx, s.message());
    if (chunk.empty()) break;
    results.resize(chunk.size(), wanted);
    if (Status s = queryPoints(search, chunk.data(), chunk.size(), plan.queryOptions(interrupter), results.results());
        !s.ok()) {
      if (interrupter->interrupted()) return stopped(watch, ctx);
      return usage(ctx, fmt::format("--at {}: {}", a.at, s.message()));
    }
    results.packDistance(setup.packing, &packed[0]);
    results.packClosestPoints(setup.packing, &packed[1]);
    results.packFeatures(setup.packing, &packed[2]);
    results.packGradients(setup.packing, &packed[3]);
    if (Status s = outputs.append(chunk.size(), packed[0], packed[1], packed[2], packed[3]); !s.ok()) {
      ctx.err << "distband at: " << s.message() << "\n";
      return kExitFailure;
    }
  }
  if (interrupter->interrupted()) return stopped(watch, ctx);
  const double compute_seconds = secondsSince(t_compute);
  std::vector<std::string> lines;
  if (Status s = outputs.finish(&lines); !s.ok()) {
    ctx.err << "distband at: " << s.message() << "\n";
    return kExitFailure;
  }
  for (const std::string& line : lines) ctx.out << line << "\n";
  ctx.out << fmt::format("done: {} points in {:.3f} s ({:.3g} points/s); total {:.3f} s\n", outputs.rows(),
                         compute_seconds, compute_seconds > 0 ? double(outputs.rows()) / compute_seconds : 0.0,
                         secondsSince(t_start));
  return kExitOk;
}

}  // namespace

std::string cubicVolumeLattice(const VolumeGeometry& geometry, const std::string& source, double* h) {
  const Vec3d& s = geometry.spacing;
  if (!(s.x == s.y && s.y == s.z))
    return fmt::format(
        "--volume {}: its spacing ({:g}, {:g}, {:g}) is anisotropic; `distband at` takes cubic voxels only (give "
        "--voxel-size H to place them on a cubic lattice; compute and query take any spacing)",
        source, s.x, s.y, s.z);
  if (geometry.reoriented)
    return fmt::format(
        "--volume {}: its header's axes are flipped or permuted against the array's; `distband at` places voxel "
        "(i, j, k) at origin + h * (i, j, k) only (compute and query take such files)",
        source);
  *h = s.x;
  return {};
}

std::string checkAtFlags(const AtArgs& a, bool remote, AtSetup* setup) {
  AtSetup s;
  if (std::string e = parsePointQueryFlags(a.field, &s.spec); !e.empty()) return e;
  if (s.spec.asset && !remote) return "--asset names an asset a server holds: give --server too";
  if (a.threads < 0) return fmt::format("--threads must be >= 0 (got {})", a.threads);
  if (remote && a.threads > 0) return "--threads applies in-process; a server computes on its own threads";
  if (a.chunk_points < 1 || size_t(a.chunk_points) > kMaxChunkPoints)
    return fmt::format("--chunk-points must be in [1, {}] (got {})", kMaxChunkPoints, a.chunk_points);
  if (std::string e = checkPointOutputFlags(a.outputs); !e.empty()) return e;
  if (a.at.empty()) return "--at QUERY: the points to evaluate the field at (.npy, .xyz, .txt or .ply) is required";
  PointFileFormat format;
  if (!pointFileFormatFromPath(a.at, &format))
    return fmt::format("--at {}: unknown point file format (expected .npy, .xyz, .txt or .ply)", a.at);
  if (Status st = PointCloudReader::fromFile(a.at, format, {}, &s.points); !st.ok()) return "--at: " + st.message();
  s.packing.doubles = s.points->doublePrecision();
  s.packing.wide_ids = s.spec.seeds == SeedKind::kVolume;
  *setup = std::move(s);
  return {};
}

CliCommand registerAtCommand(CLI::App& app, const CliContext& context, AtRemote remote) {
  auto args = std::make_shared<AtArgs>();
  CLI::App* cmd = app.add_subcommand("at", "The distance field at arbitrary points (in-process, or --server)");
  addPointQueryFlags(cmd, &args->field, AssetSeeds::kYes);
  cmd->add_option("--at", args->at,
                  "Query points: .npy (N x 3 float32/float64), .xyz/.txt (x y z a line) or .ply (its vertices)");
  addPointOutputFlags(cmd, &args->outputs);
  cmd->add_option("--chunk-points", args->chunk_points, "Points read, computed and written at once")
      ->capture_default_str();
  cmd->add_option("--threads", args->threads, "In-process: worker threads (0: all cores)")->default_val(0);
  if (remote.add_flags) remote.add_flags(cmd);
  return {cmd, [args, &context, cmd, remote] {
            if (cmd->get_option_no_throw("--server") && cmd->count("--server") > 0) return remote.run(*args, context);
            return runInProcess(*args, context);
          }};
}

}  // namespace distband

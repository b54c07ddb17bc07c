// mesh_bench: the SMI 2009 paper's Table 1 mesh rows (paper vs exact-feature modes, with and without segments),
// its Fig. 6 (time per distance range) and Fig. 7 (l_seg sweep), and, in the same run, OpenVDB's
// tools::meshToSignedDistanceField on the same mesh, transform and band.
//
// Contract:
//   * Default (no --case): runs the suites named by --suite (table1, openvdb, fig7, memory; default all but
//     memory) in this process with one TBB thread budget (--threads, via tbb::global_control; the engine also
//     runs in a task_arena of that size), and writes <out-dir>/<tag>.json and <tag>.md.
//   * Every distband run is a FieldRequest (site mode, limit, --stencil, --second-ring) planned as `distband compute
//     --mesh` plans it (bench/planned_field.h: gridForMesh with the request's limit, planField) and run through
//     buildFieldInputs and computeField. The OpenVDB comparison and the memory case size the grid by the voxel size
//     the planner gives --openvdb-res / --memory-res without a limit, and OpenVDB runs on distband's planned
//     transform. --feature-engine paper runs triangle sites with the paper's lifespan, a pairing no request
//     expresses: enginePlan() edits the plan for it, the one place this bench does.
//   * Timed region, distband: the inputs (mesh seeds, sign included) + computeField. In the openvdb suite the timed
//     region also assembles the delivered bricks into a level-set tree of OpenVDB's shape (VdbFieldBuilder + signed
//     flood fill), the product OpenVDB's call returns; the engine-only time is reported beside it.
//     Timed region, OpenVDB: meshToSignedDistanceField (float points and indices prepared before the clock).
//   * Errors are in voxels against brute force (tests/support/brute_mesh via bench/mesh_oracle.h: exact
//     point–triangle distance over all triangles, sign from the exact generalized winding number), on --samples
//     voxels: for table1 drawn uniformly from the whole grid, for openvdb uniformly from the band distband delivered
//     (OpenVDB's value at the same voxel; voxels OpenVDB left inactive are counted as missing, not as errors).
//   * Pass: every distband run within its plan's documented bound (bench/mesh_oracle.h: exact-feature cubic26 0.05,
//     other stencils 0.15, paper mode 0.2 voxel), no sign error on a closed mesh, every sample delivered (paper mode
//     in the openvdb suite: at most 5 % of the exact band's samples beyond its limit), fig7's runs deliver the whole
//     grid; else each failure is printed (run, grid, first bad voxel) and the exit status is 1. OpenVDB's errors
//     are reported, not judged.
//   * --case memory-distband | memory-distband-discard | memory-seeds | memory-openvdb: one memory row (default
//     armadillo at 1024^3, half-width 3) in this process, one JSON line on stdout; the memory suite runs them as
//     child processes under /usr/bin/time -v and reads their "Maximum resident set size".
//   * --smoke: table1 and openvdb on the bunny, the fandisk and the teapot at 32^3 and 48^3 (the CTest run).
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <openvdb/openvdb.h>
#include <openvdb/tools/MeshToVolume.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include "core/field/field_plan.h"
#include "core/io/vdb_writer.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "tests/support/brute_mesh.h"

#include "bench/bench_util.h"
#include "bench/mesh_oracle.h"
#include "bench/planned_field.h"

namespace distband {
namespace {

using json = nlohmann::json;
using bench::Clock;
using bench::since;

using bench::peakRssMb;
constexpr double kInf = std::numeric_limits<double>::infinity();

struct Options {
  std::string mesh_dir = "/work/shared/data/meshes";
  std::string out_dir = DISTBAND_BENCH_DIR "/results";
  std::string tag = "mesh_bench";
  std::vector<std::string> suites = {"table1", "openvdb", "fig7"};
  std::vector<std::string> table1_meshes = {"fandisk.off", "bunny.obj", "armadillo.off", "teapot.obj"};
  std::vector<std::string> openvdb_meshes = {"armadillo.off", "bunny.obj", "fandisk.off", "teapot.obj"};
  std::vector<int> resolutions = {64, 128, 256};
  int openvdb_resolution = 256;
  std::vector<int> half_widths = {3, 20, 60};
  int threads = 2;
  int samples = 2000;
  int reps = 3;  ///< timed runs of distband and OpenVDB per openvdb-suite row (medians compared)
  int padding = -1;  ///< -1: the planner's default (gridForMesh)
  double segment = 20;
  std::string stencil = "auto";  ///< auto: the engine's default for the sites (fcc12 exact-feature, cubic26 paper)
  std::string run_case;
  PropagationMode feature_engine = PropagationMode::kExact;  ///< engine mode of the exact-feature rows
  bool second_ring = false;  ///< exact-feature rows: force the engine's second-ring correction on (default: off)
  std::string memory_mesh = "armadillo.off";
  int memory_resolution = 1024;
  int memory_half_width = 3;
};

struct MeshInput {
  std::string name;
  TriangleMesh mesh;
  MeshReport report;
};

MeshInput loadInput(const Options& o, const std::string& file) {
  MeshInput in;
  in.name = std::filesystem::path(file).stem().string();
  if (Status e = loadMesh(o.mesh_dir + "/" + file, &in.mesh, &in.report); !e.ok()) throw std::runtime_error(e.toString());
  return in;
}

/// The request of one distband run: its site mode (paper: closest points; exact-feature: triangles), limit and the
/// bench's stencil and second-ring knobs; everything else is the planner's.
FieldRequest meshRequest(MeshSiteMode mode, double limit_vox, const Options& o) {
  FieldRequest request;
  request.seeds = SeedKind::kMesh;
  request.mode = mode == MeshSiteMode::kPaper ? PropagationMode::kPaper : PropagationMode::kExact;
  if (o.stencil != "auto") request.stencil = *parseStencil(o.stencil);
  if (std::isfinite(limit_vox)) request.limit_voxels = limit_vox;
  if (o.second_ring) request.second_ring = true;  // otherwise the engine's default for triangle sites (off)
  return request;
}

/// Plans `request` on the mesh (gridForMesh with the request's limit, then planField), the segment length given in
/// voxels of the planned grid (the grid does not depend on it).
bench::PlannedField planMesh(const MeshInput& in, FieldRequest request, const MeshGridOptions& go, double segment_vox) {
  bench::PlannedField p;
  if (Status e = bench::planMeshField(request, in.mesh, in.report, go, &p); !e.ok())
    throw std::runtime_error(e.toString());
  if (segment_vox > 0) {
    request.segment_length_world = segment_vox * p.grid.voxelSize();
    if (Status e = bench::planMeshField(request, in.mesh, in.report, go, &p); !e.ok())
      throw std::runtime_error(e.toString());
  }
  return p;
}

/// Grid options sizing by resolution (with --padding when given, else the planner's padding).
MeshGridOptions byResolution(int resolution, const Options& o) {
  MeshGridOptions go;
  go.resolution = resolution;
  if (o.padding >= 0) go.padding_voxels = o.padding;
  return go;
}

/// The voxel size the planner gives a mesh at `resolution` without a limit: the OpenVDB comparison and the memory
/// case keep it for every half-width (voxel-size sizing, the padding the planner picks for the limit).
MeshGridOptions byVoxelSizeOfResolution(const MeshInput& in, int resolution, const Options& o) {
  const bench::PlannedField base =
      planMesh(in, meshRequest(MeshSiteMode::kExactFeature, kInf, o), byResolution(resolution, o), 0);
  MeshGridOptions go;
  go.voxel_size = base.grid.voxelSize();
  return go;
}

bool sameGrid(const Grid& a, const Grid& b) {
  return a.dims() == b.dims() && a.voxelSize() == b.voxelSize() && a.origin().x == b.origin().x &&
         a.origin().y == b.origin().y && a.origin().z == b.origin().z;
}

json errorJson(const bench::MeshSampleCheck& c) {
  return {{"max_err_vox", c.max_err_voxels}, {"mean_err_vox", c.mean_err_voxels}, {"sign_errors", c.sign_errors},
          {"missing", c.missing}, {"compared", c.compared}, {"bound_vox", c.bound_voxels}};
}

/// The peer's errors: the same statistics, judged by no bound (OpenVDB's accuracy is reported, not checked).
bench::MeshSampleCheck peerErrors(const bench::MeshSamples& ref, const std::vector<float>& values, const Grid& grid) {
  return bench::checkMeshSamples(ref, values, grid.voxelSize(), false, kInf);
}

// Finds the sample voxels' values in streamed bricks without keeping the field.
class SampleProbe {
 public:
  explicit SampleProbe(const std::vector<Coord>& voxels) : values_(voxels.size(), NAN) {
    for (size_t i = 0; i < voxels.size(); ++i) {
      const Coord& c = voxels[i];
      by_brick_[key({c.x & ~7, c.y & ~7, c.z & ~7})].push_back({i, brickOffset(c.x & 7, c.y & 7, c.z & 7)});
    }
  }
  void add(const SegmentBricks& s) {
    for (const Brick& b : s.bricks) {
      auto it = by_brick_.find(key(b.origin));
      if (it == by_brick_.end()) continue;
      for (const auto& [i, off] : it->second)
        if (b.mask.test(off)) values_[i] = b.values[off];
    }
  }
  const std::vector<float>& values() const { return values_; }

 private:
  static uint64_t key(const Coord& c) {
    return (uint64_t(uint32_t(c.z)) << 42) | (uint64_t(uint32_t(c.y)) << 21) | uint64_t(uint32_t(c.x));
  }
  std::unordered_map<uint64_t, std::vector<std::pair<size_t, int>>> by_brick_;
  std::vector<float> values_;
};

struct DistbandRun {
  double seeds_s = 0, engine_s = 0, output_s = 0, total_s = 0;
  int64_t voxels = 0, band_voxels = 0;
  FieldRunResult result;
};

/// The plan a run computes with. --feature-engine paper pairs triangle sites with the paper's lifespan, which no
/// request expresses (a request's mode sets both): the inputs are built for the planned sites, then the run takes the
/// paper engine mode. This is the one place this bench edits a plan.
bench::PlannedField enginePlan(const bench::PlannedField& planned, const Options& o) {
  bench::PlannedField e = planned;
  if (planned.plan.sites == SiteKind::kTriangle) e.plan.mode = o.feature_engine;
  return e;
}

// One distband run of a planned request (bench/planned_field.h): buildFieldInputs (the mesh seeds, sign included),
// then computeField. `consume` sees every segment (inside the timed region).
DistbandRun runDistband(const bench::PlannedField& planned, const MeshInput& in, const Options& o,
                        const std::function<void(SegmentBricks&)>& consume) {
  DistbandRun run;
  const auto t0 = Clock::now();
  SeedSource source;
  source.mesh = &in.mesh;
  FieldInputs inputs;
  if (Status e = bench::buildPlannedInputs(planned, source, nullptr, &inputs); !e.ok())
    throw std::runtime_error(e.toString());
  run.seeds_s = since(t0);
  run.band_voxels = int64_t(inputs.seeds.band.size());
  bench::RunSettings settings;
  settings.threads = o.threads;
  double consume_s = 0;
  run.result = bench::computePlanned(enginePlan(planned, o), std::move(inputs), settings, [&](SegmentBricks&& s) {
    const auto tc = Clock::now();
    consume(s);
    consume_s += since(tc);
  });
  run.total_s = since(t0);
  run.output_s = consume_s;
  run.engine_s = run.total_s - run.seeds_s - consume_s;
  run.voxels = run.result.voxels;
  return run;
}

/// The sampled errors of a run against the brute-force reference; fails `verdict` unless they are within the plan's
/// documented bound (bench/mesh_oracle.h), with no sign error on a closed mesh with a signed field, and (with
/// `require_all`) every sample delivered.
bench::MeshSampleCheck checkRun(bench::Verdict& verdict, const std::string& name, const MeshInput& in,
                                const bench::PlannedField& planned, const bench::MeshSamples& ref,
                                const std::vector<float>& values, bool require_all) {
  const bench::MeshSampleCheck c =
      bench::checkMeshSamples(ref, values, planned.grid.voxelSize(), in.report.closed() && planned.plan.signedField(),
                              bench::meshErrorBoundVoxels(planned.plan));
  if (!c.ok(require_all)) verdict.fail(name, planned.grid, c.describe());
  return c;
}

std::vector<Coord> uniformGridSample(const Grid& grid, int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<Coord> v;
  for (int i = 0; i < n; ++i)
    v.push_back({int(rng() % grid.dims().x), int(rng() % grid.dims().y), int(rng() % grid.dims().z)});
  return v;
}

// ---- Table 1 (+ Fig. 6 from the per-segment stats) ----
json table1(const Options& o, bench::Verdict& verdict) {
  json rows = json::array();
  for (const std::string& file : o.table1_meshes) {
    const MeshInput in = loadInput(o, file);
    for (int res : o.resolutions) {
      // Whole volume, no limit: every run of this mesh and resolution is planned on the same grid.
      const MeshGridOptions go = byResolution(res, o);
      const Grid grid = planMesh(in, meshRequest(MeshSiteMode::kExactFeature, kInf, o), go, 0).grid;
      const bench::MeshSamples ref = bench::sampleMesh(in.mesh, grid, uniformGridSample(grid, o.samples, 11));
      for (double seg : {o.segment, 0.0})
        for (MeshSiteMode mode : {MeshSiteMode::kPaper, MeshSiteMode::kExactFeature}) {
          const bench::PlannedField planned = planMesh(in, meshRequest(mode, kInf, o), go, seg);
          const std::string name = fmt::format("table1 {} {}^3 {} l_seg={}", in.name, res, meshSiteModeName(mode), seg);
          if (!sameGrid(planned.grid, grid)) {
            verdict.fail(name, planned.grid, "the planner gave this run another grid than the reference's");
            continue;
          }
          SampleProbe probe(ref.voxels);
          const DistbandRun run = runDistband(planned, in, o, [&](SegmentBricks& s) { probe.add(s); });
          const bench::MeshSampleCheck err = checkRun(verdict, name, in, planned, ref, probe.values(), true);
          json row = {{"mesh", in.name}, {"res", res}, {"dims", {grid.dims().x, grid.dims().y, grid.dims().z}},
                      {"mode", meshSiteModeName(mode)}, {"segment", seg}, {"time_s", run.total_s},
                      {"seeds_s", run.seeds_s}, {"engine_s", run.engine_s}, {"voxels", run.voxels},
                      {"steps", run.result.steps}, {"error", errorJson(err)}, {"pass", err.ok(true)}};
          json segs = json::array();
          for (const SegmentStats& s : run.result.segments)
            segs.push_back({{"lower", s.lower_world / grid.voxelSize()}, {"upper", s.upper_world / grid.voxelSize()},
                            {"voxels", s.voxels}, {"seconds", s.seconds}});
          row["segments"] = segs;
          fmt::print("{} : {:.3f} s (seeds {:.3f}), max err {:.4f} vox (bound {:g}), sign errors {}{}\n", name,
                     run.total_s, run.seeds_s, err.max_err_voxels, err.bound_voxels, err.sign_errors,
                     err.ok(true) ? "" : " FAIL");
          std::fflush(stdout);
          rows.push_back(row);
        }
    }
  }
  return rows;
}

// ---- distband vs OpenVDB at one resolution and several half-widths ----
openvdb::FloatGrid::Ptr runOpenVdb(const MeshInput& in, const Grid& grid, int hw, double* seconds) {
  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> tris;
  std::vector<openvdb::Vec4I> quads;
  for (const Vec3d& v : in.mesh.vertices) points.emplace_back(float(v.x), float(v.y), float(v.z));
  for (const auto& t : in.mesh.triangles) tris.emplace_back(t[0], t[1], t[2]);
  auto xf = openvdb::math::Transform::createLinearTransform(grid.voxelSize());
  xf->postTranslate(openvdb::Vec3d(grid.origin().x, grid.origin().y, grid.origin().z));
  const auto t0 = Clock::now();
  auto vdb = openvdb::tools::meshToSignedDistanceField<openvdb::FloatGrid>(*xf, points, tris, quads, float(hw),
                                                                           float(hw));
  *seconds = since(t0);
  return vdb;
}

json openvdbSuite(const Options& o, bench::Verdict& verdict) {
  json rows = json::array();
  for (const std::string& file : o.openvdb_meshes) {
    const MeshInput in = loadInput(o, file);
    // The Table 1 voxel size at this resolution for every half-width; the planner pads the grid for the limit, so
    // distband computes the whole band OpenVDB computes, and OpenVDB runs on distband's planned transform.
    const MeshGridOptions go = byVoxelSizeOfResolution(in, o.openvdb_resolution, o);
    for (int hw : o.half_widths) {
      const bench::PlannedField exact_plan = planMesh(in, meshRequest(MeshSiteMode::kExactFeature, hw, o), go, 0);
      const bench::PlannedField paper_plan = planMesh(in, meshRequest(MeshSiteMode::kPaper, hw, o), go, 0);
      const Grid& grid = exact_plan.grid;
      const std::string name = fmt::format("openvdb {} {}^3 hw={}", in.name, o.openvdb_resolution, hw);
      if (!sameGrid(paper_plan.grid, grid)) verdict.fail(name, grid, "paper mode was planned on another grid");
      json row = {{"mesh", in.name}, {"res", o.openvdb_resolution}, {"half_width", hw},
                  {"dims", {grid.dims().x, grid.dims().y, grid.dims().z}}, {"threads", o.threads}};
      // distband exact-feature first: its delivered band gives the sample voxels.
      std::unique_ptr<VdbFieldBuilder> built;
      // The timed product: seeds, engine and the assembled level-set grid.
      auto runExact = [&](std::unique_ptr<VdbFieldBuilder>* out) {
        auto builder = std::make_unique<VdbFieldBuilder>(grid, float(exact_plan.plan.limit_world));
        DistbandRun run = runDistband(exact_plan, in, o, [&](SegmentBricks& s) { builder->add(s); });
        const auto tf = Clock::now();
        builder->finish();
        run.output_s += since(tf);
        run.total_s += since(tf);
        if (out) *out = std::move(builder);
        return run;
      };
      DistbandRun exact = runExact(&built);
      // Sample voxels uniformly from distband's active band.
      {
        const VdbTree<float>& tree = built->distance();
        std::vector<Coord> all;
        all.reserve(size_t(tree.activeVoxels()));
        for (const auto* leaf : tree.leaves())
          for (int i = 0; i < kBrickVoxels; ++i)
            if (leaf->mask.test(i)) all.push_back(leaf->origin + brickLocal(i));
        std::mt19937 rng(5);
        std::shuffle(all.begin(), all.end(), rng);
        all.resize(std::min<size_t>(all.size(), o.samples));
        const bench::MeshSamples ref = bench::sampleMesh(in.mesh, grid, all);
        auto valuesFrom = [&](const openvdb::FloatGrid& g) {
          std::vector<float> v(ref.voxels.size(), NAN);
          auto acc = g.getConstAccessor();
          for (size_t i = 0; i < ref.voxels.size(); ++i) {
            const openvdb::Coord c(ref.voxels[i].x, ref.voxels[i].y, ref.voxels[i].z);
            if (acc.isValueOn(c)) v[i] = acc.getValue(c);
          }
          return v;
        };
        std::vector<float> exact_values(ref.voxels.size());
        for (size_t i = 0; i < ref.voxels.size(); ++i) exact_values[i] = built->value(ref.voxels[i]);  // all active
        const bench::MeshSampleCheck e_exact =
            checkRun(verdict, name + " exact-feature", in, exact_plan, ref, exact_values, true);
        built.reset();
        // distband paper mode on the same band. Its values near the limit may fall just beyond it (not delivered):
        // those samples count as missing, not as errors.
        SampleProbe probe(ref.voxels);
        const DistbandRun paper = runDistband(paper_plan, in, o, [&](SegmentBricks& s) { probe.add(s); });
        const bench::MeshSampleCheck e_paper =
            checkRun(verdict, name + " paper", in, paper_plan, ref, probe.values(), false);
        if (e_paper.missing > int64_t(ref.voxels.size()) / 20)
          verdict.fail(name + " paper", grid, fmt::format("{} of {} samples of the exact band not delivered",
                                                          e_paper.missing, ref.voxels.size()));
        // OpenVDB (the peer: its errors are reported, not checked).
        double vdb_s = 0;
        auto vdb = runOpenVdb(in, grid, hw, &vdb_s);
        const bench::MeshSampleCheck e_vdb = peerErrors(ref, valuesFrom(*vdb), grid);
        const int64_t vdb_voxels = int64_t(vdb->activeVoxelCount());
        vdb.reset();
        // More timed runs of both, alternating which goes first (the first run of a process pays for fresh memory),
        // compared by their medians.
        std::vector<double> exact_times{exact.total_s}, vdb_times{vdb_s};
        for (int r = 1; r < o.reps; ++r) {
          if (r % 2) {
            double s = 0;
            runOpenVdb(in, grid, hw, &s);
            vdb_times.push_back(s);
            exact_times.push_back(runExact(nullptr).total_s);
          } else {
            exact_times.push_back(runExact(nullptr).total_s);
            double s = 0;
            runOpenVdb(in, grid, hw, &s);
            vdb_times.push_back(s);
          }
        }
        const double exact_med = bench::median(exact_times), vdb_med = bench::median(vdb_times);
        row["reps"] = o.reps;
        row["distband_exact"] = {{"time_s", exact_med}, {"times_s", exact_times}, {"seeds_s", exact.seeds_s},
                                 {"engine_s", exact.engine_s}, {"vdb_assembly_s", exact.output_s},
                                 {"voxels", exact.voxels}, {"error", errorJson(e_exact)}};
        row["distband_paper"] = {{"time_s", paper.total_s}, {"seeds_s", paper.seeds_s}, {"engine_s", paper.engine_s},
                                 {"voxels", paper.voxels}, {"error", errorJson(e_paper)}};
        row["openvdb"] = {{"time_s", vdb_med}, {"times_s", vdb_times}, {"voxels", vdb_voxels},
                          {"error", errorJson(e_vdb)}};
        row["ratio_exact_over_openvdb"] = exact_med / vdb_med;
        fmt::print("openvdb {} {}^3 hw={} : distband exact {:.3f} s median of {} (first run: seeds {:.3f} engine {:.3f} vdb {:.3f}; "
                   "max {:.4f}, sign {}), paper {:.3f} s (max {:.4f}), OpenVDB {:.3f} s median (max {:.4f}, sign {}, missing {}) "
                   "ratio {:.2f}\n",
                   in.name, o.openvdb_resolution, hw, exact_med, o.reps, exact.seeds_s, exact.engine_s, exact.output_s,
                   e_exact.max_err_voxels, e_exact.sign_errors, paper.total_s, e_paper.max_err_voxels, vdb_med, e_vdb.max_err_voxels,
                   e_vdb.sign_errors, e_vdb.missing, exact_med / vdb_med);
        std::fflush(stdout);
      }
      rows.push_back(row);
    }
  }
  return rows;
}

// ---- Fig. 7: l_seg sweep on the bunny at the largest resolution ----
json fig7(const Options& o, bench::Verdict& verdict) {
  json rows = json::array();
  const MeshInput in = loadInput(o, "bunny.obj");
  const int res = o.resolutions.back();
  const MeshGridOptions go = byResolution(res, o);
  for (double seg : {5.0, 10.0, 20.0, 40.0, 80.0, 0.0})
    for (MeshSiteMode mode : {MeshSiteMode::kPaper, MeshSiteMode::kExactFeature}) {
      const bench::PlannedField planned = planMesh(in, meshRequest(mode, kInf, o), go, seg);
      const DistbandRun run = runDistband(planned, in, o, [](SegmentBricks&) {});
      // Timing rows (their accuracy is table1's); without a limit every voxel of the grid is delivered.
      if (run.voxels != planned.grid.voxelCount())
        verdict.fail(fmt::format("fig7 bunny {}^3 {} l_seg={}", res, meshSiteModeName(mode), seg), planned.grid,
                     fmt::format("{} voxels delivered, the grid has {}", run.voxels, planned.grid.voxelCount()));
      rows.push_back({{"mesh", in.name}, {"res", res}, {"mode", meshSiteModeName(mode)}, {"segment", seg},
                      {"time_s", run.total_s}, {"steps", run.result.steps}});
      fmt::print("fig7 bunny {}^3 {} l_seg={} : {:.3f} s\n", res, meshSiteModeName(mode), seg, run.total_s);
      std::fflush(stdout);
    }
  return rows;
}

// ---- memory case (one per process) ----
json memoryCase(const Options& o) {
  const MeshInput in = loadInput(o, o.memory_mesh);
  const bench::PlannedField planned =
      planMesh(in, meshRequest(MeshSiteMode::kExactFeature, o.memory_half_width, o),
               byVoxelSizeOfResolution(in, o.memory_resolution, o), 0);
  const Grid& grid = planned.grid;
  const double rss_before = peakRssMb();
  json row = {{"case", o.run_case}, {"mesh", in.name}, {"res", o.memory_resolution},
              {"half_width", o.memory_half_width}, {"threads", o.threads},
              {"dims", {grid.dims().x, grid.dims().y, grid.dims().z}}, {"rss_after_load_mb", rss_before}};
  if (o.run_case == "memory-distband") {
    VdbFieldBuilder builder(grid, float(planned.plan.limit_world));
    DistbandRun run = runDistband(planned, in, o, [&](SegmentBricks& s) { builder.add(s); });
    builder.finish();
    row["time_s"] = run.total_s;
    row["seeds_s"] = run.seeds_s;
    row["band_voxels"] = run.band_voxels;
    row["active_voxels"] = builder.activeVoxels();
    row["engine_s"] = run.engine_s;
    row["updates"] = run.result.updates;
    row["steps"] = run.result.steps;
  } else if (o.run_case == "memory-distband-discard") {  // same run, output dropped: the engine's own footprint
    DistbandRun run = runDistband(planned, in, o, [](SegmentBricks&) {});
    row["time_s"] = run.total_s;
    row["band_voxels"] = run.band_voxels;
    row["active_voxels"] = run.voxels;
  } else if (o.run_case == "memory-seeds") {  // the initial band alone
    SeedSource source;
    source.mesh = &in.mesh;
    FieldInputs inputs;
    const auto t0 = Clock::now();
    if (Status e = bench::buildPlannedInputs(planned, source, nullptr, &inputs); !e.ok())
      throw std::runtime_error(e.toString());
    row["time_s"] = since(t0);
    row["band_voxels"] = int64_t(inputs.seeds.band.size());
  } else if (o.run_case == "memory-openvdb") {
    double s = 0;
    auto vdb = runOpenVdb(in, grid, o.memory_half_width, &s);
    row["time_s"] = s;
    row["active_voxels"] = int64_t(vdb->activeVoxelCount());
  } else {
    throw std::runtime_error("unknown --case " + o.run_case);
  }
  row["peak_rss_mb"] = peakRssMb();
  return row;
}

json memorySuite(const Options& o, const std::string& self) {
  json rows = json::array();
  for (const char* c : {"memory-distband", "memory-distband-discard", "memory-seeds", "memory-openvdb"}) {
    const std::string cmd =
        fmt::format("/usr/bin/time -v '{}' --case {} --mesh-dir '{}' --threads {} --memory-res {} --memory-half-width {} "
                    "--memory-mesh '{}' 2>&1",
                    self, c, o.mesh_dir, o.threads, o.memory_resolution, o.memory_half_width, o.memory_mesh);
    const auto [out, rc] = bench::runCommand(cmd);
    if (rc < 0) throw std::runtime_error("cannot run " + cmd);
    json row;
    std::istringstream lines(out);
    for (std::string line; std::getline(lines, line);)
      if (!line.empty() && line[0] == '{') row = json::parse(line);
    if (const auto mb = bench::timeVPeakRssMb(out)) row["time_v_peak_rss_mb"] = *mb;
    fmt::print("memory {}: {}\n", c, row.dump());
    std::fflush(stdout);
    rows.push_back(row);
  }
  return rows;
}

std::string num(const json& v, const char* f = "{:.3f}") {
  return v.is_number() ? fmt::format(fmt::runtime(f), v.get<double>()) : "-";
}

std::string markdown(const json& out) {
  std::string md = fmt::format("# mesh_bench results ({})\n\n", out["tag"].get<std::string>());
  md += fmt::format("- machine: {} threads (TBB global_control + engine task_arena), load average at start: {}\n",
                    out["threads"].get<int>(), out["loadavg_start"].get<std::string>());
  md += "- errors in voxels vs brute force (exact point–triangle distance over all triangles); sign reference: exact "
        "generalized winding number > 0.5\n- distband sign: pseudonormal; engine stencil: " +
        out["stencil"].get<std::string>() + "; paper mode = CP+PQ point sites + the paper's lifespan, exact-feature = "
        "triangle-id sites + the engine's " + out["feature_engine"].get<std::string>() + " mode; open meshes are signed with the winding number\n\n";
  if (out.contains("table1")) {
    md += "## Table 1 (whole volume, no limit): time in seconds, paper vs exact-feature\n\n"
          "| mesh | res | l_seg | paper s | paper max err | paper mean err | exact-feature s | exact max err | "
          "exact mean err | sign errors (paper/exact) |\n|---|---|---|---|---|---|---|---|---|---|\n";
    const json& rows = out["table1"];
    for (size_t i = 0; i + 1 < rows.size(); i += 2) {
      const json &p = rows[i], &e = rows[i + 1];
      md += fmt::format("| {} | {}³ | {} | {} | {} | {} | {} | {} | {} | {}/{} |\n", p["mesh"].get<std::string>(),
                        p["res"].get<int>(), p["segment"].get<double>() > 0 ? num(p["segment"], "{:.0f}") : "-",
                        num(p["time_s"]), num(p["error"]["max_err_vox"], "{:.4f}"),
                        num(p["error"]["mean_err_vox"], "{:.5f}"), num(e["time_s"]),
                        num(e["error"]["max_err_vox"], "{:.4f}"), num(e["error"]["mean_err_vox"], "{:.5f}"),
                        p["error"]["sign_errors"].get<int64_t>(), e["error"]["sign_errors"].get<int64_t>());
    }
    md += "\n### Fig. 6: time per distance range (bunny, largest resolution, l_seg = 20)\n\n"
          "| mode | range (voxels) | voxels | seconds |\n|---|---|---|---|\n";
    for (const json& r : rows)
      if (r["mesh"] == "bunny" && r["res"] == out["max_res"] && r["segment"].get<double>() > 0)
        for (const json& s : r["segments"])
          md += fmt::format("| {} | {:.0f}–{:.0f} | {} | {:.3f} |\n", r["mode"].get<std::string>(),
                            s["lower"].get<double>(), std::min(s["upper"].get<double>(), 1e9),
                            s["voxels"].get<int64_t>(), s["seconds"].get<double>());
  }
  if (out.contains("openvdb")) {
    md += fmt::format("\n## distband vs OpenVDB meshToSignedDistanceField (same transform, same band, same threads)\n\n"
                      "Times are medians of {} runs of each, alternating which goes first; both use {} TBB threads. "
                      "distband's time covers seeds, engine and the assembled OpenVDB level-set grid; the engine+seeds "
                      "column is from its first run.\n\n",
                      out["openvdb"].empty() ? 0 : out["openvdb"][0].value("reps", 1),
                      out["openvdb"].empty() ? 0 : out["openvdb"][0].value("threads", 0));
    md += "| mesh | res | half-width | distband exact s | (engine+seeds s) | OpenVDB s | ratio | exact max/mean err | "
          "OpenVDB max/mean err | sign errors exact/OpenVDB | OpenVDB missing | paper s | paper max/mean err |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (const json& r : out["openvdb"]) {
      const json &e = r["distband_exact"], &v = r["openvdb"], &p = r["distband_paper"];
      md += fmt::format("| {} | {}³ | {} | {} | {} | {} | {:.2f} | {} / {} | {} / {} | {} / {} | {} | {} | {} / {} |\n",
                        r["mesh"].get<std::string>(), r["res"].get<int>(), r["half_width"].get<int>(),
                        num(e["time_s"]), num(e["seeds_s"].get<double>() + e["engine_s"].get<double>()),
                        num(v["time_s"]), r["ratio_exact_over_openvdb"].get<double>(),
                        num(e["error"]["max_err_vox"], "{:.4f}"), num(e["error"]["mean_err_vox"], "{:.5f}"),
                        num(v["error"]["max_err_vox"], "{:.4f}"), num(v["error"]["mean_err_vox"], "{:.5f}"),
                        e["error"]["sign_errors"].get<int64_t>(), v["error"]["sign_errors"].get<int64_t>(),
                        v["error"]["missing"].get<int64_t>(), num(p["time_s"]),
                        num(p["error"]["max_err_vox"], "{:.4f}"), num(p["error"]["mean_err_vox"], "{:.5f}"));
    }
  }
  if (out.contains("fig7")) {
    md += "\n## Fig. 7: l_seg sweep (bunny, whole volume)\n\n| mode | l_seg | seconds | steps |\n|---|---|---|---|\n";
    for (const json& r : out["fig7"])
      md += fmt::format("| {} | {} | {} | {} |\n", r["mode"].get<std::string>(),
                        r["segment"].get<double>() > 0 ? num(r["segment"], "{:.0f}") : "none", num(r["time_s"]),
                        r["steps"].get<int>());
  }
  if (out.contains("memory")) {
    md += "\n## Memory: peak RSS (separate processes, /usr/bin/time -v)\n\n"
          "| case | mesh | res | half-width | time s | active voxels | peak RSS MB |\n|---|---|---|---|---|---|---|\n";
    for (const json& r : out["memory"])
      md += fmt::format("| {} | {} | {}³ | {} | {} | {} | {} |\n", r.value("case", "?"), r.value("mesh", "?"),
                        r.value("res", 0), r.value("half_width", 0), num(r.value("time_s", json())),
                        r.value("active_voxels", r.value("band_voxels", int64_t(0))), num(r.value("time_v_peak_rss_mb", json()), "{:.0f}"));
  }
  return md;
}

std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::string s;
  std::getline(f, s);
  return s;
}

}  // namespace
}  // namespace distband

int main(int argc, char** argv) {
  using namespace distband;
  Options o;
  CLI::App app{"distband mesh benchmark: Table 1 mesh rows and OpenVDB meshToSignedDistanceField"};
  app.add_option("--mesh-dir", o.mesh_dir, "directory holding the meshes");
  app.add_option("--out-dir", o.out_dir, "where <tag>.json and <tag>.md go");
  app.add_option("--tag", o.tag, "output file stem");
  app.add_option("--suite", o.suites, "table1, openvdb, fig7, memory")->delimiter(',');
  app.add_option("--meshes", o.table1_meshes, "Table 1 meshes")->delimiter(',');
  app.add_option("--openvdb-meshes", o.openvdb_meshes, "meshes for the OpenVDB comparison")->delimiter(',');
  app.add_option("--resolutions", o.resolutions, "Table 1 resolutions")->delimiter(',');
  app.add_option("--openvdb-res", o.openvdb_resolution, "resolution of the OpenVDB comparison");
  app.add_option("--half-widths", o.half_widths, "band half-widths (voxels) for the OpenVDB comparison")->delimiter(',');
  app.add_option("--threads", o.threads, "TBB threads for both distband and OpenVDB");
  app.add_option("--samples", o.samples, "sampled voxels for the error statistics");
  app.add_option("--reps", o.reps, "openvdb suite: timed runs of each method per row (medians are compared)")->check(CLI::Range(1, 99));
  app.add_option("--padding", o.padding, "padding (voxels) of the Table 1 grid (default: the planner's)");
  bool smoke = false;
  app.add_flag("--smoke", smoke, "table1 and openvdb on tests/data's meshes at 32^3 / 48^3, 400 samples, once, output in the "
                                 "temporary directory unless --out-dir is given (the CTest run)");
  app.add_option("--segment", o.segment, "l_seg (voxels) of the segmented Table 1 rows");
  app.add_option("--stencil", o.stencil, "engine stencil: auto (the product default) | cubic26 | cubic18 | cubic6 | fcc12");
  app.add_option("--case", o.run_case,
                 "memory-distband | memory-distband-discard | memory-seeds | memory-openvdb: one memory row in this process");
  app.add_option("--memory-mesh", o.memory_mesh, "mesh of the memory case");
  app.add_option("--memory-res", o.memory_resolution, "resolution of the memory case");
  app.add_option("--memory-half-width", o.memory_half_width, "half-width of the memory case");
  app.add_flag("--second-ring", o.second_ring, "exact-feature rows: also run the second-ring correction");
  std::string feature_engine = "exact";
  app.add_option("--feature-engine", feature_engine,
                 "engine mode of the exact-feature rows: exact (iterate to convergence) or paper (lifespan)");
  CLI11_PARSE(app, argc, argv);
  if (smoke) {
    o.suites = {"table1", "openvdb"};
    o.table1_meshes = o.openvdb_meshes = {"bunny.obj", "fandisk.off", "teapot.obj"};
    o.resolutions = {32};
    o.openvdb_resolution = 48;
    o.half_widths = {3};
    o.samples = 400;
    o.reps = 1;
    if (app.get_option("--mesh-dir")->count() == 0) o.mesh_dir = DISTBAND_BENCH_DIR "/../tests/data/meshes";
    if (app.get_option("--out-dir")->count() == 0) o.out_dir = std::filesystem::temp_directory_path().string();
    if (app.get_option("--tag")->count() == 0) o.tag = "mesh_bench_smoke";
  }
  if (!parseMode(feature_engine, &o.feature_engine)) {
    fmt::print(stderr, "unknown engine mode {}\n", feature_engine);
    return 2;
  }
  if (o.stencil != "auto" && !parseStencil(o.stencil)) {
    fmt::print(stderr, "unknown stencil {}\n", o.stencil);
    return 2;
  }
  openvdb::initialize();
  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, o.threads);
  bench::Verdict verdict("mesh_bench");
  try {
    if (!o.run_case.empty()) {
      fmt::print("{}\n", memoryCase(o).dump());
      return 0;
    }
    json out = {{"tag", o.tag}, {"threads", o.threads}, {"stencil", o.stencil},
                {"feature_engine", std::string(modeName(o.feature_engine))},
                {"second_ring", o.second_ring},
                {"loadavg_start", slurp("/proc/loadavg")}, {"max_res", o.resolutions.back()}};
    auto has = [&](const char* s) { return std::find(o.suites.begin(), o.suites.end(), s) != o.suites.end(); };
    std::filesystem::create_directories(o.out_dir);
    auto save = [&] {
      distband::bench::writeResultFile(o.out_dir + "/" + o.tag + ".json", out.dump(2) + "\n");
      distband::bench::writeResultFile(o.out_dir + "/" + o.tag + ".md", markdown(out));
    };
    if (has("openvdb")) out["openvdb"] = openvdbSuite(o, verdict), save();
    if (has("table1")) out["table1"] = table1(o, verdict), save();
    if (has("fig7")) out["fig7"] = fig7(o, verdict), save();
    if (has("memory")) out["memory"] = memorySuite(o, std::filesystem::canonical("/proc/self/exe").string()), save();
    save();
  } catch (const std::exception& e) {
    verdict.fail("mesh_bench", e.what());
  }
  return verdict.finish();
}

// scaling_bench: a mesh's narrow band (seeds + propagation, exact-feature, the planner's defaults) at 1 and N threads,
// and a model of its time at more threads than this machine has (issue 11, goal 3: >= 12x from 1 to 16 threads,
// argued from profiles where no 16-core machine is at hand).
// Contract:
//   * Runs the band --reps times at each of --threads (medians of wall seconds, seeds and engine together, output
//     dropped). At 1 thread it also records each propagation step's work items and wall time (BandOptions::on_step).
//   * The model, for n threads:  T(n) = S + P / n + sum_i W_i / min(n, ceil(items_i / grain_i)),
//     S = --serial-fraction x T(1) (the serial share measured by bench/serial_fraction.py on a frame-pointer perf
//     profile of the same run), W_i the steps' times (each step is one parallel loop whose chunks are at least its
//     grain: 256 front entries, 1024 band voxels for the first step), P the rest (large loops: seeds, insertion,
//     emission, the output's gathering). It ignores memory bandwidth and the scheduler's fork/join cost (counted as
//     --join-us per step per thread count > 1, default 20 us), so it is a bound to check against the measured 2-thread
//     time, which it prints beside its own.
//   * Prints a table and one JSON line (--json FILE writes it too).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/global_control.h>

#include "bench/bench_util.h"
#include "core/band/band_engine.h"
#include "core/field/field_plan.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/seeds/mesh_seeds.h"

using namespace distband;
using bench::Clock;
using bench::since;

namespace {

struct Step {
  size_t items = 0;
  double seconds = 0;
};

struct Run {
  double seconds = 0;
  std::vector<Step> steps;  // 1 thread only
};

Run runBand(const TriangleMesh& mesh, const MeshReport& report, const Grid& grid, double half_width, int threads,
            bool record_steps) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
  FieldRequest request;
  request.seeds = SeedKind::kMesh;
  request.limit_voxels = half_width;
  FieldPlan plan;
  if (Status e = planField(request, grid, &report, &plan); !e.ok()) throw std::runtime_error(e.toString());
  Run run;
  Clock::time_point last;
  BandOptions options = plan.bandOptions(plan.runOptions());
  options.threads = threads;
  if (record_steps)
    options.on_step = [&](int, size_t items) {
      const auto now = Clock::now();
      if (!run.steps.empty()) run.steps.back().seconds = std::chrono::duration<double>(now - last).count();
      run.steps.push_back({items, 0});
      last = now;
    };
  const auto t0 = Clock::now();
  Seeds seeds;
  if (Status e = makeMeshSeeds(grid, mesh, plan.meshSeedOptions(grid), &seeds); !e.ok())
    throw std::runtime_error(e.toString());
  computeBandField(grid, std::move(seeds), options, [&](SegmentBricks&&) {});
  run.seconds = since(t0);
  // The last step runs until its segment's emission (counted there, with the large loops).
  if (!run.steps.empty()) run.steps.pop_back();
  return run;
}

}  // namespace

int main(int argc, char** argv) {
  std::string mesh_path = std::string(DISTBAND_BENCH_DIR) + "/../../shared/data/meshes/armadillo.off";
  int resolution = 512, reps = 3;
  double half_width = 20, serial_fraction = 0, join_us = 20;
  std::vector<int> threads = {1, 2};
  std::vector<int> model_threads = {2, 4, 8, 16};
  std::string json_path;
  CLI::App app("the band at 1 and N threads, and a model of its time at more threads");
  app.add_option("--mesh", mesh_path, "mesh file");
  app.add_option("--resolution", resolution, "grid resolution (longest side)")->check(CLI::Range(16, 4096));
  app.add_option("--half-width", half_width, "the limit, in voxels")->check(CLI::PositiveNumber);
  app.add_option("--threads", threads, "thread counts to measure (1 first)")->delimiter(',');
  app.add_option("--model-threads", model_threads, "thread counts to model")->delimiter(',');
  app.add_option("--reps,-R", reps, "runs per thread count (median)")->check(CLI::Range(1, 50));
  app.add_option("--serial-fraction", serial_fraction, "serial share of the 1-thread run (bench/serial_fraction.py)")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--join-us", join_us, "fork/join cost of a parallel loop, microseconds")->check(CLI::NonNegativeNumber);
  app.add_option("--json", json_path, "also write the JSON line to this file");
  CLI11_PARSE(app, argc, argv);

  TriangleMesh mesh;
  MeshReport report;
  if (Status e = loadMesh(mesh_path, &mesh, &report); !e.ok()) {
    fmt::print(stderr, "{}\n", e.toString());
    return 2;
  }
  MeshGridOptions go;
  go.resolution = resolution;
  Grid grid;
  if (Status e = gridForMesh(mesh, go, {std::numeric_limits<double>::infinity(), double(half_width)}, &grid); !e.ok()) {
    fmt::print(stderr, "{}\n", e.toString());
    return 2;
  }

  nlohmann::json out = {{"mesh", mesh_path}, {"resolution", resolution}, {"half_width", half_width}, {"reps", reps},
                        {"serial_fraction", serial_fraction}, {"join_us", join_us}};
  std::vector<Step> steps;
  double t1 = 0, t2 = 0;
  for (int n : threads) {
    std::vector<double> seconds;
    for (int r = 0; r < reps; ++r) {
      Run run = runBand(mesh, report, grid, half_width, n, n == 1 && r == 0);
      seconds.push_back(run.seconds);
      if (!run.steps.empty()) steps = std::move(run.steps);
    }
    const double med = bench::median(seconds);
    if (n == 1) t1 = med;
    if (n == 2) t2 = med;
    out["measured"][std::to_string(n)] = med;
    fmt::print("{} thread{}: {:.3f} s (median of {})\n", n, n == 1 ? "" : "s", med, reps);
  }
  if (t1 == 0) {
    fmt::print(stderr, "scaling_bench: the model needs a 1-thread run (--threads 1,...)\n");
    return 2;
  }
  double w = 0;
  for (const Step& s : steps) w += s.seconds;
  const double serial = serial_fraction * t1;
  const double rest = std::max(0.0, t1 - serial - w);
  fmt::print("1 thread: {:.3f} s = serial {:.3f} + steps {:.3f} ({} steps) + other parallel loops {:.3f}\n", t1, serial,
             w, steps.size(), rest);
  auto model = [&](int n) {
    double t = serial + rest / n;
    for (size_t i = 0; i < steps.size(); ++i) {
      const double grain = i == 0 ? 1024.0 : 256.0;  // the first step pushes the band list (stepFromBand)
      const double chunks = std::ceil(double(steps[i].items) / grain);
      t += steps[i].seconds / std::max(1.0, std::min(double(n), chunks)) + (n > 1 ? join_us * 1e-6 : 0.0);
    }
    return t;
  };
  for (int n : model_threads) {
    const double tn = model(n);
    double short_w = 0;  // steps with fewer chunks than threads
    for (size_t i = 0; i < steps.size(); ++i)
      if (std::ceil(double(steps[i].items) / (i == 0 ? 1024.0 : 256.0)) < n) short_w += steps[i].seconds;
    out["model"][std::to_string(n)] = {{"seconds", tn}, {"speedup", t1 / tn}, {"steps_short_of_threads_s", short_w}};
    fmt::print("model {:2d} threads: {:.3f} s, speedup {:.1f}x (steps with fewer chunks than threads: {:.4f} s at 1 "
               "thread){}\n",
               n, tn, t1 / tn, short_w,
               n == 2 && t2 > 0 ? fmt::format("; measured {:.3f} s, {:.2f}x", t2, t1 / t2) : std::string());
  }
  nlohmann::json step_list = nlohmann::json::array();
  for (const Step& s : steps) step_list.push_back({s.items, s.seconds});
  out["steps"] = step_list;
  const std::string line = out.dump();
  fmt::print("{}\n", line);
  if (!json_path.empty()) std::ofstream(json_path) << line << "\n";
  return 0;
}

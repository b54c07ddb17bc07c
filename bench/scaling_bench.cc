// scaling_bench: a mesh's narrow band (seeds + propagation, exact-feature, the planner's defaults) at 1 and N threads,
// and a model of its time at more threads than this machine has (>= 12x from 1 to 16 threads is the goal, argued from
// profiles where no 16-core machine is at hand).
// Contract:
//   * The band is a FieldRequest (mesh, limit --half-width voxels) planned as `distband compute --mesh` plans it
//     (bench/planned_field.h: gridForMesh with the request's limit, planField) and run through buildFieldInputs and
//     computeField, --reps times at each of --threads (medians of wall seconds, inputs and engine together, output
//     dropped). The first 1-thread run also records each propagation step's work items and wall time: it calls the
//     band's entry point with the plan's own band options (FieldPlan::bandOptions) plus the BandOptions::on_step
//     observer, which computeField does not expose.
//   * The model, for n threads:  T(n) = S + P / n + sum_i W_i / min(n, ceil(items_i / grain_i)),
//     S = --serial-fraction x T(1) (the serial share measured by bench/serial_fraction.py on a frame-pointer perf
//     profile of the same run), W_i the steps' times (each step is one parallel loop whose chunks are at least its
//     grain: 256 front entries, 1024 band voxels for the first step), P the rest (large loops: seeds, insertion,
//     emission, the output's gathering). It ignores memory bandwidth and the scheduler's fork/join cost (counted as
//     --join-us per step per thread count > 1, default 20 us), so it is a bound to check against the measured 2-thread
//     time, which it prints beside its own.
//   * Reference: brute force (bench/mesh_oracle.h) at --samples voxels drawn from the first run's delivery, and the
//     first run's field itself: the result is bit-identical for any thread count (core/field/field_run.h).
//   * Pass: every run's field equal to the first (an order-independent checksum of voxel and value bits), the samples
//     within the plan's documented bound with no sign error on a closed mesh; else the exit status is 1 and the
//     failure names the run or the first bad voxel.
//   * Prints a table and one JSON line (--json FILE writes it too).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/global_control.h>

#include "bench/bench_util.h"
#include "bench/mesh_oracle.h"
#include "bench/planned_field.h"
#include "core/band/band_engine.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"

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
  // Check runs only (untimed: the hashing would add serial work to the callback):
  uint64_t voxels = 0, sum = 0;  // delivered voxels and an order-independent checksum of (voxel, value bits)
  std::vector<std::pair<Coord, float>> samples;  // 1-in-256 of the delivered voxels (hashed)
};

uint64_t voxelHash(const Coord& c, float value) {
  uint32_t bits;
  std::memcpy(&bits, &value, 4);
  uint64_t h = (uint64_t(uint32_t(c.x)) * 0x9E3779B97F4A7C15ull) ^ (uint64_t(uint32_t(c.y)) << 21) ^
               (uint64_t(uint32_t(c.z)) << 42) ^ (uint64_t(bits) * 0xC2B2AE3D27D4EB4Full);
  h ^= h >> 29;
  return h * 0xBF58476D1CE4E5B9ull;
}

bool sampled(const Coord& c) {
  const uint32_t h = uint32_t(c.x) * 73856093u ^ uint32_t(c.y) * 19349663u ^ uint32_t(c.z) * 83492791u;
  return ((h >> 7) & 255) == 0;
}

Run runBand(const bench::PlannedField& planned, const TriangleMesh& mesh, int threads, bool record_steps, bool check) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
  Run run;
  Clock::time_point last;
  auto consume = [&](SegmentBricks&& s) {
    if (!check) return;
    for (const Brick& b : s.bricks)
      for (int i = 0; i < kBrickVoxels; ++i)
        if (b.mask.test(i)) {
          const Coord c = b.origin + brickLocal(i);
          ++run.voxels;
          run.sum += voxelHash(c, b.values[i]);
          if (sampled(c)) run.samples.push_back({c, b.values[i]});
        }
  };
  const auto t0 = Clock::now();
  SeedSource source;
  source.mesh = &mesh;
  FieldInputs inputs;
  if (Status e = bench::buildPlannedInputs(planned, source, nullptr, &inputs); !e.ok())
    throw std::runtime_error(e.toString());
  if (record_steps) {
    FieldRunOptions run_options = planned.plan.runOptions();
    run_options.threads = threads;
    BandOptions options = planned.plan.bandOptions(run_options);
    options.on_step = [&](int, size_t items) {
      const auto now = Clock::now();
      if (!run.steps.empty()) run.steps.back().seconds = std::chrono::duration<double>(now - last).count();
      run.steps.push_back({items, 0});
      last = now;
    };
    computeBandField(planned.grid, std::move(inputs.seeds), options, consume);
  } else {
    bench::RunSettings settings;
    settings.threads = threads;
    bench::computePlanned(planned, std::move(inputs), settings, consume);
  }
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
  int samples = 500;
  app.add_option("--samples", samples, "voxels checked by brute force")->check(CLI::Range(1, 100000));
  CLI11_PARSE(app, argc, argv);

  TriangleMesh mesh;
  MeshReport report;
  if (Status e = loadMesh(mesh_path, &mesh, &report); !e.ok()) {
    fmt::print(stderr, "{}\n", e.toString());
    return 2;
  }
  FieldRequest request;
  request.seeds = SeedKind::kMesh;
  request.limit_voxels = half_width;
  MeshGridOptions go;
  go.resolution = resolution;
  bench::PlannedField planned;
  if (Status e = bench::planMeshField(request, mesh, report, go, &planned); !e.ok()) {
    fmt::print(stderr, "{}\n", e.toString());
    return 2;
  }
  if (planned.plan.algorithm != FieldAlgorithm::kBand) {
    fmt::print(stderr, "scaling_bench: the planner does not run the band for this mesh\n");
    return bench::kExitWrong;
  }
  bench::Verdict verdict("scaling_bench");
  const std::string name = fmt::format("{} at {}, limit {} voxels", mesh_path, resolution, half_width);

  nlohmann::json out = {{"mesh", mesh_path}, {"resolution", resolution}, {"half_width", half_width}, {"reps", reps},
                        {"serial_fraction", serial_fraction}, {"join_us", join_us}};
  std::vector<Step> steps;
  double t1 = 0, t2 = 0;
  std::optional<Run> first_check;
  for (int n : threads) {
    std::vector<double> seconds;
    for (int r = 0; r < reps; ++r) {
      Run run = runBand(planned, mesh, n, n == 1 && r == 0, false);
      seconds.push_back(run.seconds);
      if (!run.steps.empty()) steps = std::move(run.steps);
    }
    const double med = bench::median(seconds);
    if (n == 1) t1 = med;
    if (n == 2) t2 = med;
    out["measured"][std::to_string(n)] = med;
    fmt::print("{} thread{}: {:.3f} s (median of {})\n", n, n == 1 ? "" : "s", med, reps);
    // The check run of this thread count: the same field as the first check run.
    Run check = runBand(planned, mesh, n, false, true);
    if (!first_check) {
      first_check = std::move(check);
    } else if (check.voxels != first_check->voxels || check.sum != first_check->sum) {
      verdict.fail(name, planned.grid,
                   fmt::format("{} threads: {} voxels, checksum {:016x}; {} threads gave {} voxels, checksum {:016x}",
                               n, check.voxels, check.sum, threads.front(), first_check->voxels, first_check->sum));
    }
  }
  if (first_check) {  // brute force at the sampled voxels (at most --samples of them)
    std::vector<Coord> voxels;
    std::vector<float> values;
    for (const auto& [c, v] : first_check->samples) {
      if (int(voxels.size()) >= samples) break;
      voxels.push_back(c);
      values.push_back(v);
    }
    const bench::MeshSampleCheck c =
        bench::checkMeshSamples(bench::sampleMesh(mesh, planned.grid, voxels), values, planned.grid.voxelSize(),
                                report.closed() && planned.plan.signedField(), bench::meshErrorBoundVoxels(planned.plan));
    fmt::print("accuracy on {} sampled voxels: {}\n", voxels.size(), c.describe());
    if (!c.ok() || voxels.empty())
      verdict.fail(name, planned.grid, voxels.empty() ? std::string("nothing delivered to sample") : c.describe());
    out["max_err_vox"] = c.max_err_voxels;
  }
  if (t1 == 0) {
    fmt::print(stderr, "scaling_bench: the model needs a 1-thread run (--threads 1,...)\n");
    return verdict.ok() ? 2 : bench::kExitWrong;
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
  out["pass"] = verdict.ok();
  const std::string line = out.dump();
  fmt::print("{}\n", line);
  if (!json_path.empty()) distband::bench::writeResultFile(json_path, line + "\n");
  return verdict.finish();
}

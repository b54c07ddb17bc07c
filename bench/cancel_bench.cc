// cancel_bench: how long each phase of a computation keeps running after its Interrupter trips (the service's goal:
// 100 ms at most, in every phase, at 1024^3 too). For each case the work runs once uncancelled, or until
// --max-run-s (a deadline on its Interrupter, so a 1024^3 full-domain run need not finish): its duration T. Then
// --samples times with a cancel from another thread at a random moment in [2 %, 98 %] of T (seeded, so runs
// are comparable). Two latencies: "compute stops", from cancel() until the computation has returned (no thread
// computes for it any more), and "returns", until the call has also freed its state (FieldRunResult::release_seconds:
// at 1024^3 that is GBs of bricks, whose release costs time in proportion, not compute).
//
//   build/bench/cancel_bench [--resolution 1024] [--threads 2] [--samples 10] [--max-run-s 30] [--cases all|a,b]
//                            [--mesh-dir DIR] [--smoke]
//
// Cases: mesh seeds with each sign method (armadillo if --mesh-dir has it, else the bunny; half-width 3), the band
// on two points (full domain: propagation, second-ring correction and emission in one segment; and in 8 segments),
// the band within a limit around a sphere shell volume (seeds and engine), and emission alone (segments of N/16, the
// consumer cancels from inside a chunk callback of one of the first segments, so the engine is mid-emission), and the
// separable EDTs the planner picks for whole-grid points and volumes (their state is freed inside the call: "compute
// stops" includes it). Every case is a FieldRequest planned and run as `distband compute` does (bench/planned_field.h);
// the band cases ask for it with an explicit stencil, and a case whose plan is not the algorithm it measures fails.
// Reference: none (this bench measures latency, not fields).
// Pass: every case plans as expected (else exit 1); goal (exit 3): the worst compute stop at most 100 ms.
// --smoke: 64^3, 2 samples a case, runs capped at 2 s, no results file.
// Output: a markdown table (median and max per case).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <tbb/task_arena.h>

#include "bench/bench_util.h"
#include "bench/planned_field.h"
#include "core/mesh/mesh_grid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/separable/point_edt.h"

namespace distband {
namespace {

using bench::Clock;
using bench::since;

struct Outcome {
  bool stopped = false;       // interrupted before the end
  double release_ms = 0;      // of the time to return: freeing the engine's state
};

struct Case {
  std::string name;
  /// Runs the work once with `interrupter` (never null).
  std::function<Outcome(Interrupter&)> run;
  /// Cancel from inside the work instead of at a random moment (emission).
  bool self_cancel = false;
};

int run(int argc, char** argv) {
  int resolution = 1024, threads = 2, samples = 10;
  double max_run_s = 30;
  std::string cases_arg = "all", mesh_dir = std::string(DISTBAND_BENCH_DIR) + "/../tests/data/meshes",
              tag = "cancel_bench";
  CLI::App app{"cancel_bench: CPU-stop latency after a cancel, per phase"};
  app.add_option("--resolution", resolution, "grid size N (N^3)")->capture_default_str();
  app.add_option("--threads", threads, "TBB threads")->capture_default_str();
  app.add_option("--samples", samples, "cancels per case")->capture_default_str();
  app.add_option("--max-run-s", max_run_s, "cap on the reference run of a case (seconds)")->capture_default_str();
  app.add_option("--cases", cases_arg, "all, or a comma-separated list");
  app.add_option("--mesh-dir", mesh_dir, "where armadillo.off (or bunny.obj) is");
  app.add_option("--tag", tag, "output name under bench/results/");
  bool smoke = false;
  app.add_flag("--smoke", smoke, "64^3, 2 samples, runs capped at 2 s, no results file (the CTest run)");
  CLI11_PARSE(app, argc, argv);
  if (smoke) {
    resolution = 64;
    samples = 2;
    max_run_s = 2;
  }
  tbb::task_arena arena(threads);
  const int n = resolution;

  TriangleMesh mesh;
  MeshReport report;
  std::string mesh_name = "armadillo.off";
  if (!loadMesh(mesh_dir + "/" + mesh_name, &mesh, &report).ok()) {
    mesh_name = "bunny.obj";
    if (Status e = loadMesh(mesh_dir + "/" + mesh_name, &mesh, &report); !e.ok()) {
      std::fprintf(stderr, "%s\n", e.toString().c_str());
      return 1;
    }
  }
  const Grid grid({0, 0, 0}, 1.0, {n, n, n});
  const std::vector<Vec3d> two_points = {{n * 0.31, n * 0.42, n * 0.53}, {n * 0.77, n * 0.18, n * 0.66}};
  std::shared_ptr<const std::vector<uint8_t>> shell;  // made on first use
  auto shellMask = [&] {
    if (!shell) shell = std::make_shared<const std::vector<uint8_t>>(bench::sphereShellMask(n));
    return shell;
  };
  Clock::time_point self_cancelled{};  // when a case cancelled itself from inside its callback
  std::vector<std::string> plan_errors;
  // Every case is planned as `distband compute` plans it (bench/planned_field.h); a case that measures the band
  // where the planner would take a separable EDT asks for the band's stencil explicitly.
  auto plan = [&](const FieldRequest& request, FieldAlgorithm expected) {
    bench::PlannedField p;
    MeshGridOptions go;
    go.resolution = n;
    const Status e = request.seeds == SeedKind::kMesh ? bench::planMeshField(request, mesh, report, go, &p)
                                                      : bench::planGridField(request, grid, &p);
    if (!e.ok()) plan_errors.push_back(e.toString());
    else if (p.plan.algorithm != expected)
      plan_errors.push_back(fmt::format("the planner picks {} where this case measures {}",
                                        algorithmName(p.plan.algorithm), algorithmName(expected)));
    return p;
  };
  auto pointsRequest = [&](bool band, double segment, double limit) {
    FieldRequest r;
    r.seeds = SeedKind::kPoints;
    r.point_layout = pointLayout(two_points);
    if (band) r.stencil = StencilKind::kCubic26;  // asks for the propagation itself
    r.segment_length_world = segment;
    r.limit_world = limit;
    return r;
  };
  auto shellRequest = [&](bool band, double limit) {
    FieldRequest r;
    r.seeds = SeedKind::kVolume;
    r.inside_negative = true;
    if (band) r.stencil = StencilKind::kCubic26;
    r.limit_world = limit;
    return r;
  };

  auto meshSeeds = [&](SignMethod sign) {
    FieldRequest r;
    r.seeds = SeedKind::kMesh;
    r.mesh_sign = sign;
    r.limit_voxels = 3;
    const bench::PlannedField planned = plan(r, FieldAlgorithm::kBand);
    return [&, planned](Interrupter& stop) {
      SeedSource source;
      source.mesh = &mesh;
      FieldInputs inputs;
      return Outcome{bench::buildPlannedInputs(planned, source, &stop, &inputs).code() == Status::Code::kCancelled};
    };
  };
  auto engine = [&](double segment, double limit, size_t chunk, std::function<bool(const SegmentBricks&)> cancel_in) {
    const bench::PlannedField planned = plan(pointsRequest(true, segment, limit), FieldAlgorithm::kBand);
    return [&, planned, chunk, cancel_in](Interrupter& stop) {
      SeedSource source;
      source.points = &two_points;
      bench::RunSettings settings;
      settings.max_chunk_bricks = chunk;
      settings.interrupter = &stop;
      const bench::PlannedRun r = bench::runPlannedField(planned, source, settings, [&](SegmentBricks&& s) {
        if (cancel_in && cancel_in(s)) {
          self_cancelled = Clock::now();
          stop.cancel();
        }
      });
      return Outcome{r.result.interrupted, r.result.release_seconds * 1000};
    };
  };
  // The volume's inputs and its run: with an explicit stencil the band, else the separable EDT the planner picks.
  auto shellCase = [&](bool band, double limit) {
    const bench::PlannedField planned =
        plan(shellRequest(band, limit), band ? FieldAlgorithm::kBand : FieldAlgorithm::kSeparable);
    return [&, planned](Interrupter& stop) {
      SeedSource source;
      source.volume = LabelVolume({n, n, n}, VoxelType::kUint8, shellMask());
      bench::RunSettings settings;
      settings.max_chunk_bricks = 1024;
      settings.interrupter = &stop;
      const bench::PlannedRun r = bench::runPlannedField(planned, source, settings, [](SegmentBricks&&) {});
      if (r.status.code() == Status::Code::kCancelled) return Outcome{true};
      return Outcome{r.result.interrupted, r.result.release_seconds * 1000};
    };
  };
  auto separablePoints = [&] {
    const bench::PlannedField planned = plan(pointsRequest(false, 0, std::numeric_limits<double>::infinity()),
                                             FieldAlgorithm::kSeparable);
    return [&, planned](Interrupter& stop) {
      SeedSource source;
      source.points = &two_points;
      bench::RunSettings settings;
      settings.max_chunk_bricks = 1024;
      settings.interrupter = &stop;
      return Outcome{bench::runPlannedField(planned, source, settings, [](SegmentBricks&&) {}).result.interrupted};
    };
  };
  int chunks_seen = 0;
  std::vector<Case> cases = {
      {"mesh seeds, pseudonormal", meshSeeds(SignMethod::kPseudonormal)},
      {"mesh seeds, winding number", meshSeeds(SignMethod::kWinding)},
      {"mesh seeds, parity (Embree)", meshSeeds(SignMethod::kParity)},
      {"engine, two points, full domain", engine(0, std::numeric_limits<double>::infinity(), 1024, {})},
      {"engine, two points, 8 segments", engine(n / 4.0, std::numeric_limits<double>::infinity(), 1024, {})},
      {"sphere shell volume, limit 5, band (seeds + engine)", shellCase(true, 5)},
      {"emission (cancelled inside the k-th chunk)",
       engine(n / 16.0, std::numeric_limits<double>::infinity(), 1024,
              [&](const SegmentBricks&) { return --chunks_seen == 0; }),
       true},
      {"separable point EDT, two points, full domain", separablePoints()},
      {"separable EDT, sphere shell volume (signed), full domain", shellCase(false, std::numeric_limits<double>::infinity())},
  };
  const std::vector<std::string> short_names = {"seeds_pseudonormal", "seeds_winding", "seeds_parity", "points_full",
                                                "points_segments", "shell_band", "emission", "separable_points",
                                                "separable_shell"};
  if (!plan_errors.empty()) {
    for (const std::string& e : plan_errors) std::fprintf(stderr, "cancel_bench: FAIL planning: %s\n", e.c_str());
    return bench::kExitWrong;
  }

  std::string md =
      fmt::format("# cancel_bench ({}^3, {} threads, {} samples per case, reference runs capped at {} s; mesh {})\n\n",
                  n, threads, samples, max_run_s, mesh_name);
  md += "| case | uncancelled run (s, capped) | compute stops: median (ms) | max (ms) | returns, state freed: median (ms) | "
        "max (ms) | stopped early |\n|---|---|---|---|---|---|---|\n";
  std::printf("%s", md.c_str());
  std::mt19937 rng(2026);
  double worst = 0, worst_return = 0;
  for (size_t c = 0; c < cases.size(); ++c) {
    if (cases_arg != "all" && ("," + cases_arg + ",").find("," + short_names[c] + ",") == std::string::npos) continue;
    const Case& kase = cases[c];
    double full_ms = 0;
    arena.execute([&] {
      Interrupter capped(Clock::now() +
                         std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(max_run_s)));
      chunks_seen = 1 << 30;
      const auto t0 = Clock::now();
      kase.run(capped);
      full_ms = 1000 * since(t0);
    });
    std::vector<double> latency, returned;
    int stopped = 0;
    for (int i = 0; i < samples; ++i) {
      Interrupter stop;
      const double at_ms = std::uniform_real_distribution<double>(0.02, 0.98)(rng) * full_ms;
      Clock::time_point cancelled{};
      std::thread canceller;
      if (kase.self_cancel) {
        chunks_seen = 1 + int(rng() % 64);
      } else {
        canceller = std::thread([&] {
          std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(at_ms));
          cancelled = Clock::now();
          stop.cancel();
        });
      }
      Outcome out;
      arena.execute([&] { out = kase.run(stop); });
      const auto end = Clock::now();
      if (canceller.joinable()) canceller.join();
      if (kase.self_cancel) cancelled = self_cancelled;
      if (!out.stopped) continue;  // finished before the cancel
      ++stopped;
      const double total = std::chrono::duration<double, std::milli>(end - cancelled).count();
      returned.push_back(total);
      latency.push_back(total - out.release_ms);
    }
    const double med = latency.empty() ? 0 : bench::median(latency);
    const double mx = latency.empty() ? 0 : *std::max_element(latency.begin(), latency.end());
    const double rmed = returned.empty() ? 0 : bench::median(returned);
    const double rmx = returned.empty() ? 0 : *std::max_element(returned.begin(), returned.end());
    worst = std::max(worst, mx);
    worst_return = std::max(worst_return, rmx);
    const std::string row = fmt::format("| {} | {:.2f} | {:.1f} | {:.1f} | {:.1f} | {:.1f} | {} / {} |\n", kase.name,
                                        full_ms / 1000, med, mx, rmed, rmx, stopped, samples);
    std::printf("%s", row.c_str());
    std::fflush(stdout);
    md += row;
  }
  md += fmt::format("\nWorst compute stop: {:.1f} ms (goal: at most 100 ms); worst return with the state freed: {:.1f} ms.\n",
                    worst, worst_return);
  std::printf("\nWorst compute stop: %.1f ms; worst return: %.1f ms\n", worst, worst_return);
  if (!smoke) distband::bench::writeResultFile(std::string(DISTBAND_BENCH_DIR) + "/results/" + tag + ".md", md);
  return worst <= 100 ? 0 : 3;
}

}  // namespace
}  // namespace distband

int main(int argc, char** argv) { return distband::run(argc, argv); }

// sparse_grid_bench: memory follows the band at any grid size. One point seed at the centre of an n^3 grid (voxel size
// 1, default n = 16384) with a distance limit of L voxels (default 50), planned and run like `distband compute
// --points` (bench/planned_field.h: FieldRequest -> planField -> buildFieldInputs -> computeField; with a limit the
// planner runs the band): seconds per run (median of --reps, inputs and the whole computeField call including the
// brick table's setup and release) and this process's peak RSS. Run it as its own process for a clean peak: it
// measures nothing else.
// Reference: the exact distance to the point (analytic), on every delivered voxel of the first run, and the count
// of voxels within the limit. The check keeps nothing (the peak RSS is the run's): one segment's bricks come in
// strictly increasing (z, y, x) order, so no voxel can come twice, and then the count proves none is missing.
// Pass: every delivered value within 1e-4 voxel of the float32-rounded exact distance, nothing beyond the limit,
// brick origins strictly increasing, as many voxels as lie within the limit (those within 1e-9 of it may go either
// way); else the exit status is 1 and the first bad voxel is named.
// Prints one JSON line: res, limit, threads, reps, median/min seconds, peak_rss_mb, voxels, bricks, max_err_vox, pass
// and a hash of the delivered bricks (origins, masks, value bits, in delivery order) for comparing builds bit for bit.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <tuple>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <tbb/info.h>

#include "bench/bench_util.h"
#include "bench/planned_field.h"
#include "core/grid.h"
#include "core/separable/point_edt.h"

int main(int argc, char** argv) {
  using namespace distband;
  int res = 16384, reps = 5, threads = 0;
  double limit = 50;
  CLI::App app("one point seed at the centre of an n^3 grid with a distance limit: time and peak RSS");
  app.add_option("--res", res, "grid resolution n (n^3 voxels)")->check(CLI::Range(8, kMaxGridDim));
  app.add_option("--limit", limit, "distance limit in voxels")->check(CLI::PositiveNumber);
  app.add_option("--reps,-R", reps, "repetitions; the median time is reported")->check(CLI::Range(1, 100));
  app.add_option("--threads", threads, "engine threads (0: all cores)")->check(CLI::Range(0, 256));
  CLI11_PARSE(app, argc, argv);

  bench::Verdict verdict("sparse_grid_bench");
  const Grid grid({0, 0, 0}, 1.0, {res, res, res});
  const double c = res / 2 + 0.25;  // off the lattice: no ties on the axes
  const std::vector<Vec3d> points = {{c, c, c}};
  FieldRequest request;
  request.seeds = SeedKind::kPoints;
  request.limit_voxels = limit;
  request.point_layout = pointLayout(points);
  bench::PlannedField planned;
  if (Status e = bench::planGridField(request, grid, &planned); !e.ok()) {
    std::fprintf(stderr, "%s\n", e.toString().c_str());
    return 2;
  }
  SeedSource source;
  source.points = &points;
  bench::RunSettings settings;
  settings.threads = threads;

  std::vector<double> seconds;
  int64_t voxels = 0, bricks = 0, first_voxels = 0;
  uint64_t hash = 1469598103934665603ull;  // FNV-1a over the delivered bricks
  auto mix = [&](const void* p, size_t n) {
    for (size_t i = 0; i < n; ++i) hash = (hash ^ static_cast<const uint8_t*>(p)[i]) * 1099511628211ull;
  };
  // The check (first run, outside the timing of later runs): exact distance of each delivered voxel to the point.
  double max_err = 0;
  int64_t beyond = 0, bad = 0;
  Coord first_bad{-1, -1, -1};
  float first_bad_value = 0;
  double first_bad_exact = 0;
  int64_t out_of_order = 0;
  Coord last_origin{-1, -1, -1};
  for (int r = 0; r < reps; ++r) {
    voxels = bricks = 0;
    const bool first = r == 0;
    const bench::PlannedRun run = bench::runPlannedField(planned, source, settings, [&](SegmentBricks&& seg) {
      for (const Brick& b : seg.bricks) {
        voxels += b.mask.count();
        ++bricks;
        if (!first) continue;
        out_of_order += std::tie(b.origin.z, b.origin.y, b.origin.x) <=
                        std::tie(last_origin.z, last_origin.y, last_origin.x);
        last_origin = b.origin;
        mix(&b.origin, sizeof(b.origin));
        mix(b.mask.words.data(), sizeof(b.mask.words));
        for (int off = 0; off < kBrickVoxels; ++off) {
          if (!b.mask.test(off)) continue;
          mix(&b.values[off], sizeof(float));
          const Coord v = b.origin + brickLocal(off);
          const double exact = (Vec3d{double(v.x), double(v.y), double(v.z)} - points[0]).length();
          if (exact > limit * (1 + 1e-9)) ++beyond;
          const double err = std::abs(double(b.values[off]) - double(float(exact)));
          max_err = std::max(max_err, err);
          if ((err > 1e-4 || exact > limit * (1 + 1e-9)) && bad++ == 0) {
            first_bad = v;
            first_bad_value = b.values[off];
            first_bad_exact = exact;
          }
        }
      }
    });
    if (!run.status.ok()) {
      std::fprintf(stderr, "%s\n", run.status.toString().c_str());
      return 1;
    }
    seconds.push_back(run.total_seconds);
    if (first) first_voxels = voxels;
  }
  // Voxels within the limit, counted on the lattice around the point (those within 1e-9 of the limit either way).
  int64_t within = 0, on_limit = 0;
  const int r0 = int(std::floor(c - limit)) - 1, r1 = int(std::ceil(c + limit)) + 1;
  for (int z = std::max(0, r0); z <= std::min(res - 1, r1); ++z)
    for (int y = std::max(0, r0); y <= std::min(res - 1, r1); ++y)
      for (int x = std::max(0, r0); x <= std::min(res - 1, r1); ++x) {
        const double d = (Vec3d{double(x), double(y), double(z)} - points[0]).length();
        within += d <= limit * (1 - 1e-9);
        on_limit += d > limit * (1 - 1e-9) && d <= limit * (1 + 1e-9);
      }
  const std::string name = fmt::format("one point, limit {} voxels", limit);
  if (bad)
    verdict.fail(name, grid, fmt::format("{} voxels wrong (max error {:.3g} voxel, {} beyond the limit); first at ({}, "
                                         "{}, {}): exact {:.9g}, got {:.9g}",
                                         bad, max_err, beyond, first_bad.x, first_bad.y, first_bad.z, first_bad_exact,
                                         first_bad_value));
  if (out_of_order)
    verdict.fail(name, grid, fmt::format("{} bricks out of (z, y, x) order in a single segment", out_of_order));
  if (first_voxels < within || first_voxels > within + on_limit)
    verdict.fail(name, grid, fmt::format("{} voxels delivered, {} lie within the limit ({} on it)", first_voxels,
                                         within, on_limit));
  const int used_threads = threads > 0 ? threads : tbb::info::default_concurrency();
  std::printf("%s\n", fmt::format("{{\"res\": {}, \"limit\": {}, \"threads\": {}, \"reps\": {}, \"algorithm\": \"{}\", "
                                  "\"median_s\": {:.4f}, \"min_s\": {:.4f}, \"peak_rss_mb\": {:.1f}, \"voxels\": {}, "
                                  "\"bricks\": {}, \"max_err_vox\": {:.3g}, \"pass\": {}, \"hash\": \"{:016x}\"}}",
                                  res, limit, used_threads, reps, algorithmName(planned.plan.algorithm),
                                  bench::median(seconds), *std::min_element(seconds.begin(), seconds.end()),
                                  bench::peakRssMb(), voxels, bricks, max_err, verdict.ok(), hash)
                          .c_str());
  return verdict.finish();
}

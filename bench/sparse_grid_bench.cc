// sparse_grid_bench: memory follows the band at any grid size (issue 11, goal 5). One point seed at the centre of an
// n^3 grid (voxel size 1, default n = 16384) with a distance limit of L voxels (default 50): seconds per run (median
// of --reps, whole computeBandField call including the brick table's setup and release) and this process's peak
// RSS. Run it as its own process for a clean peak: it measures nothing else.
// Prints one JSON line: res, limit, threads, reps, median/min seconds, peak_rss_mb, voxels, bricks and a hash of the
// delivered bricks (origins, masks, value bits, in delivery order) for comparing builds bit for bit.
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <tbb/global_control.h>
#include <tbb/info.h>

#include "core/band/band_engine.h"
#include "core/grid.h"
#include "core/seeds/point_seeds.h"

#include "bench/bench_util.h"

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

  const Grid grid({0, 0, 0}, 1.0, {res, res, res});
  const double c = res / 2 + 0.25;  // off the lattice: no ties on the axes
  BandOptions options;
  options.limit_world = limit;
  options.threads = threads;
  std::vector<double> seconds;
  int64_t voxels = 0, bricks = 0;
  uint64_t hash = 1469598103934665603ull;  // FNV-1a over the delivered bricks
  auto mix = [&](const void* p, size_t n) {
    for (size_t i = 0; i < n; ++i) hash = (hash ^ static_cast<const uint8_t*>(p)[i]) * 1099511628211ull;
  };
  for (int r = 0; r < reps; ++r) {
    Seeds seeds;
    const auto t0 = std::chrono::steady_clock::now();
    if (Status e = makePointSeeds(grid, {{c, c, c}}, &seeds); !e.ok()) {
      std::fprintf(stderr, "%s\n", e.toString().c_str());
      return 1;
    }
    voxels = bricks = 0;
    const bool first = r == 0;
    computeBandField(grid, std::move(seeds), options, [&](SegmentBricks&& seg) {
      for (const Brick& b : seg.bricks) {
        voxels += b.mask.count();
        ++bricks;
        if (first) {
          mix(&b.origin, sizeof(b.origin));
          mix(b.mask.words.data(), sizeof(b.mask.words));
          for (int off = 0; off < kBrickVoxels; ++off)
            if (b.mask.test(off)) mix(&b.values[off], sizeof(float));
        }
      }
    });
    seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  const int used_threads = threads > 0 ? threads : tbb::info::default_concurrency();
  std::printf("%s\n", fmt::format("{{\"res\": {}, \"limit\": {}, \"threads\": {}, \"reps\": {}, \"median_s\": {:.4f}, "
                                  "\"min_s\": {:.4f}, \"peak_rss_mb\": {:.1f}, \"voxels\": {}, \"bricks\": {}, "
                                  "\"hash\": \"{:016x}\"}}",
                                  res, limit, used_threads, reps, bench::median(seconds),
                                  *std::min_element(seconds.begin(), seconds.end()), bench::peakRssMb(), voxels,
                                  bricks, hash)
                          .c_str());
  return 0;
}

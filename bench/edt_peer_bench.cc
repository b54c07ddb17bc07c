// edt_peer_bench: the engine against seung-lab edt (`binary_edt`, separable and threaded: the fastest public CPU
// exact EDT) on the same seeds, in the same run.
//   * Cases: two points at 256³ and 512³, two seed voxels at 256³ and a sphere shell at 256³ and 512³ (full
//     domain), a sphere shell and 40 random blobs at 512³ with a limit of 5 voxels. edt has no limit: it always computes the whole grid, which is what a
//     limited query has to beat.
//   * distband is timed engine only (seeds built before the clock starts, output bricks dropped), edt whole (it has
//     no separate setup); each at the thread counts asked, medians of --reps runs, the peer in the same process.
//   * Every row is a FieldRequest planned and run as `distband compute` does (bench/planned_field.h): first as the
//     product plans it (the separable EDTs, core/separable/volume_edt.h for volumes and core/separable/point_edt.h
//     for the two points) and, unless --compare-band false, again with the band asked for through the request (an
//     explicit cubic26 stencil: the propagation, with the product's defaults otherwise).
//   * Reference: edt's exact result on every voxel (first repetition, when the peer runs).
//   * Pass: every delivered voxel within 1e-4 voxel of edt's value (every case here is exact: points, and volumes
//     with cubic26 without segments), every voxel within the limit delivered once, none beyond it; else the case,
//     the grid and the first bad voxel are printed and the exit status is 1. --smoke runs every case at 32^3, once,
//     on 2 threads.
//   * Label suite (--suite labels): label volumes (bench::labelRegions: 2, 100 and 10 000 labels) with spacings
//     0.5x0.5x2.5 and 1x1x1, with and without black border, against edt::edt at every voxel (<= 1e-5 relative);
//     timed at --label-n: 100 labels anisotropic (full field, and a limit of 5 voxels), 2 labels with the limit, and a
//     binary anisotropic volume against edt::binary_edt. edt's time is its best over the thread counts; goals (reported,
//     not checked): full fields <= 0.5x edt, limited ones <= max(0.1, the delivered voxel fraction) x edt's full field.
// The peer's header is read from ../shared/peers/edt (LGPL-3.0): it is built into this program, never copied into
// the repository. Writes a Markdown table to stdout and, with --json, the rows to a file.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <string>
#include <limits>
#include <type_traits>
#include <vector>

#include <CLI/CLI.hpp>
#include <edt.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "bench/bench_util.h"
#include "bench/planned_field.h"
#include "core/separable/point_edt.h"

namespace distband {
namespace {

using bench::Clock;
using bench::since;
using bench::median;

struct Case {
  std::string name;
  int n;
  double limit_voxels;  // infinity: full domain
  std::vector<uint8_t> (*mask)(int n);
  bool as_points = false;  // seed the engine with the mask's voxels as a point list (point seeds)
  /// The mask's voxels as points (index space = world space here: origin 0, voxel size 1).
  std::vector<Vec3d> points(int size) const {
    const std::vector<uint8_t> m = mask(size);
    std::vector<Vec3d> p;
    for (size_t i = 0; i < m.size(); ++i)
      if (m[i]) p.push_back({double(i % size), double(i / size % size), double(i / (size_t(size) * size))});
    return p;
  }
};

std::vector<uint8_t> twoVoxels(int n) {
  std::vector<uint8_t> m(size_t(n) * n * n, 0);
  m[(size_t(n / 4) * n + n / 3) * n + n / 5] = 1;
  m[(size_t(3 * n / 4) * n + 2 * n / 3) * n + 4 * n / 5] = 1;
  return m;
}

struct Row {
  std::string name, algorithm;
  int n = 0, threads = 0;
  double limit_voxels = 0;
  double distband_s = 0, edt_s = 0;
  double distband_cpu_s = 0, edt_cpu_s = 0;  // process CPU time (all threads): steadier than wall time when shared
  int64_t voxels = 0;  // distband: delivered
  double max_err_voxels = 0, exact_fraction = 0;
  int64_t updates = 0;
};

double processCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

/// The case as a request: the product's plan, or with `band` the propagation asked for by its stencil.
FieldRequest requestFor(const Case& c, bool band) {
  FieldRequest request;
  request.seeds = c.as_points ? SeedKind::kPoints : SeedKind::kVolume;
  request.limit_world = c.limit_voxels;  // voxel size 1
  if (c.as_points) request.point_layout = pointLayout(c.points(c.n));
  if (band) request.stencil = StencilKind::kCubic26;
  return request;
}

Row run(const Case& c, const bench::PlannedField& planned, int threads, int reps, bool peer, bench::Verdict& verdict) {
  const int n = c.n;
  const Grid& grid = planned.grid;
  const std::vector<uint8_t> mask = c.mask(n);
  const std::vector<Vec3d> points = c.as_points ? c.points(n) : std::vector<Vec3d>{};
  Row row;
  row.name = c.name;
  row.n = n;
  row.threads = threads;
  row.limit_voxels = c.limit_voxels;
  row.algorithm = std::string(algorithmName(planned.plan.algorithm));

  // The peer: distance of every non-seed voxel to the nearest seed voxel (edt measures foreground to background).
  std::vector<uint8_t> foreground(mask.size());
  for (size_t i = 0; i < mask.size(); ++i) foreground[i] = mask[i] ? 0 : 1;
  std::vector<float> exact;
  std::vector<double> edt_times, edt_cpu;
  for (int r = 0; r < reps && peer; ++r) {
    const auto t0 = Clock::now();
    const double cpu0 = processCpuSeconds();
    float* d = edt::binary_edt<uint8_t>(foreground.data(), n, n, n, 1.f, 1.f, 1.f, false, threads);
    edt_times.push_back(since(t0));
    edt_cpu.push_back(processCpuSeconds() - cpu0);
    if (r == 0) exact.assign(d, d + mask.size());
    delete[] d;
  }
  row.edt_s = peer ? median(edt_times) : NAN;
  row.edt_cpu_s = peer ? median(edt_cpu) : NAN;

  SeedSource source;
  source.points = &points;
  source.volume = LabelVolume({n, n, n}, VoxelType::kUint8,
                              std::shared_ptr<const std::vector<uint8_t>>(&mask, [](const std::vector<uint8_t>*) {}));
  bench::RunSettings settings;
  settings.threads = threads;
  settings.max_chunk_bricks = 4096;
  const std::string case_name = fmt::format("{} {}^3, {}, {} threads", c.name, n, row.algorithm, threads);
  std::vector<double> times, cpu;
  for (int r = 0; r < reps; ++r) {
    FieldInputs inputs;  // built before the clock: the engine alone is timed
    if (Status e = bench::buildPlannedInputs(planned, source, nullptr, &inputs); !e.ok())
      throw std::runtime_error(e.toString());
    int64_t exact_count = 0, voxels = 0, bad = 0, repeated = 0, outside = 0;
    double max_err = 0;
    Coord first_bad{-1, -1, -1};
    float first_bad_value = 0;
    const bool check = r == 0 && peer;
    std::vector<uint8_t> delivered(check ? mask.size() : 0, 0);
    const double limit = c.limit_voxels;
    const auto t0 = Clock::now();
    const double cpu0 = processCpuSeconds();
    double check_s = 0;
    auto consume = [&](SegmentBricks&& s) {
      if (!check) return;
      const auto c0 = Clock::now();
      for (const Brick& b : s.bricks)
        for (int i = 0; i < kBrickVoxels; ++i) {
          if (!b.mask.test(i)) continue;
          const Coord v = b.origin + brickLocal(i);
          if (!grid.contains(v)) {
            ++outside;
            continue;
          }
          const size_t k = size_t(grid.denseIndex(v));
          repeated += delivered[k]++ > 0;
          const double err = std::abs(double(b.values[i]) - exact[k]);
          max_err = std::max(max_err, err);
          exact_count += err <= 1e-4;
          if ((err > 1e-4 || exact[k] > limit * (1 + 1e-6)) && bad++ == 0) {
            first_bad = v;
            first_bad_value = b.values[i];
          }
          ++voxels;
        }
      check_s += since(c0);
    };
    const FieldRunResult result = bench::computePlanned(planned, std::move(inputs), settings, consume);
    times.push_back(since(t0) - check_s);
    cpu.push_back(processCpuSeconds() - cpu0 - check_s);
    row.voxels = result.voxels;
    if (check) {
      row.max_err_voxels = max_err;
      row.exact_fraction = voxels ? double(exact_count) / double(voxels) : 1.0;
      row.updates = result.updates;
      if (bad)
        verdict.fail(case_name, grid,
                     fmt::format("{} voxels off by more than 1e-4 voxel or beyond the limit (max error {:.3g}); first at "
                                 "({}, {}, {}): edt {:.9g}, got {:.9g}",
                                 bad, max_err, first_bad.x, first_bad.y, first_bad.z,
                                 exact[size_t(grid.denseIndex(first_bad))], first_bad_value));
      if (repeated || outside)
        verdict.fail(case_name, grid, fmt::format("{} voxels delivered twice, {} outside the grid", repeated, outside));
      int64_t missing = 0;
      Coord first_missing{-1, -1, -1};
      for (size_t k = 0; k < exact.size(); ++k)
        if (!delivered[k] && exact[k] < limit * (1 - 1e-6) && missing++ == 0)
          first_missing = {int(k % size_t(n)), int(k / size_t(n) % size_t(n)), int(k / (size_t(n) * size_t(n)))};
      if (missing)
        verdict.fail(case_name, grid, fmt::format("{} voxels within the limit not delivered; first at ({}, {}, {}): "
                                                  "edt {:.9g}", missing, first_missing.x, first_missing.y,
                                                  first_missing.z, exact[size_t(grid.denseIndex(first_missing))]));
    }
  }
  row.distband_s = median(times);
  row.distband_cpu_s = median(cpu);
  return row;
}

// ---- Label volumes and per-axis spacing: edt::edt (multi-label) and edt::binary_edt with anisotropy ----

struct LabelCase {
  std::string name;
  int n = 0;
  int labels = 0;         // regions of bench::labelRegions; 0: a binary case (random blobs, the seed field)
  Vec3d spacing{1, 1, 1};
  bool black_border = false;
  double limit_voxels = std::numeric_limits<double>::infinity();  // voxels of the smallest spacing
};

struct LabelRow {
  LabelCase c;
  int threads = 0;
  double distband_s = 0, edt_s = 0;   // edt: its best over the thread counts run (its full field, it has no limit)
  double distband_cpu_s = 0, edt_cpu_s = 0;  // process CPU time (all threads; edt: its run of the best wall time)
  int64_t voxels = 0;                 // distband: delivered
  double max_rel_err = 0;
};

/// edt's field for a case (edt::edt on the labels, edt::binary_edt on the blobs' complement), at `threads`.
std::vector<float> peerField(const LabelCase& c, const LabelVolume& volume, const std::vector<uint8_t>& foreground,
                             int threads) {
  const int n = c.n;
  const float wx = float(c.spacing.x), wy = float(c.spacing.y), wz = float(c.spacing.z);
  float* d = nullptr;
  if (c.labels == 0) {
    d = edt::binary_edt<uint8_t>(const_cast<uint8_t*>(foreground.data()), n, n, n, wx, wy, wz, c.black_border, threads);
  } else {
    d = volume.visit([&](const auto* labels) {
      using T = std::remove_cv_t<std::remove_pointer_t<decltype(labels)>>;
      return edt::edt<T>(const_cast<T*>(labels), n, n, n, wx, wy, wz, c.black_border, threads);
    });
  }
  std::vector<float> out(d, d + size_t(n) * n * n);
  delete[] d;
  return out;
}

LabelRow runLabelCase(const LabelCase& c, const std::vector<int>& threads, int reps, bool peer,
                      bench::Verdict& verdict) {
  const int n = c.n;
  const Grid grid({0, 0, 0}, c.spacing, {n, n, n});
  LabelVolume volume;
  std::vector<uint8_t> foreground;  // binary: edt measures its nonzero voxels to the nearest zero one (our seeds)
  if (c.labels > 0) {
    volume = bench::labelRegions(n, c.labels);
  } else {
    std::vector<uint8_t> blobs = bench::randomBlobsMask(n);
    foreground.resize(blobs.size());
    for (size_t i = 0; i < blobs.size(); ++i) foreground[i] = blobs[i] ? 0 : 1;
    volume = LabelVolume::ofMask({n, n, n}, std::move(blobs));
  }
  LabelRow row;
  row.c = c;
  // The peer, best over the thread counts; its first result is the reference.
  std::vector<float> exact;
  double edt_best = std::numeric_limits<double>::infinity();
  for (int t : threads)
    for (int r = 0; r < reps && peer; ++r) {
      const auto t0 = Clock::now();
      const double c0 = processCpuSeconds();
      std::vector<float> d = peerField(c, volume, foreground, t);
      if (since(t0) < edt_best) {
        edt_best = since(t0);
        row.edt_cpu_s = processCpuSeconds() - c0;
      }
      if (exact.empty()) exact = std::move(d);
    }
  row.edt_s = peer ? edt_best : NAN;
  // distband, as `distband compute --volume --labels [--black-border] --spacing ... [--limit-voxels]` plans it.
  FieldRequest request;
  request.seeds = SeedKind::kVolume;
  request.labels = c.labels > 0;
  request.black_border = c.black_border;
  if (std::isfinite(c.limit_voxels)) request.limit_voxels = c.limit_voxels;
  bench::PlannedField planned;
  const std::string case_name = fmt::format("{} {}^3", c.name, n);
  if (Status e = bench::planGridField(request, grid, &planned); !e.ok()) {
    verdict.fail(case_name, grid, "planning: " + e.toString());
    return row;
  }
  SeedSource source;
  source.volume = volume;
  bench::RunSettings settings;
  settings.threads = threads.back();
  settings.max_chunk_bricks = 4096;
  row.threads = settings.threads;
  const double limit = std::isfinite(c.limit_voxels) ? c.limit_voxels * grid.voxelSize() : INFINITY;
  std::vector<double> times, cpu;
  for (int r = 0; r < reps; ++r) {
    FieldInputs inputs;
    if (Status e = bench::buildPlannedInputs(planned, source, nullptr, &inputs); !e.ok()) {
      verdict.fail(case_name, grid, e.toString());
      return row;
    }
    const bool check = r == 0 && peer;
    std::vector<uint8_t> delivered(check ? exact.size() : 0, 0);
    int64_t bad = 0, repeated = 0;
    double max_rel = 0;
    Coord first_bad{-1, -1, -1};
    float first_bad_value = 0;
    double check_s = 0;
    const auto t0 = Clock::now();
    const double c0 = processCpuSeconds();
    auto consume = [&](SegmentBricks&& s) {
      if (!check) return;
      const auto c0 = Clock::now();
      for (const Brick& b : s.bricks)
        for (int i = 0; i < kBrickVoxels; ++i) {
          if (!b.mask.test(i)) continue;
          const Coord v = b.origin + brickLocal(i);
          const size_t k = size_t(grid.denseIndex(v));
          repeated += delivered[k]++ > 0;
          const double want = exact[k], err = std::abs(double(b.values[i]) - want);
          const double rel = err / std::max(1e-6, std::abs(want));
          max_rel = std::max(max_rel, want == 0 ? err : rel);
          if ((err > 1e-5 * std::abs(want) + 1e-6 || want > limit * (1 + 1e-6)) && bad++ == 0) {
            first_bad = v;
            first_bad_value = b.values[i];
          }
        }
      check_s += since(c0);
    };
    const FieldRunResult result = bench::computePlanned(planned, std::move(inputs), settings, consume);
    times.push_back(since(t0) - check_s);
    cpu.push_back(processCpuSeconds() - c0 - check_s);  // the check runs on the calling thread
    row.voxels = result.voxels;
    if (!check) continue;
    row.max_rel_err = max_rel;
    if (bad)
      verdict.fail(case_name, grid,
                   fmt::format("{} voxels off edt by more than 1e-5 relative or beyond the limit; first at ({}, {}, {}): "
                               "edt {:.9g}, got {:.9g}",
                               bad, first_bad.x, first_bad.y, first_bad.z, exact[size_t(grid.denseIndex(first_bad))],
                               first_bad_value));
    int64_t missing = 0;
    for (size_t k = 0; k < exact.size(); ++k) missing += !delivered[k] && exact[k] < limit * (1 - 1e-6);
    if (missing || repeated)
      verdict.fail(case_name, grid,
                   fmt::format("{} voxels within the limit not delivered, {} delivered twice", missing, repeated));
  }
  row.distband_s = median(times);
  row.distband_cpu_s = median(cpu);
  return row;
}

}  // namespace
}  // namespace distband

int main(int argc, char** argv) {
  using namespace distband;
  CLI::App app{"distband engine vs seung-lab edt (binary_edt) on the same seeds, same run"};
  std::vector<int> threads{1, 2};
  int reps = 3;
  std::string json_path, only;
  app.add_option("--threads", threads, "Thread counts to run (each case at each)")->expected(1, 8);
  app.add_option("--reps", reps, "Repetitions per measurement (median)");
  app.add_option("--case", only, "Run only the case with this name");
  app.add_option("--json", json_path, "Also write the rows as JSON");
  bool compare_band = true;
  app.add_option("--compare-band", compare_band, "Full-domain rows: also run the band engine forced (slow at 512³)");
  bool peer = true;
  app.add_option("--peer", peer, "Run edt (and check against it); false: distband alone, e.g. under a profiler");
  bool smoke = false;
  app.add_flag("--smoke", smoke, "every case at 32^3, once, on 2 threads (the CTest run)");
  std::string suite = "all";
  app.add_option("--suite", suite, "seeds (the binary cases), labels (label volumes and spacing) or all");
  int label_n = 512, exact_n = 128;
  app.add_option("--label-n", label_n, "N of the label suite's timed N^3 rows");
  app.add_option("--exact-n", exact_n, "N of the label suite's exactness rows (2, 100, 10000 labels; two spacings)");
  CLI11_PARSE(app, argc, argv);
  if (smoke) {
    threads = {2};
    reps = 1;
    label_n = exact_n = 32;
  }
  bench::Verdict verdict("edt_peer_bench");
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<Case> cases = {
      {"two points (point seeds), full domain", 256, inf, twoVoxels, true},
      {"two points (point seeds), full domain", 512, inf, twoVoxels, true},
      {"two seed voxels, full domain", 256, inf, twoVoxels},
      {"sphere shell, full domain", 256, inf, bench::sphereShellMask},
      {"sphere shell, full domain", 512, inf, bench::sphereShellMask},
      {"sphere band, limit 5 voxels", 512, 5, bench::sphereShellMask},
      {"random blobs, limit 5 voxels", 512, 5, bench::randomBlobsMask},
  };
  if (smoke) {  // one row per case name at 32^3
    std::vector<Case> small;
    for (Case c : cases)
      if (std::none_of(small.begin(), small.end(), [&](const Case& s) { return s.name == c.name; })) {
        c.n = 32;
        small.push_back(c);
      }
    cases = small;
  }
  nlohmann::json rows = nlohmann::json::array();
  if (suite != "labels")
    std::printf("| case | grid | distband algorithm | threads | distband engine s | edt s | ratio | voxels delivered | ns "
                "per voxel per thread | updates per voxel | max err (voxel) | exact | distband CPU s | edt CPU s "
                "|\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Case& c : cases) {
    if ((!only.empty() && c.name != only) || suite == "labels") continue;
    // The product's plan, then, where it is not the band, the band asked for by the request.
    const Grid grid({0, 0, 0}, 1.0, {c.n, c.n, c.n});
    std::vector<bench::PlannedField> plans(1);
    if (Status e = bench::planGridField(requestFor(c, false), grid, &plans[0]); !e.ok()) {
      verdict.fail(c.name, grid, "planning: " + e.toString());
      continue;
    }
    if (plans[0].plan.algorithm != FieldAlgorithm::kBand && compare_band) {
      plans.emplace_back();
      if (Status e = bench::planGridField(requestFor(c, true), grid, &plans[1]); !e.ok()) {
        verdict.fail(c.name, grid, "planning the band: " + e.toString());
        continue;
      }
    }
    for (const bench::PlannedField& planned : plans)
    for (int t : threads) {
      const Row r = run(c, planned, t, reps, peer, verdict);
      std::printf("| %s | %d³ | %s | %d | %.3f | %.3f | %.2f | %lld | %.0f | %.2f | %.3f | %.2f %% | %.3f | %.3f |\n", r.name.c_str(), r.n,
                  r.algorithm.c_str(), r.threads, r.distband_s, r.edt_s, r.distband_s / r.edt_s, (long long)r.voxels,
                  1e9 * r.distband_s * r.threads / double(std::max<int64_t>(1, r.voxels)),
                  double(r.updates) / double(std::max<int64_t>(1, r.voxels)), r.max_err_voxels, 100 * r.exact_fraction,
                  r.distband_cpu_s, r.edt_cpu_s);
      std::fflush(stdout);
      rows.push_back({{"case", r.name}, {"n", r.n}, {"algorithm", r.algorithm}, {"threads", r.threads},
                      {"limit_voxels", std::isfinite(r.limit_voxels) ? nlohmann::json(r.limit_voxels) : nlohmann::json()},
                      {"distband_s", r.distband_s}, {"edt_s", r.edt_s},
                      {"distband_cpu_s", r.distband_cpu_s}, {"edt_cpu_s", r.edt_cpu_s}, {"ratio", r.distband_s / r.edt_s},
                      {"voxels", r.voxels}, {"updates", r.updates}, {"max_err_voxels", r.max_err_voxels},
                      {"exact_fraction", r.exact_fraction}, {"reps", reps}});
    }
  }
  if (suite != "seeds") {
    // Label volumes and spacing: exact rows (every voxel against edt) at exact_n, timed rows at label_n; edt's time is
    // its best over the thread counts, distband runs at the last thread count.
    std::vector<LabelCase> label_cases;
    for (int labels : {2, 100, 10000})
      for (const Vec3d& s : {Vec3d{0.5, 0.5, 2.5}, Vec3d{1, 1, 1}})
        for (bool black : {false, true})
          label_cases.push_back({fmt::format("{} labels, spacing {}x{}x{}{}", labels, s.x, s.y, s.z,
                                             black ? ", black border" : ""),
                                 exact_n, labels, s, black});
    for (int labels : {2, 100})
      label_cases.push_back({fmt::format("{} labels, spacing 0.5x0.5x2.5, limit 5 voxels", labels), exact_n, labels,
                             {0.5, 0.5, 2.5}, false, 5});
    label_cases.push_back({"100 labels, spacing 0.5x0.5x2.5", label_n, 100, {0.5, 0.5, 2.5}, false});
    label_cases.push_back({"100 labels, spacing 0.5x0.5x2.5, limit 5 voxels", label_n, 100, {0.5, 0.5, 2.5}, false, 5});
    label_cases.push_back({"2 labels, spacing 0.5x0.5x2.5, limit 5 voxels", label_n, 2, {0.5, 0.5, 2.5}, false, 5});
    label_cases.push_back({"binary (40 blobs), spacing 0.5x0.5x2.5", label_n, 0, {0.5, 0.5, 2.5}, false});
    std::printf(
        "\n| label case | grid | threads | distband s | edt s (best of its threads, full field) | ratio | voxels "
        "delivered | band fraction | goal | max rel err vs edt | distband CPU s | edt CPU s |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (const LabelCase& c : label_cases) {
      if (!only.empty() && c.name != only) continue;
      const LabelRow r = runLabelCase(c, threads, reps, peer, verdict);
      const double fraction = double(r.voxels) / (double(c.n) * c.n * c.n);
      const double goal = std::isfinite(c.limit_voxels) ? std::max(0.1, fraction) : 0.5;
      std::printf("| %s | %d³ | %d | %.3f | %.3f | %.3f | %lld | %.3f | <= %.2f | %.2e | %.3f | %.3f |\n",
                  c.name.c_str(), c.n, r.threads, r.distband_s, r.edt_s, r.distband_s / r.edt_s, (long long)r.voxels,
                  fraction, goal, r.max_rel_err, r.distband_cpu_s, r.edt_cpu_s);
      std::fflush(stdout);
      rows.push_back(
          {{"case", c.name},
           {"n", c.n},
           {"labels", c.labels},
           {"threads", r.threads},
           {"spacing", {c.spacing.x, c.spacing.y, c.spacing.z}},
           {"black_border", c.black_border},
           {"limit_voxels", std::isfinite(c.limit_voxels) ? nlohmann::json(c.limit_voxels) : nlohmann::json()},
           {"distband_s", r.distband_s},
           {"edt_best_s", r.edt_s},
           {"ratio", r.distband_s / r.edt_s},
           {"voxels", r.voxels},
           {"band_fraction", fraction},
           {"goal_ratio", goal},
           {"max_rel_err", r.max_rel_err},
           {"distband_cpu_s", r.distband_cpu_s},
           {"edt_cpu_s", r.edt_cpu_s},
           {"reps", reps}});
    }
  }
  if (!json_path.empty()) distband::bench::writeResultFile(json_path, rows.dump(2) + "\n");
  return verdict.finish();
}

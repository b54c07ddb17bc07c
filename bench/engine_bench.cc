// engine_bench: the SMI 2009 paper's mesh-free Table 1 rows, its Fig. 7, random points, seed volumes and the
// sparse-memory case, each against an exact oracle and against scipy's exact EDT (the peer) timed in the same run.
//
// Contract:
//   * Driver mode (no --case): builds the list of rows, runs scipy once per distinct input (bench/scipy_edt.py
//     as a subprocess) and every row in its own child process (this binary with --case ..., under
//     /usr/bin/time -v when present), so each row's peak RSS is its own. Writes <out-dir>/<tag>.json (one object
//     per row) and <out-dir>/<tag>.md, rewritten after every row so an interrupted run keeps what it measured.
//     Exits 1 when any row failed its check or could not run, after listing them.
//   * Case mode (--case NAME --res N ...): runs one row in this process and prints one JSON line on stdout.
//     Each row is a FieldRequest (its stencil, mode, segment length and limit; the explicit stencil asks for the
//     band) planned and run as `distband compute` plans it (bench/planned_field.h). The timed region of a
//     repetition is: build the inputs (buildFieldInputs), allocate the output, run computeField with a callback that
//     consumes every delivered brick (a DenseField, or for the memory case an analytic check that keeps nothing).
//     The memory case's seeds are custom (one off-lattice site per band voxel: no request expresses them), run with
//     the plan of the same request. peak_rss_mb is getrusage's high-water mark taken right after the timed
//     repetitions, before any oracle is built.
//   * Errors are in voxels, against an oracle sharing no code with the engine: brute force over the point list,
//     an exact separable EDT (Felzenszwalb–Huttenlocher) for volumes, the exact distance to the seed sites for the
//     memory case. The output format is float32, so the reference is the exact double rounded to float32 (the best
//     float answer); frac_off counts voxels off by more than 1e-4 voxel.
//   * Pass (errorBound): max error within the row's documented bound, every voxel within the limit delivered, once,
//     none beyond it; else the row prints its JSON with "pass": false and the worst voxel, and exits 1.
//   * --smoke: every input at 32^3 (the memory case at 64^3), two stencils, both modes, once (the CTest run).
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include "core/band/band_engine.h"
#include "core/grid.h"
#include "core/io/dense_field.h"
#include "core/io/npy.h"
#include "core/seeds/seeds.h"
#include "core/separable/point_edt.h"
#include "core/stencil.h"

#include "bench/bench_util.h"
#include "bench/planned_field.h"
#include "tests/support/exact_edt.h"

namespace distband {
namespace {

using json = nlohmann::json;
using bench::peakRssMb;
using bench::runCommand;
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr float kUndelivered = -1.0f;  // DenseField background: no voxel the engine delivers is negative here
constexpr double kOffTolerance = 1e-4;

// ---------------------------------------------------------------------------------------------------------
// Inputs. Deterministic functions of (case, resolution), so the driver (which writes scipy's mask) and the
// child (which builds the engine's seeds) see the same input. Voxel size 1, origin 0: world = index space.

struct Input {
  std::vector<Vec3d> points;  // point cases (world = index coordinates)
  std::vector<uint8_t> mask;  // volume cases, x-fastest
  bool volume = false;
};

bool isPointCase(const std::string& c) { return c == "one_point" || c == "two_points" || c == "random100"; }
bool isVolumeCase(const std::string& c) { return c == "sphere_shell" || c == "random_blobs"; }
bool isKnownCase(const std::string& c) { return isPointCase(c) || isVolumeCase(c) || c == "sphere_band"; }

Input makeInput(const std::string& kase, int n) {
  Input in;
  if (kase == "one_point") {
    // The paper's one-point case: a single point at the centre voxel.
    in.points = {{double(n / 2), double(n / 2), double(n / 2)}};
  } else if (kase == "two_points") {
    // Two points at 1/3 and 2/3 of the main diagonal (voxel centres, so scipy sees the same input).
    const double a = std::round((n - 1) / 3.0), b = std::round(2.0 * (n - 1) / 3.0);
    in.points = {{a, a, a}, {b, b, b}};
  } else if (kase == "random100") {
    // 100 points uniform in the box at continuous (off-grid) positions: general Voronoi boundaries.
    std::mt19937_64 rng(2009);
    std::uniform_real_distribution<double> u(0.0, n - 1.0);
    for (int i = 0; i < 100; ++i) {
      const double x = u(rng), y = u(rng), z = u(rng);
      in.points.push_back({x, y, z});
    }
  } else if (kase == "sphere_shell" || kase == "random_blobs") {
    in.volume = true;
    in.mask = kase == "sphere_shell" ? bench::sphereShellMask(n) : bench::randomBlobsMask(n);
  }
  return in;
}

/// The scipy peer's input: the mask itself, or for point cases the voxel nearest each point.
std::vector<uint8_t> peerMask(const Input& in, int n) {
  if (in.volume) return in.mask;
  std::vector<uint8_t> mask(size_t(n) * n * n, 0);
  for (const Vec3d& p : in.points) {
    auto r = [n](double v) { return int(std::clamp(std::lround(v), 0L, long(n - 1))); };
    mask[(size_t(r(p.z)) * n + r(p.y)) * n + r(p.x)] = 1;
  }
  return mask;
}

// The memory case: a sphere of radius 25/64 n (100, 200, 400 voxels at 256, 512, 1024) given as its sparse band
// of voxels within kSphereBandTau = sqrt(3)/2 of the surface (the voxels whose cell can meet the sphere), each with
// its own site = its projection onto the sphere (a valid custom kPoint seed source). A dense 1024^3 mask would be
// 1 GiB by itself.
constexpr double kSphereBandTau = 0.8660254037844386;

struct Sphere {
  Vec3d c;
  double r;
};

Sphere benchSphere(int n) { return {{0.5 * n + 0.125, 0.5 * n - 0.375, 0.5 * n + 0.0625}, n * 25.0 / 64.0}; }

/// Calls f(x, y, z) for every voxel of the n^3 box within `tau` of the sphere surface (row by row, so the cost
/// is proportional to the band, not to the box).
template <typename F>
void forEachNearSphere(int n, const Sphere& s, double tau, F&& f) {
  const double ro = s.r + tau, ri = std::max(0.0, s.r - tau);
  const int z0 = std::max(0, int(std::ceil(s.c.z - ro))), z1 = std::min(n - 1, int(std::floor(s.c.z + ro)));
  for (int z = z0; z <= z1; ++z) {
    const double dz = z - s.c.z;
    const double ry = std::sqrt(std::max(0.0, ro * ro - dz * dz));
    const int y0 = std::max(0, int(std::ceil(s.c.y - ry))), y1 = std::min(n - 1, int(std::floor(s.c.y + ry)));
    for (int y = y0; y <= y1; ++y) {
      const double dy = y - s.c.y, q = dy * dy + dz * dz;
      if (q > ro * ro) continue;
      const double xo = std::sqrt(ro * ro - q), xi = std::sqrt(std::max(0.0, ri * ri - q));
      // Candidate runs [c-xo, c-xi] and [c+xi, c+xo], widened by one voxel and merged when they meet; each
      // candidate is tested exactly.
      int a0 = int(std::ceil(s.c.x - xo)), a1 = int(std::floor(s.c.x - xi)) + 1;
      int b0 = int(std::ceil(s.c.x + xi)) - 1, b1 = int(std::floor(s.c.x + xo));
      std::array<std::pair<int, int>, 2> runs{{{a0, a1}, {b0, b1}}};
      int nruns = 2;
      if (a1 >= b0) {
        runs[0] = {a0, b1};
        nruns = 1;
      }
      for (int k = 0; k < nruns; ++k)
        for (int x = std::max(0, runs[k].first); x <= std::min(n - 1, runs[k].second); ++x) {
          const double d = (Vec3d{double(x), double(y), double(z)} - s.c).length();
          if (std::abs(d - s.r) <= tau) f(x, y, z, d);
        }
    }
  }
}

Seeds sphereBandSeeds(int n, const Sphere& s) {
  Seeds seeds;
  seeds.kind = SiteKind::kPoint;
  size_t count = 0;  // reserve exactly: vector growth would double the seeds' peak memory
  forEachNearSphere(n, s, kSphereBandTau, [&](int, int, int, double) { ++count; });
  seeds.band.reserve(count);
  seeds.points.reserve(count);
  forEachNearSphere(n, s, kSphereBandTau, [&](int x, int y, int z, double d) {
    const Vec3d p{double(x), double(y), double(z)};
    seeds.band.push_back({{x, y, z}, static_cast<uint32_t>(seeds.points.size())});
    seeds.points.push_back(s.c + (p - s.c) * (s.r / d));
  });
  return seeds;
}

// ---------------------------------------------------------------------------------------------------------
// Oracles (no code shared with the engine).

/// Exact Euclidean distance of every voxel of an n^3 box to the nearest nonzero mask voxel (x-fastest): the
/// test suite's exact EDT (tests/support/exact_edt.h), which shares no code with the engine.
std::vector<double> exactEdt(const std::vector<uint8_t>& mask, int n) {
  std::vector<double> d = oracle::edtSqr(n, n, n, mask);
  for (double& v : d) v = std::sqrt(v);
  return d;
}

/// Exact distance from voxel q to the nearest of `points`, searching the sites within `radius` through a
/// sorted cell index (cell size kCell). Returns +inf when no site lies within the searched cells.
class SiteIndex {
 public:
  static constexpr int kCell = 4;
  explicit SiteIndex(const std::vector<Vec3d>& points) : points_(points) {
    order_.resize(points.size());
    for (uint32_t i = 0; i < order_.size(); ++i) order_[i] = {cellKey(cellOf(points[i])), i};
    std::sort(order_.begin(), order_.end());
  }
  double nearest(const Vec3d& q, double radius) const {
    double best = kInf;
    const Coord lo = cellOf(q - Vec3d{radius, radius, radius}), hi = cellOf(q + Vec3d{radius, radius, radius});
    for (int z = lo.z; z <= hi.z; ++z)
      for (int y = lo.y; y <= hi.y; ++y)
        for (int x = lo.x; x <= hi.x; ++x) {
          const uint64_t key = cellKey({x, y, z});
          auto it = std::lower_bound(order_.begin(), order_.end(), std::pair<uint64_t, uint32_t>{key, 0});
          for (; it != order_.end() && it->first == key; ++it)
            best = std::min(best, (q - points_[it->second]).lengthSqr());
        }
    return std::sqrt(best);
  }

 private:
  static Coord cellOf(const Vec3d& p) {
    return {int(std::floor(p.x / kCell)), int(std::floor(p.y / kCell)), int(std::floor(p.z / kCell))};
  }
  static uint64_t cellKey(const Coord& c) {
    return (uint64_t(uint32_t(c.z + (1 << 20))) << 42) | (uint64_t(uint32_t(c.y + (1 << 20))) << 21) |
           uint64_t(uint32_t(c.x + (1 << 20)));
  }
  const std::vector<Vec3d>& points_;
  std::vector<std::pair<uint64_t, uint32_t>> order_;
};

/// Deterministic 1-in-64 voxel sample for the memory case's site-set oracle.
inline bool sampled(const Coord& c) {
  const uint32_t h = uint32_t(c.x) * 73856093u ^ uint32_t(c.y) * 19349663u ^ uint32_t(c.z) * 83492791u;
  return ((h >> 7) & 63) == 0;
}

struct ErrorStats {
  double max_err = 0, sum_err = 0;
  int64_t compared = 0, off = 0, missing = 0, beyond_limit = 0, delivered = 0;
  Coord worst{-1, -1, -1};  // the voxel with the largest error (lowest z, y, x among equals), for bug reports
  double worst_exact = 0;
  float worst_value = 0;
  void merge(const ErrorStats& o) {
    if (o.max_err > max_err || (o.max_err == max_err && o.max_err > 0 &&
                                std::tie(o.worst.z, o.worst.y, o.worst.x) < std::tie(worst.z, worst.y, worst.x))) {
      worst = o.worst;
      worst_exact = o.worst_exact;
      worst_value = o.worst_value;
    }
    max_err = std::max(max_err, o.max_err);
    sum_err += o.sum_err;
    compared += o.compared;
    off += o.off;
    missing += o.missing;
    beyond_limit += o.beyond_limit;
    delivered += o.delivered;
  }
  /// One voxel: `exact` in voxels (double), `value` as delivered (kUndelivered if not).
  void add(double exact, float value, double limit, const Coord& c = {-1, -1, -1}) {
    const bool got = value != kUndelivered;
    delivered += got;
    if (exact > limit * (1 + 1e-9)) {
      beyond_limit += got;  // the contract: nothing beyond the limit is delivered
      return;
    }
    if (exact > limit * (1 - 1e-9)) return;  // on the limit within rounding: either answer is fine
    ++compared;
    if (!got) {
      ++missing;
      return;
    }
    const double err = std::abs(double(value) - double(float(exact)));
    if (err > max_err) {
      worst = c;
      worst_exact = exact;
      worst_value = value;
    }
    max_err = std::max(max_err, err);
    sum_err += err;
    off += err > kOffTolerance;
  }
};

/// Compares a dense field (x-fastest, n^3) with exact(i) for every voxel, in parallel over z.
template <typename ExactFn>
ErrorStats compareDense(const std::vector<float>& field, int n, double limit, ExactFn&& exact) {
  return tbb::parallel_reduce(
      tbb::blocked_range<int>(0, n), ErrorStats{},
      [&](const tbb::blocked_range<int>& r, ErrorStats acc) {
        for (int z = r.begin(); z < r.end(); ++z)
          for (int y = 0; y < n; ++y)
            for (int x = 0; x < n; ++x) {
              const size_t i = (size_t(z) * n + y) * n + x;
              acc.add(exact(x, y, z, i), field[i], limit, {x, y, z});
            }
        return acc;
      },
      [](ErrorStats a, const ErrorStats& b) {
        a.merge(b);
        return a;
      });
}

json jsonNumberOrNull(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

// ---------------------------------------------------------------------------------------------------------
// Case mode: one row in this process.

struct CaseSpec {
  std::string kase;
  int res = 64;
  std::string stencil = "cubic26";
  std::string mode = "exact";
  double segment = 0;  // 0: none
  double limit = kInf;
  int threads = 2;
  int reps = 3;
};

/// The largest error (voxels, against the exact distance rounded to float32) the docs state for a row
/// (docs/algorithm.md section 5, docs/benchmarks.md): exact mode is exact for points and the random blobs with every
/// stencil, with and without segments; the sphere shell is within 0.04 (0.028-0.035 measured at 256^3); the memory
/// case's dense off-lattice sites within 0.07 (0.065). Paper mode: points within 0.1 (0.094), volumes within 0.35
/// (0.33), the memory case within 0.2 (0.17).
double errorBound(const CaseSpec& s) {
  const bool exact = s.mode == "exact";
  if (s.kase == "sphere_band") return exact ? 0.07 : 0.2;
  if (isPointCase(s.kase)) return exact ? kOffTolerance : 0.1;
  if (s.kase == "random_blobs") return exact ? kOffTolerance : 0.35;
  return exact ? 0.04 : 0.35;
}

int runCase(const CaseSpec& spec) {
  const std::optional<StencilKind> stencil = parseStencil(spec.stencil);
  PropagationMode mode;
  if (!stencil || !parseMode(spec.mode, &mode) || !isKnownCase(spec.kase) || spec.res < 8 || spec.reps < 1) {
    std::cerr << "bad case spec (case, stencil, mode, res >= 8, reps >= 1)\n";
    return 2;
  }
  const int n = spec.res;
  const bool memory_case = spec.kase == "sphere_band";
  const Sphere sphere = benchSphere(n);
  Input input;
  if (!memory_case) input = makeInput(spec.kase, n);
  // The row as a request, planned as `distband compute` plans it; the explicit stencil asks for the band.
  FieldRequest request;
  request.seeds = input.volume ? SeedKind::kVolume : SeedKind::kPoints;
  request.stencil = *stencil;
  request.mode = mode;
  request.segment_length_world = spec.segment;  // voxel size 1: world units are voxels
  request.limit_world = spec.limit;
  if (!input.volume && !memory_case) request.point_layout = pointLayout(input.points);
  bench::PlannedField planned;
  if (Status why = bench::planGridField(request, Grid({0, 0, 0}, 1.0, {n, n, n}), &planned); !why.ok()) {
    std::cerr << "invalid request: " << why.toString() << "\n";
    return 2;
  }
  const Grid& grid = planned.grid;
  if (Status why = validateRunOptions(grid, planned.plan.runOptions()); !why.ok()) {
    std::cerr << "invalid options: " << why.toString() << "\n";
    return 2;
  }
  if (planned.plan.algorithm != FieldAlgorithm::kBand) {
    std::cerr << "the planner does not run the band for an explicit stencil\n";
    return bench::kExitWrong;
  }
  SeedSource source;
  source.points = &input.points;
  if (!input.mask.empty())  // volume cases
    source.volume = LabelVolume({n, n, n}, VoxelType::kUint8, std::shared_ptr<const std::vector<uint8_t>>(
                                                                   &input.mask, [](const std::vector<uint8_t>*) {}));
  bench::RunSettings settings;
  settings.threads = spec.threads;

  std::vector<double> times;
  FieldRunResult last;
  std::vector<float> field;  // the last repetition's output (dense cases)
  ErrorStats analytic;       // memory case: checked inside the callback, nothing kept ...
  std::vector<std::pair<Coord, float>> sample;  // ... but a 1-in-64 sample for the exact site-set check
  size_t band_voxels = 0, max_segment_bricks = 0;
  int64_t written = 0;  // dense cases: voxel writes of the last repetition, repeats included
  for (int rep = 0; rep < spec.reps; ++rep) {
    field.clear();
    field.shrink_to_fit();
    analytic = {};
    sample.clear();
    max_segment_bricks = 0;
    const auto t0 = std::chrono::steady_clock::now();
    FieldInputs inputs;
    if (memory_case) {
      // No request expresses these seeds (one site per band voxel, off the lattice): the plan's run on custom inputs.
      inputs.seeds = sphereBandSeeds(n, sphere);
    } else if (Status err = bench::buildPlannedInputs(planned, source, nullptr, &inputs); !err.ok()) {
      std::cerr << "seeds: " << err.toString() << "\n";
      return 1;
    }
    band_voxels = inputs.seeds.band.size();
    std::optional<DenseField> dense;
    if (!memory_case) dense.emplace(grid, kUndelivered);
    last = bench::computePlanned(planned, std::move(inputs), settings, [&](SegmentBricks&& seg) {
      max_segment_bricks = std::max(max_segment_bricks, seg.bricks.size());
      if (dense) {
        dense->add(seg);
        return;
      }
      for (const Brick& b : seg.bricks)
        for (int i = 0; i < kBrickVoxels; ++i) {
          if (!b.mask.test(i)) continue;
          const Coord c = b.origin + brickLocal(i);
          const double exact = std::abs((Vec3d{double(c.x), double(c.y), double(c.z)} - sphere.c).length() - sphere.r);
          analytic.add(exact, b.values[i], kInf);
          if (sampled(c)) sample.push_back({c, b.values[i]});
        }
    });
    times.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    if (dense) {
      written = dense->written();
      field = std::move(dense->values());
    }
  }
  const double rss = peakRssMb();

  json row;
  row["case"] = spec.kase;
  row["resolution"] = n;
  row["stencil"] = spec.stencil;
  row["mode"] = spec.mode;
  row["segment"] = spec.segment > 0 ? json(spec.segment) : json(nullptr);
  row["limit"] = jsonNumberOrNull(spec.limit);
  row["threads"] = spec.threads;
  row["reps"] = spec.reps;
  row["time_s"] = bench::median(times);
  row["times_s"] = times;
  row["engine_s"] = last.seconds;
  row["steps"] = last.steps;
  row["voxels"] = last.voxels;
  row["updates"] = last.updates;
  row["corrections"] = last.corrections;
  row["bricks_allocated"] = last.bricks_allocated;
  row["band_voxels"] = band_voxels;
  row["max_segment_bricks"] = max_segment_bricks;
  row["peak_rss_mb"] = rss;
  json segs = json::array();
  for (const SegmentStats& s : last.segments)
    segs.push_back({{"index", s.index}, {"lower", s.lower_world}, {"upper", s.upper_world}, {"voxels", s.voxels},
                    {"steps", s.steps}, {"seconds", s.seconds}});
  row["segments"] = segs;

  ErrorStats st;
  if (memory_case) {
    // The engine's error: exact distance to the seed sites (brute force over the sites near each voxel) on a
    // deterministic 1-in-64 sample of the delivered voxels. The distance to the true sphere differs from it by
    // the sampling of the sphere by sites, reported apart as max_err_vs_sphere_vox.
    const Seeds seeds = sphereBandSeeds(n, sphere);
    const SiteIndex index(seeds.points);
    st = tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, sample.size(), 1024), ErrorStats{},
        [&](const tbb::blocked_range<size_t>& r, ErrorStats acc) {
          for (size_t i = r.begin(); i != r.end(); ++i) {
            const Coord c = sample[i].first;
            const double exact = index.nearest({double(c.x), double(c.y), double(c.z)}, spec.limit + 2.0);
            acc.add(exact, sample[i].second, spec.limit, c);
          }
          return acc;
        },
        [](ErrorStats a, const ErrorStats& b) {
          a.merge(b);
          return a;
        });
    row["max_err_vs_sphere_vox"] = analytic.max_err;
    row["mean_err_vs_sphere_vox"] = analytic.compared ? analytic.sum_err / double(analytic.compared) : 0.0;
    // Voxels within the limit of the sphere, counted analytically (the sites lie on the sphere, so the voxels
    // within the limit of the sites are a subset: a few at the rim are slightly farther from the sites).
    int64_t within = 0;
    forEachNearSphere(n, sphere, spec.limit, [&](int, int, int, double) { ++within; });
    row["voxels_within_limit"] = within;
    row["oracle"] = "exact distance to the seed sites on a 1-in-64 sample of the delivered voxels";
  } else if (input.volume) {
    const std::vector<double> exact = exactEdt(input.mask, n);
    st = compareDense(field, n, spec.limit, [&](int, int, int, size_t i) { return exact[i]; });
    row["oracle"] = "exact EDT (Felzenszwalb-Huttenlocher)";
  } else {
    const std::vector<Vec3d>& pts = input.points;
    st = compareDense(field, n, spec.limit, [&](int x, int y, int z, size_t) {
      double best = kInf;
      const Vec3d p{double(x), double(y), double(z)};
      for (const Vec3d& q : pts) best = std::min(best, (p - q).lengthSqr());
      return std::sqrt(best);
    });
    row["oracle"] = "brute force over the point list";
  }
  row["max_err_vox"] = st.max_err;
  row["mean_err_vox"] = st.compared ? st.sum_err / double(st.compared) : 0.0;
  row["frac_off"] = st.compared ? double(st.off) / double(st.compared) : 0.0;
  row["compared_voxels"] = st.compared;
  if (st.max_err > 0)
    row["worst_voxel"] = {{"x", st.worst.x}, {"y", st.worst.y}, {"z", st.worst.z}, {"value", st.worst_value},
                          {"exact", st.worst_exact}};
  row["missing"] = st.missing;
  row["beyond_limit"] = st.beyond_limit;
  row["delivered_unique"] = memory_case ? analytic.delivered : st.delivered;
  // Pass/fail against the bound the docs state for this row.
  const double bound = errorBound(spec);
  std::string failure;
  if (st.max_err > bound)
    failure = fmt::format("max error {:.6g} voxel over the bound {:g}; worst voxel ({}, {}, {}): exact {:.9g}, got {:.9g}",
                          st.max_err, bound, st.worst.x, st.worst.y, st.worst.z, st.worst_exact, st.worst_value);
  else if (st.missing || st.beyond_limit)
    failure = fmt::format("{} voxels within the limit not delivered, {} delivered beyond it", st.missing,
                          st.beyond_limit);
  else if (!memory_case && written != st.delivered)
    failure = fmt::format("{} voxel deliveries for {} voxels: some came more than once", written, st.delivered);
  else if (memory_case && analytic.delivered != last.voxels)
    failure = fmt::format("the run reports {} voxels, {} were delivered", last.voxels, analytic.delivered);
  row["bound_vox"] = bound;
  row["pass"] = failure.empty();
  if (!failure.empty()) row["failure"] = failure;
  std::cout << row.dump() << std::endl;
  if (!failure.empty()) {
    std::cerr << fmt::format("engine_bench: FAIL {} {}^3 {} {} seg={} limit={}: {}\n", spec.kase, n, spec.stencil,
                             spec.mode, spec.segment, spec.limit, failure);
    return bench::kExitWrong;
  }
  return 0;
}

// ---------------------------------------------------------------------------------------------------------
// Driver mode.

struct Row {
  CaseSpec spec;
  std::vector<std::string> groups;
};

std::string rowKey(const CaseSpec& s) {
  return fmt::format("{}|{}|{}|{}|{}|{}", s.kase, s.res, s.stencil, s.mode, s.segment, s.limit);
}

std::vector<std::string> splitList(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

struct DriverOptions {
  bool quick = false;
  bool smoke = false;  // the CTest run: tiny rows, results in the temporary directory unless --out-dir is given
  int reps = 3;
  int big_reps = -1;  // repetitions for rows at 256^3 and above; < 0: same as reps
  int threads = 2;
  std::string out_dir = DISTBAND_BENCH_DIR "/results";
  std::string tag;
  std::string python = "/usr/bin/python3";
  std::string scipy_script = DISTBAND_BENCH_DIR "/scipy_edt.py";
  bool no_peer = false;
  std::string groups = "table1,fig7,random,volume,memory";
  std::string stencils = "cubic6,cubic18,cubic26,fcc12";
  std::string modes = "paper,exact";
};

std::vector<Row> planRows(const DriverOptions& o) {
  const std::vector<std::string> stencils = splitList(o.stencils), modes = splitList(o.modes);
  const std::vector<std::string> groups = splitList(o.groups);
  auto want = [&](const std::string& g) { return std::find(groups.begin(), groups.end(), g) != groups.end(); };
  const std::vector<int> table_res = o.quick ? std::vector<int>{64} : std::vector<int>{64, 128, 256};
  const int big = o.quick ? 64 : 256;
  std::vector<Row> rows;
  std::map<std::string, size_t> index;
  auto add = [&](const std::string& group, CaseSpec s) {
    s.threads = o.threads;
    s.reps = s.res >= 256 && o.big_reps > 0 ? o.big_reps : o.reps;
    const std::string key = rowKey(s);
    if (auto it = index.find(key); it != index.end()) {
      rows[it->second].groups.push_back(group);
      return;
    }
    index[key] = rows.size();
    rows.push_back({s, {group}});
  };
  if (o.smoke) {  // every input at 32^3 (the memory case at 64^3), two stencils, both modes: a few seconds
    for (const char* kase : {"one_point", "two_points", "random100", "sphere_shell", "random_blobs"})
      for (const char* st : {"cubic26", "fcc12"})
        for (const char* m : {"exact", "paper"})
          for (double seg : {0.0, 8.0}) {
            if (isVolumeCase(kase) && seg > 0 && std::string(st) != "cubic26") continue;
            add("smoke", {kase, 32, st, m, seg});
          }
    for (const char* m : {"exact", "paper"}) add("smoke", {"sphere_band", 64, "cubic26", m, 0.0, 5.0});
    return rows;
  }
  if (want("table1"))  // the paper's Table 1, mesh-free rows: with segment (l_seg = 20) and without
    for (const char* kase : {"one_point", "two_points"})
      for (int res : table_res)
        for (double seg : {20.0, 0.0})
          for (const auto& st : stencils)
            for (const auto& m : modes) add("table1", {kase, res, st, m, seg});
  if (want("fig7")) {  // the paper's Fig. 7: time vs l_seg on three inputs, the paper's lattice and cubic26
    std::vector<std::string> f7{"fcc12", "cubic26"};
    for (const char* kase : {"one_point", "two_points", "sphere_shell"})
      for (double seg : {10.0, 20.0, 40.0, 0.0})
        for (const auto& st : f7)
          if (std::find(stencils.begin(), stencils.end(), st) != stencils.end())
            for (const auto& m : modes) add("fig7", {kase, big, st, m, seg});
  }
  if (want("random"))
    for (double seg : {0.0, 20.0})
      for (const auto& st : stencils)
        for (const auto& m : modes) add("random", {"random100", big, st, m, seg});
  if (want("volume"))
    for (const char* kase : {"sphere_shell", "random_blobs"})
      for (const auto& st : stencils)
        for (const auto& m : modes) add("volume", {kase, big, st, m, 0.0});
  if (want("memory")) {
    const std::vector<int> mem_res = o.quick ? std::vector<int>{256} : std::vector<int>{256, 512, 1024};
    for (int res : mem_res)
      for (const auto& m : modes) {
        CaseSpec s{"sphere_band", res, "cubic26", m, 0.0, 5.0};
        add("memory", s);
      }
  }
  return rows;
}

std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

std::string lastLine(const std::string& s) {
  std::string t = s;
  while (!t.empty() && (t.back() == '\n' || t.back() == '\r')) t.pop_back();
  const size_t nl = t.rfind('\n');
  return nl == std::string::npos ? t : t.substr(nl + 1);
}

std::string cpuModel() {
  std::ifstream f("/proc/cpuinfo");
  for (std::string line; std::getline(f, line);)
    if (line.rfind("model name", 0) == 0) {
      const size_t c = line.find(':');
      return c == std::string::npos ? line : line.substr(c + 2);
    }
  return "unknown";
}

std::string fmtNum(const json& v, const char* f = "{:.3f}") {
  if (v.is_null()) return "-";
  if (v.is_number()) return fmt::format(fmt::runtime(f), v.get<double>());
  return v.dump();
}

std::string fmtErr(const json& v) {
  if (!v.is_number()) return "-";
  const double e = v.get<double>();
  return e == 0 ? "0" : fmt::format("{:.2e}", e);
}

std::string markdownTable(const std::vector<json>& rows, const std::string& group) {
  std::string md =
      "| case | res | stencil | mode | l_seg | limit | thr | time_s | peer_s | ratio | max_err | bound | mean_err | "
      "frac_off | rss_mb | pass |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const json& r : rows) {
    if (std::find(r["groups"].begin(), r["groups"].end(), group) == r["groups"].end()) continue;
    if (r.contains("error")) {
      md += fmt::format("| {} | {} | {} | {} | {} | {} | {} | FAILED: {} |||||||\n", r["case"].get<std::string>(),
                        r["resolution"].get<int>(), r["stencil"].get<std::string>(), r["mode"].get<std::string>(),
                        fmtNum(r["segment"], "{:g}"), fmtNum(r["limit"], "{:g}"), r["threads"].get<int>(),
                        r["error"].get<std::string>());
      continue;
    }
    md += fmt::format("| {} | {}³ | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:g} | {} | {} | {} | {} |\n",
                      r["case"].get<std::string>(), r["resolution"].get<int>(), r["stencil"].get<std::string>(),
                      r["mode"].get<std::string>(), fmtNum(r["segment"], "{:g}"), fmtNum(r["limit"], "{:g}"),
                      r["threads"].get<int>(), fmtNum(r["time_s"]), fmtNum(r["peer_time_s"]),
                      fmtNum(r["ratio"], "{:.2f}"), fmtErr(r["max_err_vox"]), r.value("bound_vox", 0.0),
                      fmtErr(r["mean_err_vox"]), fmtErr(r["frac_off"]), fmtNum(r["peak_rss_mb"], "{:.0f}"),
                      r.value("pass", false) ? "yes" : "**NO**");
  }
  return md;
}

std::string memoryTable(const std::vector<json>& rows) {
  std::string md =
      "| res | radius | mode | limit | voxels within limit | delivered | time_s | ns/voxel | bricks | rss_mb "
      "(getrusage) | rss_mb (/usr/bin/time -v) | max_err (sites, sampled) | max_err vs sphere |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const json& r : rows) {
    if (r["case"] != "sphere_band" || r.contains("error")) continue;
    const double within = r["voxels_within_limit"].get<double>();
    md += fmt::format("| {}³ | {:g} | {} | {} | {} | {} | {} | {:.1f} | {} | {} | {} | {} | {} |\n",
                      r["resolution"].get<int>(), r["resolution"].get<int>() * 25.0 / 64.0,
                      r["mode"].get<std::string>(), fmtNum(r["limit"], "{:g}"), r["voxels_within_limit"].get<int64_t>(),
                      r["delivered_unique"].get<int64_t>(), fmtNum(r["time_s"]),
                      1e9 * r["time_s"].get<double>() / std::max(1.0, within), r["bricks_allocated"].get<int64_t>(),
                      fmtNum(r["peak_rss_mb"], "{:.0f}"), fmtNum(r.value("time_v_peak_rss_mb", json()), "{:.0f}"),
                      fmtErr(r["max_err_vox"]), fmtErr(r["max_err_vs_sphere_vox"]));
  }
  return md;
}

/// The paper's Table 1 (Core2 6300, seconds, with segment / without) beside ours (fcc12, paper mode).
std::string paperComparison(const std::vector<json>& rows, int threads) {
  const std::map<std::string, std::array<double, 6>> paper = {
      {"one_point", {0.813, 1.458, 8.157, 23.219, 97.642, 391.423}},
      {"two_points", {1.078, 1.938, 11.109, 22.766, 124.485, 409.234}}};
  auto find = [&](const std::string& kase, int res, double seg, const std::string& stencil, const std::string& mode) {
    for (const json& r : rows)
      if (r["case"] == kase && r["resolution"] == res && r["stencil"] == stencil && r["mode"] == mode &&
          (seg > 0 ? r["segment"] == seg : r["segment"].is_null()) && r["limit"].is_null() && !r.contains("error"))
        return r["time_s"].get<double>();
    return std::numeric_limits<double>::quiet_NaN();
  };
  std::string md = fmt::format(
      "| case | res | paper seg20 | paper none | fcc12 paper seg20 | fcc12 paper none | cubic26 exact seg20 | "
      "cubic26 exact none | scipy |\n|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& [kase, t] : paper)
    for (int k = 0; k < 3; ++k) {
      const int res = 64 << k;
      double scipy = std::numeric_limits<double>::quiet_NaN();
      for (const json& r : rows)
        if (r["case"] == kase && r["resolution"] == res && r["peer_time_s"].is_number()) scipy = r["peer_time_s"];
      auto f = [](double v) { return std::isnan(v) ? std::string("-") : fmt::format("{:.3f}", v); };
      md += fmt::format("| {} | {}³ | {:.3f} | {:.3f} | {} | {} | {} | {} | {} |\n", kase, res, t[2 * k],
                        t[2 * k + 1], f(find(kase, res, 20, "fcc12", "paper")), f(find(kase, res, 0, "fcc12", "paper")),
                        f(find(kase, res, 20, "cubic26", "exact")), f(find(kase, res, 0, "cubic26", "exact")),
                        f(scipy));
    }
  md += fmt::format("\nPaper: Core2 6300 1.86 GHz, 1 thread. Ours: {} threads (engine), scipy 1 thread.\n", threads);
  return md;
}

void writeOutputs(const DriverOptions& o, const std::vector<json>& rows, const json& meta) {
  std::filesystem::create_directories(o.out_dir);
  const std::string base = o.out_dir + "/" + o.tag;
  json out = meta;
  out["rows"] = rows;
  distband::bench::writeResultFile(base + ".json", out.dump(1) + "\n");
  std::string md = fmt::format("# engine_bench results ({})\n\n", o.tag);
  md += fmt::format("- date: {}\n- machine: {} ({} cores{}), load average at start: {}\n", meta["date"].get<std::string>(),
                    meta["cpu"].get<std::string>(), meta["cores"].get<int>(), ", shared with other jobs",
                    meta["loadavg_start"].get<std::string>());
  md += fmt::format("- engine: source tree at run start: git {}{} (rebuild before running)\n", meta["git_head"].get<std::string>(),
                    meta["core_uncommitted_changes"].get<bool>() ? " + uncommitted changes in core/" : "");
  md += fmt::format("- distband: {} engine threads, median of {} repetitions ({} at 256³ and above); peer: {} "
                    "(1 thread) on the same input, median of as many repetitions; ratio = distband / peer\n",
                    o.threads, o.reps, o.big_reps > 0 ? o.big_reps : o.reps,
                    o.no_peer ? "none" : "scipy.ndimage.distance_transform_edt");
  md += "- errors in voxels vs an exact oracle, against the exact value rounded to float32 (the output type): points: "
        "brute force over the points; volumes: exact EDT (Felzenszwalb-Huttenlocher); sphere_band: exact distance to "
        "the seed sites on a 1-in-64 voxel sample (its distance to the true sphere is reported apart); frac_off = "
        "fraction of voxels off by > 1e-4 voxel; time_s includes building the seeds and consuming the bricks; pass: "
        "max_err within the row's bound (bench/README.md), every voxel within the limit delivered once, none beyond\n\n";
  const std::vector<std::pair<std::string, std::string>> sections = {
      {"table1", "Table 1 (mesh-free rows): one and two points, with (l_seg = 20) and without segments"},
      {"fig7", "Fig. 7: time vs segment length (10, 20, 40, none)"},
      {"random", "100 random points"},
      {"volume", "Seed volumes (unsigned distance to the mask, as scipy's edt(mask == 0))"},
      {"memory", "Memory case: limit 5 voxels around a sphere of radius 25/64·n"},
      {"smoke", "Smoke rows (every input, tiny)"}};
  for (const auto& [g, title] : sections) {
    bool any = false;
    for (const json& r : rows)
      any |= std::find(r["groups"].begin(), r["groups"].end(), g) != r["groups"].end();
    if (!any) continue;
    md += "## " + title + "\n\n" + markdownTable(rows, g) + "\n";
    if (g == "table1") md += "Against the paper's Table 1 (seconds):\n\n" + paperComparison(rows, o.threads) + "\n";
    if (g == "memory") md += "Scaling (time ∝ voxels within the limit):\n\n" + memoryTable(rows) + "\n";
  }
  distband::bench::writeResultFile(base + ".md", md);
}

std::string shellQuote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

int runDriver(DriverOptions o) {
  if (o.tag.empty()) o.tag = o.smoke ? "engine_bench_smoke" : o.quick ? "engine_bench_quick" : "engine_bench";
  const std::vector<Row> rows = planRows(o);
  if (rows.empty()) {
    std::cerr << "no rows selected (check --groups, --stencils, --modes)\n";
    return 2;
  }
  std::error_code ec;
  const std::string self = std::filesystem::read_symlink("/proc/self/exe", ec).string();
  if (ec) {
    std::cerr << "cannot find this executable: " << ec.message() << "\n";
    return 1;
  }
  const bool have_time = std::filesystem::exists("/usr/bin/time");
  char tmpl[] = "/tmp/distband_bench_XXXXXX";
  if (!mkdtemp(tmpl)) {
    std::cerr << "cannot create a temporary directory\n";
    return 1;
  }
  const std::string tmp = tmpl;
  json meta;
  {
    const auto now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
    char buf[64];
    std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M:%S UTC", std::gmtime(&now));
    meta["date"] = buf;
  }
  meta["cpu"] = cpuModel();
  meta["cores"] = int(sysconf(_SC_NPROCESSORS_ONLN));
  meta["loadavg_start"] = lastLine(slurp("/proc/loadavg"));
  {
    // Which engine was measured: the commit, and whether core/ had uncommitted changes (read-only git queries).
    const std::string src = DISTBAND_BENCH_DIR "/..";
    auto [head, rc] = runCommand(fmt::format("git -C {} rev-parse --short HEAD 2>/dev/null", shellQuote(src)));
    auto [dirty, rc2] = runCommand(fmt::format("git -C {} status --porcelain -- core 2>/dev/null", shellQuote(src)));
    meta["git_head"] = rc == 0 ? lastLine(head) : "unknown";
    meta["core_uncommitted_changes"] = rc2 == 0 && !dirty.empty();
  }
  meta["threads"] = o.threads;
  meta["reps"] = o.reps;
  meta["big_reps"] = o.big_reps > 0 ? o.big_reps : o.reps;
  std::cerr << fmt::format("engine_bench: {} rows, {} threads, {} reps, out {}/{}.{{json,md}}\n", rows.size(),
                           o.threads, o.reps, o.out_dir, o.tag);

  std::map<std::string, json> peer_cache;  // (case, res) -> scipy result
  std::vector<json> results;
  std::vector<std::string> failures;
  for (size_t k = 0; k < rows.size(); ++k) {
    const CaseSpec& s = rows[k].spec;
    // The peer, once per distinct input.
    json peer;
    const std::string input_key = fmt::format("{}@{}", s.kase, s.res);
    if (!o.no_peer && s.kase != "sphere_band") {
      if (!peer_cache.count(input_key)) {
        const Input in = makeInput(s.kase, s.res);
        const std::string mask_path = tmp + "/mask.npy";
        if (Status err = writeNpyMask(mask_path, peerMask(in, s.res), {s.res, s.res, s.res}); !err.ok()) {
          peer_cache[input_key] = json{{"error", err.message()}};
        } else {
          const std::string cmd = fmt::format("{} {} --mask {} --reps {}", shellQuote(o.python),
                                              shellQuote(o.scipy_script), mask_path, s.reps);
          auto [out, rc] = runCommand(cmd);
          json pj;
          if (rc == 0) pj = json::parse(lastLine(out), nullptr, false);
          if (rc != 0 || pj.is_discarded())
            pj = json{{"error", fmt::format("scipy peer failed (exit {}): {}", rc, cmd)}};
          peer_cache[input_key] = pj;
          std::filesystem::remove(mask_path, ec);
          std::cerr << fmt::format("  peer {}: {}\n", input_key, pj.dump());
        }
      }
      peer = peer_cache[input_key];
    }
    // The row, in its own process.
    const std::string rss_file = tmp + "/time.txt", err_file = tmp + "/stderr.txt";
    std::string cmd = fmt::format("{} --case {} --res {} --stencil {} --mode {} --segment {} --limit {} --threads {} "
                                  "--reps {} 2>{}",
                                  shellQuote(self), s.kase, s.res, s.stencil, s.mode, s.segment,
                                  std::isfinite(s.limit) ? fmt::format("{}", s.limit) : std::string("inf"),
                                  s.threads, s.reps, err_file);
    if (have_time) cmd = fmt::format("/usr/bin/time -v -o {} {}", rss_file, cmd);
    auto [out, rc] = runCommand(cmd);
    // A row that ran but failed its check exits kExitWrong after printing its JSON (with "pass": false).
    json row = rc == 0 || rc == bench::kExitWrong ? json::parse(lastLine(out), nullptr, false) : json();
    if (row.is_discarded() || !row.is_object() || !row.contains("pass")) {
      row = json{{"case", s.kase},     {"resolution", s.res},
                 {"stencil", s.stencil}, {"mode", s.mode},
                 {"segment", s.segment > 0 ? json(s.segment) : json(nullptr)},
                 {"limit", jsonNumberOrNull(s.limit)},
                 {"threads", s.threads},
                 {"error", fmt::format("exit {}: {}", rc, lastLine(slurp(err_file)))}};
    }
    if (have_time) {
      if (const auto mb = bench::timeVPeakRssMb(slurp(rss_file))) row["time_v_peak_rss_mb"] = *mb;
    }
    row["groups"] = rows[k].groups;
    if (!peer.is_null() && peer.contains("median_s")) {
      row["peer"] = peer["peer"];
      row["peer_time_s"] = peer["median_s"];
      if (row.contains("time_s")) row["ratio"] = row["time_s"].get<double>() / peer["median_s"].get<double>();
    } else {
      row["peer"] = peer.is_null() ? json("none") : json(peer.value("error", std::string("none")));
      row["peer_time_s"] = nullptr;
      row["ratio"] = nullptr;
    }
    const bool passed = !row.contains("error") && row.value("pass", false);
    if (!passed)
      failures.push_back(fmt::format("{} {}³ {} {} seg={} limit={}: {}", s.kase, s.res, s.stencil, s.mode, s.segment,
                                     s.limit, row.contains("error") ? row["error"].get<std::string>()
                                                                    : row.value("failure", std::string("failed"))));
    std::cerr << fmt::format("[{}/{}] {} {}³ {} {} seg={} limit={}: {}{}\n", k + 1, rows.size(), s.kase, s.res,
                             s.stencil, s.mode, s.segment, s.limit,
                             row.contains("error")
                                 ? row["error"].get<std::string>()
                                 : fmt::format("{:.3f} s (peer {}), max_err {:.3g} (bound {:g}), frac_off {:.3g}, rss "
                                               "{:.0f} MB",
                                               row["time_s"].get<double>(), fmtNum(row["peer_time_s"]),
                                               row["max_err_vox"].get<double>(), row["bound_vox"].get<double>(),
                                               row["frac_off"].get<double>(), row["peak_rss_mb"].get<double>()),
                             passed ? "" : " FAIL");
    results.push_back(row);
    writeOutputs(o, results, meta);
  }
  std::filesystem::remove_all(tmp, ec);
  std::cerr << fmt::format("wrote {}/{}.json and {}/{}.md\n", o.out_dir, o.tag, o.out_dir, o.tag);
  if (!failures.empty()) {
    for (const std::string& f : failures) std::cerr << "engine_bench: FAIL " << f << "\n";
    std::cerr << fmt::format("engine_bench: {} of {} rows failed\n", failures.size(), rows.size());
    return bench::kExitWrong;
  }
  std::cerr << fmt::format("engine_bench: PASS ({} rows, each within its bound)\n", rows.size());
  return 0;
}

}  // namespace
}  // namespace distband

int main(int argc, char** argv) {
  using namespace distband;
  CLI::App app{"distband engine benchmark: the paper's Table 1 / Fig. 7 (mesh-free rows), random points, seed "
               "volumes and the sparse-memory case, against exact oracles and scipy's EDT"};
  DriverOptions o;
  CaseSpec c;
  std::string limit = "inf";
  app.add_flag("--quick", o.quick, "a small subset (64^3 rows, the 256^3 memory row)");
  app.add_flag("--smoke", o.smoke, "every input at 32^3 (memory case 64^3), reps 1; results go to the temporary "
                                   "directory unless --out-dir is given (the CTest run)");
  app.add_option("--reps,-R", o.reps, "repetitions per row; the median time is reported")->check(CLI::Range(1, 100));
  app.add_option("--big-reps", o.big_reps, "repetitions for rows at 256^3 and above (default: --reps)")
      ->check(CLI::Range(1, 100));
  app.add_option("--threads", o.threads, "engine threads (BandOptions.threads)")->check(CLI::Range(1, 256));
  auto* out_dir_opt = app.add_option("--out-dir", o.out_dir, "where <tag>.json and <tag>.md are written");
  app.add_option("--tag", o.tag, "output file name stem (default engine_bench or engine_bench_quick)");
  app.add_option("--python", o.python, "python interpreter with numpy and scipy");
  app.add_option("--scipy-script", o.scipy_script, "the peer script");
  app.add_flag("--no-peer", o.no_peer, "do not run scipy");
  app.add_option("--groups", o.groups, "comma list of: table1, fig7, random, volume, memory");
  app.add_option("--stencils", o.stencils, "comma list of: cubic6, cubic18, cubic26, fcc12");
  app.add_option("--modes", o.modes, "comma list of: paper, exact");
  auto* case_opt = app.add_option("--case", c.kase,
                                  "run one row in this process and print it as JSON: one_point, two_points, "
                                  "random100, sphere_shell, random_blobs, sphere_band");
  app.add_option("--res", c.res, "case mode: grid resolution n (n^3 voxels)")->check(CLI::Range(8, 4096));
  app.add_option("--stencil", c.stencil, "case mode: stencil");
  app.add_option("--mode", c.mode, "case mode: paper or exact");
  app.add_option("--segment", c.segment, "case mode: segment length in voxels (0: none)")->check(CLI::NonNegativeNumber);
  app.add_option("--limit", limit, "case mode: distance limit in voxels, or inf");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;  // --help exits 0; any bad flag exits 2 with CLI11's message
  }
  for (const std::string& s : splitList(o.stencils))
    if (!parseStencil(s)) {
      std::cerr << "unknown stencil '" << s << "'\n";
      return 2;
    }
  for (const std::string& m : splitList(o.modes)) {
    PropagationMode mode;
    if (!parseMode(m, &mode)) {
      std::cerr << "unknown mode '" << m << "'\n";
      return 2;
    }
  }
  if (o.smoke) {
    o.reps = 1;
    if (out_dir_opt->count() == 0) o.out_dir = std::filesystem::temp_directory_path().string();
  }
  if (case_opt->count() == 0) return runDriver(o);
  if (!isKnownCase(c.kase)) {
    std::cerr << "unknown case '" << c.kase << "'\n";
    return 2;
  }
  if (limit == "inf" || limit == "none") {
    c.limit = kInf;
  } else {
    char* end = nullptr;
    c.limit = std::strtod(limit.c_str(), &end);
    if (end == limit.c_str() || *end != '\0' || !(c.limit > 0)) {
      std::cerr << "--limit must be a positive number or inf\n";
      return 2;
    }
  }
  c.threads = o.threads;
  c.reps = o.reps;
  return runCase(c);
}

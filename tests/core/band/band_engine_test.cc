// Tests for core/engine: exactness against oracles that share no code with the engine (brute force for points,
// a Felzenszwalb–Huttenlocher EDT for volumes), lifespan sufficiency, segments, the limit, delivery order and
// exactly-once delivery, thread-count independence, signed volumes and cancellation.
// Every exactness case prints its max / mean error (voxels) and the fraction of voxels off by > 1e-4 voxel for
// every stencil and both modes; the requirements are asserted where it states them.
#include "core/band/band_engine.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "core/seeds/point_seeds.h"
#include "core/seeds/volume_seeds.h"
#include "tests/support/status_testing.h"
#include "tests/support/brute_force.h"
#include "tests/support/error_stats.h"
#include "tests/support/exact_edt.h"

namespace distband {
namespace {

using oracle::ErrorStats;

constexpr StencilKind kAllStencils[] = {StencilKind::kCubic6, StencilKind::kCubic18, StencilKind::kCubic26,
                                        StencilKind::kFcc12};
constexpr PropagationMode kAllModes[] = {PropagationMode::kPaper, PropagationMode::kExact};
constexpr float kUndelivered = std::numeric_limits<float>::infinity();

// ------------------------------------------------------------------------------------------------------------
// Running the engine and checking the delivery contract on the way.

struct EngineRun {
  std::vector<float> field;        ///< dense x-fastest; kUndelivered where nothing was delivered
  std::vector<uint8_t> delivered;  ///< times each voxel was delivered (saturating)
  std::vector<SegmentBricks> segments;  ///< kept only when requested (for sequence comparisons)
  FieldRunResult result;
  std::vector<std::string> problems;  ///< delivery-contract violations seen by the callback
  double seconds = 0;
};

EngineRun runEngine(const Grid& grid, const Seeds& seeds, const BandOptions& options, bool keep_segments = false) {
  EngineRun run;
  run.field.assign(static_cast<size_t>(grid.voxelCount()), kUndelivered);
  run.delivered.assign(static_cast<size_t>(grid.voxelCount()), 0);
  int last_index = -1;
  bool saw_last = false;
  const Coord bd = grid.brickDims();
  auto problem = [&](std::string s) {
    if (run.problems.size() < 20) run.problems.push_back(std::move(s));
  };
  const auto t0 = std::chrono::steady_clock::now();
  run.result = computeBandField(grid, seeds, options, [&](SegmentBricks&& seg) {
    if (seg.index <= last_index)
      problem("segment " + std::to_string(seg.index) + " delivered after segment " + std::to_string(last_index));
    if (saw_last) problem("a segment was delivered after the one marked last");
    last_index = seg.index;
    saw_last = saw_last || seg.last;
    if (!(seg.lower_world <= seg.upper_world)) problem("segment " + std::to_string(seg.index) + " has lower > upper");
    const Coord* prev = nullptr;
    for (const Brick& b : seg.bricks) {
      const Coord o = b.origin;
      if ((o.x & 7) || (o.y & 7) || (o.z & 7) || o.x < 0 || o.y < 0 || o.z < 0 || (o.x >> 3) >= bd.x ||
          (o.y >> 3) >= bd.y || (o.z >> 3) >= bd.z)
        problem("brick origin not on the brick grid or outside it");
      if (prev && std::make_tuple(prev->z, prev->y, prev->x) >= std::make_tuple(o.z, o.y, o.x))
        problem("bricks of segment " + std::to_string(seg.index) + " not sorted by (z, y, x) or repeated");
      prev = &b.origin;
      if (b.mask.empty()) problem("a delivered brick has an empty mask");
      for (int i = 0; i < kBrickVoxels; ++i) {
        if (!b.mask.test(i)) continue;
        const Coord c = o + brickLocal(i);
        if (!grid.contains(c)) {
          problem("a masked voxel lies outside the grid");
          continue;
        }
        const float v = b.values[i];
        const double a = std::fabs(double(v));
        // |distance| must lie in (lower, upper] (segment 0 includes 0); allow float32 rounding of the value.
        const double slack = 4e-7 * std::max(1.0, a);
        const bool above_lower = seg.index == 0 ? a >= 0 : a > seg.lower_world - slack;
        if (!std::isfinite(v) || !above_lower || a > seg.upper_world + slack)
          problem("voxel (" + std::to_string(c.x) + "," + std::to_string(c.y) + "," + std::to_string(c.z) +
                  ") value " + std::to_string(v) + " outside segment " + std::to_string(seg.index) + " range (" +
                  std::to_string(seg.lower_world) + ", " + std::to_string(seg.upper_world) + "]");
        const int64_t di = grid.denseIndex(c);
        run.field[di] = v;
        if (run.delivered[di] < 255) ++run.delivered[di];
      }
    }
    if (keep_segments) run.segments.push_back(std::move(seg));
  });
  run.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!run.result.interrupted && !saw_last) problem("no segment was marked last");
  return run;
}

int64_t countDelivered(const EngineRun& r) {
  int64_t n = 0;
  for (uint8_t d : r.delivered) n += d;
  return n;
}

bool bitIdentical(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

/// Index of the first differing voxel, as "(x,y,z) a vs b", or "" when identical.
std::string firstDifference(const Grid& grid, const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size()) return "sizes differ";
  int64_t n = 0, first = -1;
  for (size_t i = 0; i < a.size(); ++i)
    if (std::memcmp(&a[i], &b[i], sizeof(float)) != 0) {
      if (first < 0) first = int64_t(i);
      ++n;
    }
  if (first < 0) return "";
  const Coord d = grid.dims();
  char buf[200];
  std::snprintf(buf, sizeof buf, "%lld voxels differ; first at (%lld,%lld,%lld): %.9g vs %.9g",
                static_cast<long long>(n), static_cast<long long>(first % d.x),
                static_cast<long long>((first / d.x) % d.y), static_cast<long long>(first / (int64_t(d.x) * d.y)),
                a[first], b[first]);
  return buf;
}

BandOptions makeOptions(StencilKind stencil, PropagationMode mode) {
  BandOptions o;
  o.stencil = stencil;
  o.mode = mode;
  return o;
}

std::string label(StencilKind s, PropagationMode m) {
  return std::string(stencilName(s)) + "/" + std::string(modeName(m));
}

// ------------------------------------------------------------------------------------------------------------
// Inputs.

struct PointCase {
  std::string name;
  Grid grid;
  std::vector<Vec3d> world_points;
};

std::vector<Vec3d> randomPoints(int n, const Coord& dims, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> ux(0, dims.x - 1), uy(0, dims.y - 1), uz(0, dims.z - 1);
  std::vector<Vec3d> p;
  for (int i = 0; i < n; ++i) p.push_back({ux(rng), uy(rng), uz(rng)});
  return p;
}

std::vector<PointCase> pointCases(int n) {
  const Grid g({0, 0, 0}, 1.0, {n, n, n});
  const double c = 0.5 * (n - 1);
  std::vector<PointCase> cases;
  cases.push_back({"one_point", g, {{c - 0.63, c - 1.19, c + 1.52}}});
  cases.push_back({"two_points", g, {{0.3 * n + 0.3, c + 0.7, c - 0.8}, {0.68 * n + 0.6, c - 0.9, c + 1.3}}});
  cases.push_back({"100_random_points", g, randomPoints(100, g.dims(), 12345)});
  return cases;
}

std::vector<double> pointOracleVox(const Grid& grid, const std::vector<Vec3d>& world_points) {
  std::vector<std::array<double, 3>> idx;
  for (const Vec3d& w : world_points) {
    // Index space computed here, not by Grid::indexOf, to stay independent of core.
    idx.push_back({(w.x - grid.origin().x) / grid.voxelSize(), (w.y - grid.origin().y) / grid.voxelSize(),
                   (w.z - grid.origin().z) / grid.voxelSize()});
  }
  const Coord d = grid.dims();
  std::vector<double> v = oracle::bruteForceDistanceSqr(d.x, d.y, d.z, idx);
  for (double& x : v) x = std::sqrt(x);
  return v;
}

Seeds pointSeeds(const Grid& grid, const std::vector<Vec3d>& pts) {
  Seeds s;
  EXPECT_TRUE(IsOk(makePointSeeds(grid, pts, &s)));
  return s;
}

/// A one-voxel-thick spherical shell around a non-integer centre.
std::vector<uint8_t> sphereShell(const Coord& d, double radius, double half_thickness) {
  std::vector<uint8_t> m(size_t(d.x) * d.y * d.z, 0);
  const double cx = 0.5 * d.x + 0.3, cy = 0.5 * d.y - 0.4, cz = 0.5 * d.z + 0.2;
  size_t i = 0;
  for (int z = 0; z < d.z; ++z)
    for (int y = 0; y < d.y; ++y)
      for (int x = 0; x < d.x; ++x, ++i) {
        const double r = std::sqrt((x - cx) * (x - cx) + (y - cy) * (y - cy) + (z - cz) * (z - cz));
        m[i] = std::fabs(r - radius) <= half_thickness;
      }
  return m;
}

/// A union of random balls (solid), some touching the domain border.
std::vector<uint8_t> randomBlobs(const Coord& d, int count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> ux(0, d.x - 1), uy(0, d.y - 1), uz(0, d.z - 1);
  std::uniform_real_distribution<double> ur(1.5, 0.12 * std::min({d.x, d.y, d.z}));
  std::vector<uint8_t> m(size_t(d.x) * d.y * d.z, 0);
  for (int b = 0; b < count; ++b) {
    const double cx = ux(rng), cy = uy(rng), cz = uz(rng), r = ur(rng);
    size_t i = 0;
    for (int z = 0; z < d.z; ++z)
      for (int y = 0; y < d.y; ++y)
        for (int x = 0; x < d.x; ++x, ++i)
          if ((x - cx) * (x - cx) + (y - cy) * (y - cy) + (z - cz) * (z - cz) <= r * r) m[i] = 1;
  }
  return m;
}

struct VolumeCase {
  std::string name;
  Grid grid;
  std::vector<uint8_t> mask;
};

std::vector<VolumeCase> volumeCases(int n) {
  const Coord d{n, n, n};
  const Grid g({0, 0, 0}, 1.0, d);
  return {{"sphere_shell", g, sphereShell(d, 0.36 * n, 0.75)}, {"random_blobs", g, randomBlobs(d, 14, 777)}};
}

Seeds volumeSeeds(const Grid& grid, const std::vector<uint8_t>& mask, bool signed_distance) {
  Seeds s;
  EXPECT_TRUE(IsOk(makeVolumeSeeds(grid, LabelVolume::ofMask(grid.dims(), mask), signed_distance, &s)));
  return s;
}

std::vector<double> volumeOracleVox(const Grid& grid, const std::vector<uint8_t>& mask, bool signed_distance) {
  const Coord d = grid.dims();
  if (signed_distance) return oracle::signedEdt(d.x, d.y, d.z, mask);
  std::vector<double> v = oracle::edtSqr(d.x, d.y, d.z, mask);
  for (double& x : v) x = std::sqrt(x);
  return v;
}

void report(const std::string& what, const Grid& grid, const ErrorStats& s, double seconds) {
  std::printf("[errors] %-44s %s  (%.3f s)\n", what.c_str(),
              oracle::formatErrorStats(s, grid.dims().x, grid.dims().y).c_str(), seconds);
  std::fflush(stdout);
  ::testing::Test::RecordProperty(what + ".max_err_vox", std::to_string(s.max_err_vox));
  ::testing::Test::RecordProperty(what + ".mean_err_vox", std::to_string(s.mean_err_vox));
  ::testing::Test::RecordProperty(what + ".frac_off", std::to_string(s.frac_off));
}

void expectCleanDelivery(const EngineRun& run, const std::string& what) {
  for (const std::string& p : run.problems) ADD_FAILURE() << what << ": " << p;
  int64_t twice = 0;
  for (uint8_t d : run.delivered) twice += d > 1;
  EXPECT_EQ(twice, 0) << what << ": voxels delivered more than once";
  EXPECT_EQ(run.result.voxels, countDelivered(run)) << what << ": FieldRunResult::voxels disagrees with the bricks";
  int64_t seg_voxels = 0;
  for (const SegmentStats& s : run.result.segments) seg_voxels += s.voxels;
  EXPECT_EQ(seg_voxels, run.result.voxels) << what << ": SegmentStats voxels do not add up";
}

void expectAllDelivered(const EngineRun& run, const std::string& what) {
  int64_t missing = 0;
  for (uint8_t d : run.delivered) missing += d == 0;
  EXPECT_EQ(missing, 0) << what << ": voxels never delivered without a limit";
}

// ------------------------------------------------------------------------------------------------------------
// Exactness.

TEST(OracleSelfCheck, ExactEdtAgreesWithBruteForce) {
  // The two oracles check each other: the separable EDT of a sparse random mask equals brute force over its
  // nonzero voxels, and the signed EDT has the documented sign and magnitude.
  const int nx = 23, ny = 17, nz = 19;
  std::mt19937 rng(7);
  std::vector<uint8_t> mask(size_t(nx) * ny * nz, 0);
  std::vector<std::array<double, 3>> pts;
  for (int i = 0; i < 40; ++i) {
    const int x = int(rng() % nx), y = int(rng() % ny), z = int(rng() % nz);
    mask[(size_t(z) * ny + y) * nx + x] = 1;
    pts.push_back({double(x), double(y), double(z)});
  }
  const std::vector<double> edt = oracle::edtSqr(nx, ny, nz, mask);
  const std::vector<double> bf = oracle::bruteForceDistanceSqr(nx, ny, nz, pts);
  ASSERT_EQ(edt.size(), bf.size());
  for (size_t i = 0; i < edt.size(); ++i) ASSERT_EQ(edt[i], bf[i]) << i;
  const std::vector<double> sgn = oracle::signedEdt(nx, ny, nz, mask);
  for (size_t i = 0; i < mask.size(); ++i) {
    if (mask[i]) {
      EXPECT_LT(sgn[i], 0);  // a lone seed voxel is 1 from the nearest non-mask voxel
      EXPECT_GE(sgn[i], -1.0 - 1e-12);
    } else {
      EXPECT_DOUBLE_EQ(sgn[i], std::sqrt(bf[i]));
    }
  }
  EXPECT_TRUE(std::isinf(oracle::edtSqr(4, 4, 4, std::vector<uint8_t>(64, 0))[0]));
}

/// Every mode and stencil on one point set, against brute force: everything delivered once, figures reported, and
/// exact mode with cubic26 and fcc12 exact (<= 1e-5 voxel).
void checkPointExactness(const std::string& name, const Grid& grid, const std::vector<Vec3d>& world_points) {
  const std::vector<double> expected = pointOracleVox(grid, world_points);
  const Seeds seeds = pointSeeds(grid, world_points);
  const Coord d = grid.dims();
  for (PropagationMode mode : kAllModes)
    for (StencilKind stencil : kAllStencils) {
      const std::string what = fmt::format("{} {}x{}x{} h={} {}", name, d.x, d.y, d.z, grid.voxelSize(),
                                           label(stencil, mode));
      const EngineRun run = runEngine(grid, seeds, makeOptions(stencil, mode));
      expectCleanDelivery(run, what);
      expectAllDelivered(run, what);
      const ErrorStats s = oracle::compareToOracle(run.field, expected, grid.voxelSize());
      report(what, grid, s, run.seconds);
      if (mode == PropagationMode::kExact && (stencil == StencilKind::kCubic26 || stencil == StencilKind::kFcc12)) {
        EXPECT_LE(s.max_err_vox, 1e-5) << what << ": " << oracle::formatErrorStats(s, d.x, d.y);
      }
    }
}

TEST(EngineExactness, PointSeedsAgainstBruteForce) {
  for (const PointCase& pc : pointCases(64)) checkPointExactness(pc.name, pc.grid, pc.world_points);
}

TEST(EngineExactness, PointSeedsInWorldUnits) {
  // Non-unit voxel size and a shifted origin: distances are world units.
  checkPointExactness("world_units", Grid({-2.0, 1.0, 0.5}, 0.25, {40, 36, 44}),
                      {{1.13, 5.02, 6.31}, {5.7, 3.3, 4.4}, {0.2, 8.9, 10.1}});
}

/// Two points inside the grid and one outside it (its band is the clamped block near the grid's edge).
PointCase outsideCase() {
  return {"outside_point", Grid({-2.0, 1.0, 0.5}, 0.25, {40, 36, 44}),
          {{1.13, 5.02, 6.31}, {9.7, 3.3, 4.4}, {-4.0, 12.0, 3.0}}};
}

TEST(EngineExactness, PointSeedsOutsideTheGrid) {
  const PointCase pc = outsideCase();
  checkPointExactness(pc.name, pc.grid, pc.world_points);
}

// Anisotropic voxels (the band's sites and offers in unit space, core/grid.h): distances in world units against brute
// force with the same spacing. Exact mode with cubic26 keeps point seeds exact; every other stencil and mode is
// reported.
TEST(EngineExactness, PointSeedsOnAnisotropicVoxels) {
  for (const Vec3d spacing : {Vec3d{0.5, 0.5, 2.5}, Vec3d{1.0, 0.7, 0.4}}) {
    const Grid grid({-1.0, 2.0, 0.5}, spacing, {36, 30, 20});
    const std::vector<Vec3d> world = {{3.13, 6.02, 9.31}, {12.7, 14.3, 30.4}, {0.2, 12.9, 20.1}, {9.0, 9.0, 17.9}};
    std::vector<std::array<double, 3>> idx;
    for (const Vec3d& w : world)  // index space computed here, independent of core
      idx.push_back({(w.x + 1.0) / spacing.x, (w.y - 2.0) / spacing.y, (w.z - 0.5) / spacing.z});
    const Coord d = grid.dims();
    std::vector<double> expected = oracle::bruteForceDistanceSqr(d.x, d.y, d.z, idx, {spacing.x, spacing.y, spacing.z});
    const double unit = std::min({spacing.x, spacing.y, spacing.z});
    for (double& x : expected) x = std::sqrt(x) / unit;
    const Seeds seeds = pointSeeds(grid, world);
    for (PropagationMode mode : kAllModes)
      for (StencilKind stencil : kAllStencils) {
        const std::string what = fmt::format("anisotropic points {},{},{} {}", spacing.x, spacing.y, spacing.z,
                                             label(stencil, mode));
        const EngineRun run = runEngine(grid, seeds, makeOptions(stencil, mode));
        expectCleanDelivery(run, what);
        expectAllDelivered(run, what);
        const ErrorStats s = oracle::compareToOracle(run.field, expected, unit);
        report(what, grid, s, run.seconds);
        if (mode == PropagationMode::kExact && stencil == StencilKind::kCubic26) {
          EXPECT_LE(s.max_err_vox, 1e-5) << what << ": " << oracle::formatErrorStats(s, d.x, d.y);
        }
        if (mode == PropagationMode::kExact) {
          EXPECT_LE(s.max_err_vox, 0.05) << what;
        }
      }
  }
}

TEST(EngineExactness, VolumesOnAnisotropicVoxels) {
  const Coord d{40, 36, 24};
  const double spacing[3] = {0.5, 0.5, 1.5};
  const Grid grid({0, 0, 0}, Vec3d{spacing[0], spacing[1], spacing[2]}, d);
  const std::vector<uint8_t> mask = randomBlobs(d, 6, 99);
  for (bool signed_distance : {false, true}) {
    std::vector<double> expected;
    if (signed_distance) {
      expected = oracle::signedEdt(d.x, d.y, d.z, mask, spacing);
    } else {
      expected = oracle::edtSqr(d.x, d.y, d.z, mask, spacing);
      for (double& x : expected) x = std::sqrt(x);
    }
    for (double& x : expected) x /= 0.5;  // voxels: units of the smallest spacing
    const Seeds seeds = volumeSeeds(grid, mask, signed_distance);
    const std::string what = fmt::format("anisotropic volume {} exact/cubic26", signed_distance ? "signed" : "unsigned");
    const EngineRun run = runEngine(grid, seeds, makeOptions(StencilKind::kCubic26, PropagationMode::kExact));
    expectCleanDelivery(run, what);
    expectAllDelivered(run, what);
    const ErrorStats s = oracle::compareToOracle(run.field, expected, 0.5);
    report(what, grid, s, run.seconds);
    EXPECT_LE(s.max_err_vox, 0.05) << what << ": " << oracle::formatErrorStats(s, d.x, d.y);
  }
}

void checkVolumeExactness(bool signed_distance) {
  for (const VolumeCase& vc : volumeCases(64)) {
    const std::vector<double> expected = volumeOracleVox(vc.grid, vc.mask, signed_distance);
    const Seeds seeds = volumeSeeds(vc.grid, vc.mask, signed_distance);
    for (PropagationMode mode : kAllModes)
      for (StencilKind stencil : kAllStencils) {
        const std::string what =
            vc.name + (signed_distance ? " signed" : " unsigned") + " 64^3 " + label(stencil, mode);
        const EngineRun run = runEngine(vc.grid, seeds, makeOptions(stencil, mode));
        expectCleanDelivery(run, what);
        expectAllDelivered(run, what);
        const ErrorStats s = oracle::compareToOracle(run.field, expected, vc.grid.voxelSize());
        report(what, vc.grid, s, run.seconds);
        if (mode == PropagationMode::kExact && stencil == StencilKind::kCubic26) {
          EXPECT_LE(s.max_err_vox, 0.05) << what << ": " << oracle::formatErrorStats(s, 64, 64);
          EXPECT_LE(s.frac_off, 1e-4) << what << ": " << oracle::formatErrorStats(s, 64, 64);
        }
        if (signed_distance) {
          // Signs: strictly negative on the mask, strictly positive off it (no voxel centre is on the boundary).
          int64_t wrong = 0;
          for (size_t i = 0; i < vc.mask.size(); ++i)
            wrong += vc.mask[i] ? !(run.field[i] < 0) : !(run.field[i] > 0);
          EXPECT_EQ(wrong, 0) << what << ": voxels with the wrong sign";
        } else {
          int64_t nonzero_on_mask = 0;
          for (size_t i = 0; i < vc.mask.size(); ++i) nonzero_on_mask += vc.mask[i] && run.field[i] != 0.0f;
          EXPECT_EQ(nonzero_on_mask, 0) << what << ": mask voxels must have distance 0";
        }
      }
  }
}

TEST(EngineExactness, UnsignedVolumesAgainstExactEdt) { checkVolumeExactness(false); }

TEST(EngineExactness, SignedVolumesAgainstExactEdt) { checkVolumeExactness(true); }

// ------------------------------------------------------------------------------------------------------------
// Lifespan sufficiency: the paper's lifespan (with the engine's default margin) must give exactly the field
// obtained by iterating until nothing changes (alpha = +infinity), for every stencil and input kind.

TEST(EngineLifespan, DefaultLifespanEqualsIterationToConvergence) {
  struct Input {
    std::string name;
    Grid grid;
    Seeds seeds;
  };
  std::vector<Input> inputs;
  const int n = 56;
  const Grid g({0, 0, 0}, 1.0, {n, n, n});
  inputs.push_back({"one_point", g, pointSeeds(g, pointCases(n)[0].world_points)});
  inputs.push_back({"two_points", g, pointSeeds(g, pointCases(n)[1].world_points)});
  inputs.push_back({"30_random_points", g, pointSeeds(g, randomPoints(30, g.dims(), 99))});
  {
    const PointCase pc = outsideCase();
    inputs.push_back({pc.name, pc.grid, pointSeeds(pc.grid, pc.world_points)});
  }
  for (const VolumeCase& vc : volumeCases(n)) {
    inputs.push_back({vc.name, vc.grid, volumeSeeds(vc.grid, vc.mask, false)});
    inputs.push_back({vc.name + "_signed", vc.grid, volumeSeeds(vc.grid, vc.mask, true)});
  }
  for (const Input& in : inputs)
    for (StencilKind stencil : kAllStencils) {
      const std::string what = in.name + " " + std::string(stencilName(stencil));
      BandOptions lifespan = makeOptions(stencil, PropagationMode::kPaper);
      BandOptions converge = lifespan;
      converge.lifespan_alpha = std::numeric_limits<double>::infinity();
      const EngineRun a = runEngine(in.grid, in.seeds, lifespan);
      const EngineRun b = runEngine(in.grid, in.seeds, converge);
      expectCleanDelivery(a, what);
      expectAllDelivered(a, what);
      EXPECT_TRUE(bitIdentical(a.field, b.field))
          << what << " (margin " << defaultLifespanMargin(stencil)
          << "): lifespan run differs from the converged run: " << firstDifference(in.grid, a.field, b.field);
      std::printf("[lifespan] %-28s margin %d steps %d vs %d (converged)\n", what.c_str(),
                  defaultLifespanMargin(stencil), a.result.steps, b.result.steps);
    }
}

TEST(EngineLifespan, ZeroMarginNeverGoesBelowTheTrueDistance) {
  // The raw paper lifespan (margin 0) may finish voxels early, leaving values too large; every value is still the
  // distance to some seed site, so it can never be below the exact EDT. Prints how many voxels the raw lifespan
  // leaves different from the converged field (the reason the engine adds a margin).
  const int n = 48;
  const Grid g({0, 0, 0}, 1.0, {n, n, n});
  const std::vector<uint8_t> mask = randomBlobs(g.dims(), 10, 4242);
  const Seeds seeds = volumeSeeds(g, mask, false);
  const std::vector<double> exact = volumeOracleVox(g, mask, false);
  for (StencilKind stencil : kAllStencils) {
    BandOptions raw = makeOptions(stencil, PropagationMode::kPaper);
    raw.lifespan_margin = 0;
    BandOptions converge = raw;
    converge.lifespan_alpha = std::numeric_limits<double>::infinity();
    const EngineRun a = runEngine(g, seeds, raw);
    const EngineRun b = runEngine(g, seeds, converge);
    expectCleanDelivery(a, "margin 0");
    expectAllDelivered(a, "margin 0");
    int64_t below = 0, differ = 0;
    for (size_t i = 0; i < a.field.size(); ++i) {
      below += a.field[i] < static_cast<float>(exact[i]);
      differ += a.field[i] != b.field[i];
    }
    std::printf("[lifespan] blobs 48^3 %-8s margin 0: %lld voxels differ from the converged field\n",
                std::string(stencilName(stencil)).c_str(), static_cast<long long>(differ));
    EXPECT_EQ(below, 0) << stencilName(stencil);
  }
}

// ------------------------------------------------------------------------------------------------------------
// Segments and the limit.

/// Exact mode must give bit-identical fields whatever the segmentation or limit. Paper mode is plain vector
/// propagation, whose fixed point is not unique: segments change when held-back offers arrive, so a few voxels may
/// settle on a different (near-tie) site. There we bound how many and by how much, in voxels.
void expectSameField(PropagationMode mode, const Grid& g, const std::vector<float>& a, const std::vector<float>& b,
                     const std::vector<uint8_t>* only, const std::string& what) {
  int64_t differ = 0, compared = 0;
  double max_diff = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (only && !(*only)[i]) continue;
    ++compared;
    if (std::memcmp(&a[i], &b[i], sizeof(float)) == 0) continue;
    ++differ;
    max_diff = std::max(max_diff, std::fabs(double(a[i]) - double(b[i])) / g.voxelSize());
  }
  if (mode == PropagationMode::kExact) {
    EXPECT_EQ(differ, 0) << what << ": " << firstDifference(g, a, b);
    return;
  }
  std::printf("[paper-mode order dependence] %s: %lld of %lld voxels differ, max %.4f voxel\n", what.c_str(),
              static_cast<long long>(differ), static_cast<long long>(compared), max_diff);
  EXPECT_LE(double(differ), 2e-3 * double(compared)) << what << ": " << firstDifference(g, a, b);
  EXPECT_LE(max_diff, 0.5) << what;
}

TEST(EngineSegments, SegmentsGiveTheSameFieldAsOneSegment) {
  const int n = 64;
  const Grid g({0, 0, 0}, 1.0, {n, n, n});
  const std::vector<std::pair<std::string, Seeds>> inputs = {
      {"two_points", pointSeeds(g, pointCases(n)[1].world_points)},
      {"random_blobs", volumeSeeds(g, randomBlobs(g.dims(), 14, 777), false)},
      {"random_blobs_signed", volumeSeeds(g, randomBlobs(g.dims(), 14, 777), true)},
  };
  for (const auto& [name, seeds] : inputs)
    for (PropagationMode mode : kAllModes)
      for (StencilKind stencil : kAllStencils) {
        const std::string what = name + " " + label(stencil, mode);
        const EngineRun whole = runEngine(g, seeds, makeOptions(stencil, mode));
        EXPECT_EQ(whole.result.segments.size(), 1u) << what;
        for (double seg : {5.0, 7.5}) {
          BandOptions o = makeOptions(stencil, mode);
          o.segment_length_world = seg;
          const EngineRun split = runEngine(g, seeds, o);
          const std::string w = what + " l_seg=" + std::to_string(seg);
          expectCleanDelivery(split, w);
          expectAllDelivered(split, w);
          EXPECT_GE(split.result.segments.size(), 2u) << w;
          for (size_t i = 0; i < split.result.segments.size(); ++i) {
            const SegmentStats& s = split.result.segments[i];
            EXPECT_EQ(s.index, int(i)) << w;
            EXPECT_DOUBLE_EQ(s.lower_world, i * seg) << w;
            if (i + 1 < split.result.segments.size()) {
              EXPECT_DOUBLE_EQ(s.upper_world, (i + 1) * seg) << w;
            }
          }
          expectSameField(mode, g, whole.field, split.field, nullptr, w);
        }
      }
}

TEST(EngineSegments, LimitDeliversExactlyTheVoxelsWithin) {
  const int n = 64;
  const Grid g({0, 0, 0}, 0.5, {n, n, n});  // world units: limit 3.25 = 6.5 voxels
  const std::vector<std::pair<std::string, Seeds>> inputs = {
      {"one_point", pointSeeds(g, {{16.1, 15.3, 16.7}})},
      {"100_random_points", pointSeeds(g, [&] {
         std::vector<Vec3d> p = randomPoints(100, g.dims(), 5);
         for (Vec3d& v : p) v = v * 0.5;
         return p;
       }())},
      {"sphere_shell_signed", volumeSeeds(g, sphereShell(g.dims(), 20, 0.75), true)},
  };
  const double limit = 3.25;
  for (const auto& [name, seeds] : inputs)
    for (PropagationMode mode : kAllModes)
      for (StencilKind stencil : kAllStencils) {
        const std::string what = name + " " + label(stencil, mode);
        const EngineRun whole = runEngine(g, seeds, makeOptions(stencil, mode));
        for (double seg : {0.0, 1.0}) {
          BandOptions o = makeOptions(stencil, mode);
          o.limit_world = limit;
          o.segment_length_world = seg;
          const EngineRun lim = runEngine(g, seeds, o);
          const std::string w = what + " limit=3.25 l_seg=" + std::to_string(seg);
          expectCleanDelivery(lim, w);
          int64_t beyond = 0, missing = 0, inside = 0;
          for (size_t i = 0; i < whole.field.size(); ++i) {
            const bool within = std::fabs(whole.field[i]) <= limit;
            inside += within;
            if (lim.delivered[i] && std::fabs(lim.field[i]) > limit) ++beyond;
            if (within && !lim.delivered[i]) ++missing;
          }
          EXPECT_EQ(beyond, 0) << w << ": voxels delivered beyond the limit";
          EXPECT_EQ(missing, 0) << w << ": voxels within the limit not delivered";
          expectSameField(mode, g, whole.field, lim.field, &lim.delivered, w + " vs the unlimited run");
          EXPECT_EQ(lim.result.voxels, inside) << w;
          for (const SegmentStats& s : lim.result.segments) EXPECT_LE(s.lower_world, limit) << w;
        }
      }
}

TEST(EngineSegments, StorageIsSparseUnderASmallLimit) {
  // 256^3 domain, one point, limit 4 voxels: only the bricks around the point may be allocated.
  const Grid g({0, 0, 0}, 1.0, {256, 256, 256});
  const Seeds seeds = pointSeeds(g, {{100.4, 120.2, 130.7}});
  BandOptions o = makeOptions(StencilKind::kCubic26, PropagationMode::kExact);
  o.limit_world = 4.0;
  int64_t voxels = 0;
  const FieldRunResult r = computeBandField(g, seeds, o, [&](SegmentBricks&& s) {
    for (const Brick& b : s.bricks) voxels += b.mask.count();
  });
  EXPECT_EQ(voxels, r.voxels);
  EXPECT_GT(voxels, 200);
  EXPECT_LT(voxels, 400);  // 4/3*pi*4^3 ~ 268 voxels
  EXPECT_LE(r.bricks_allocated, 27) << "a radius-4 ball touches at most 3x3x3 bricks (+ its band ring)";
  EXPECT_GT(r.bricks_allocated, 0);
}

// ------------------------------------------------------------------------------------------------------------
// Threads.

TEST(EngineThreads, OneAndTwoThreadsAreBitIdentical) {
  const int n = 80;
  const Grid g({0, 0, 0}, 1.0, {n, n, n});
  const std::vector<std::pair<std::string, Seeds>> inputs = {
      {"100_random_points", pointSeeds(g, randomPoints(100, g.dims(), 2024))},
      {"random_blobs_signed", volumeSeeds(g, randomBlobs(g.dims(), 20, 31337), true)},
  };
  for (const auto& [name, seeds] : inputs)
    for (PropagationMode mode : kAllModes)
      for (StencilKind stencil : {StencilKind::kCubic6, StencilKind::kCubic26, StencilKind::kFcc12}) {
        const std::string what = name + " " + label(stencil, mode);
        BandOptions o = makeOptions(stencil, mode);
        o.segment_length_world = 12;
        o.threads = 1;
        const EngineRun one = runEngine(g, seeds, o, /*keep_segments=*/true);
        o.threads = 2;
        const EngineRun two = runEngine(g, seeds, o, /*keep_segments=*/true);
        expectCleanDelivery(two, what);
        EXPECT_TRUE(bitIdentical(one.field, two.field)) << what << ": " << firstDifference(g, one.field, two.field);
        EXPECT_EQ(one.result.steps, two.result.steps) << what;
        // (result.updates is a work counter; it may legitimately depend on the thread interleaving.)
        // The delivered stream itself (segments, bricks, masks, values) must not depend on the thread count.
        ASSERT_EQ(one.segments.size(), two.segments.size()) << what;
        for (size_t s = 0; s < one.segments.size(); ++s) {
          const SegmentBricks &a = one.segments[s], &b = two.segments[s];
          EXPECT_EQ(a.index, b.index);
          EXPECT_EQ(a.lower_world, b.lower_world);
          EXPECT_EQ(a.upper_world, b.upper_world);
          ASSERT_EQ(a.bricks.size(), b.bricks.size()) << what << " segment " << s;
          for (size_t k = 0; k < a.bricks.size(); ++k) {
            EXPECT_EQ(a.bricks[k].origin, b.bricks[k].origin);
            EXPECT_EQ(a.bricks[k].mask.words, b.bricks[k].mask.words);
            for (int i = 0; i < kBrickVoxels; ++i)
              if (a.bricks[k].mask.test(i)) {
                EXPECT_EQ(a.bricks[k].values[i], b.bricks[k].values[i]);
              }
          }
        }
        std::printf("[threads] %-40s 1 thread %.3f s, 2 threads %.3f s\n", what.c_str(), one.seconds, two.seconds);
      }
}

// ------------------------------------------------------------------------------------------------------------
// Cancellation, options and preconditions.

TEST(EngineControl, InterruptBeforeTheFirstStep) {
  const Grid g({0, 0, 0}, 1.0, {64, 64, 64});
  const Seeds seeds = pointSeeds(g, {{10, 10, 10}});
  BandOptions o;
  Interrupter stop;
  stop.cancel();
  o.interrupter = &stop;
  int64_t delivered = 0;
  const FieldRunResult r =
      computeBandField(g, seeds, o, [&](SegmentBricks&& s) { delivered += int64_t(s.bricks.size()); });
  EXPECT_TRUE(r.interrupted);
  EXPECT_LT(r.voxels, g.voxelCount());
}

TEST(EngineControl, InterruptAfterTheFirstSegmentStopsTheRun) {
  const Grid g({0, 0, 0}, 1.0, {64, 64, 64});
  const Seeds seeds = pointSeeds(g, {{10.2, 20.3, 30.4}});
  Interrupter stop;
  int after_stop = 0, segments = 0;
  BandOptions o;
  o.segment_length_world = 4;
  o.interrupter = &stop;
  const FieldRunResult r = computeBandField(g, seeds, o, [&](SegmentBricks&& s) {
    if (stop.interrupted()) ++after_stop;
    ++segments;
    EXPECT_FALSE(s.last);
    stop.cancel();
  });
  EXPECT_TRUE(r.interrupted);
  EXPECT_EQ(segments, 1);
  EXPECT_EQ(after_stop, 0);
}

/// Everything a run delivers, brick by brick in delivery order, with each callback's segment and completeness.
struct Delivery {
  std::vector<std::pair<int, Brick>> bricks;  // (segment, brick)
  std::vector<std::pair<int, bool>> calls;    // (segment, complete) of every callback
  size_t largest_call = 0;
};

Delivery deliver(const Grid& g, const Seeds& seeds, BandOptions o) {
  Delivery d;
  computeBandField(g, seeds, o, [&](SegmentBricks&& s) {
    d.calls.push_back({s.index, s.complete});
    d.largest_call = std::max(d.largest_call, s.bricks.size());
    for (Brick& b : s.bricks) d.bricks.push_back({s.index, std::move(b)});
  });
  return d;
}

TEST(EngineControl, ChunkedEmissionDeliversTheSameBricksInTheSameOrder) {
  const Grid g({0, 0, 0}, 1.0, {40, 36, 44});
  const std::vector<uint8_t> mask = randomBlobs(g.dims(), 5, 99);
  struct Case {
    const char* name;
    Seeds seeds;
  };
  std::vector<Case> cases;
  cases.push_back({"points", pointSeeds(g, {{3.2, 7.5, 30.1}, {33.3, 20.2, 4.4}})});
  cases.push_back({"signed volume", volumeSeeds(g, mask, true)});
  for (const Case& c : cases)
    for (double segment : {0.0, 3.0}) {
      BandOptions o;
      o.segment_length_world = segment;
      o.limit_world = 14;
      const Delivery whole = deliver(g, c.seeds, o);
      o.max_chunk_bricks = 7;
      const Delivery chunked = deliver(g, c.seeds, o);
      ASSERT_EQ(whole.bricks.size(), chunked.bricks.size()) << c.name;
      for (size_t i = 0; i < whole.bricks.size(); ++i) {
        EXPECT_EQ(whole.bricks[i].first, chunked.bricks[i].first) << c.name << " brick " << i;
        EXPECT_EQ(whole.bricks[i].second.origin, chunked.bricks[i].second.origin) << c.name << " brick " << i;
        EXPECT_EQ(std::memcmp(&whole.bricks[i].second.mask, &chunked.bricks[i].second.mask, sizeof(BrickMask)), 0);
        for (int v = 0; v < kBrickVoxels; ++v)
          if (whole.bricks[i].second.mask.test(v)) {
            ASSERT_EQ(whole.bricks[i].second.values[v], chunked.bricks[i].second.values[v]) << c.name;
          }
      }
      EXPECT_LE(chunked.largest_call, 7u) << c.name;
      // Every segment ends with exactly one complete chunk, and segments come in order.
      int complete = 0;
      for (size_t i = 0; i < chunked.calls.size(); ++i) {
        complete += chunked.calls[i].second;
        if (i > 0) {
          EXPECT_GE(chunked.calls[i].first, chunked.calls[i - 1].first);
        }
        if (i > 0 && chunked.calls[i].first != chunked.calls[i - 1].first) {
          EXPECT_TRUE(chunked.calls[i - 1].second);
        }
      }
      EXPECT_EQ(complete, int(whole.calls.size())) << c.name;
      EXPECT_TRUE(chunked.calls.back().second);
    }
}

TEST(EngineControl, ADeadlineInThePastStopsTheRunAtOnce) {
  const Grid g({0, 0, 0}, 1.0, {96, 96, 96});
  const Seeds seeds = pointSeeds(g, {{10, 10, 10}});
  Interrupter expired(Interrupter::Clock::now() - std::chrono::seconds(1));
  BandOptions o;
  o.interrupter = &expired;
  int callbacks = 0;
  const FieldRunResult r = computeBandField(g, seeds, o, [&](SegmentBricks&&) { ++callbacks; });
  EXPECT_TRUE(r.interrupted);
  EXPECT_EQ(callbacks, 0);
  EXPECT_EQ(expired.status().code(), Status::Code::kDeadlineExceeded);
}

TEST(EngineControl, CancelFromAnotherThreadStopsALongRun) {
  const Grid g({0, 0, 0}, 1.0, {192, 192, 192});
  const Seeds seeds = pointSeeds(g, {{10.5, 20.5, 30.5}, {150.2, 170.1, 20.3}});
  Interrupter stop;
  BandOptions o;
  o.interrupter = &stop;
  o.threads = 2;
  std::thread canceller([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
    stop.cancel();
  });
  const auto t0 = std::chrono::steady_clock::now();
  const FieldRunResult r = computeBandField(g, seeds, o, [](SegmentBricks&&) {});
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  canceller.join();
  EXPECT_TRUE(r.interrupted);
  EXPECT_LT(seconds, 2.0) << "a generous bound: the latency itself is measured by bench/cancel_bench";
}

TEST(EngineControl, ModeNames) {
  PropagationMode m;
  ASSERT_TRUE(parseMode("paper", &m));
  EXPECT_EQ(m, PropagationMode::kPaper);
  ASSERT_TRUE(parseMode("exact", &m));
  EXPECT_EQ(m, PropagationMode::kExact);
  EXPECT_FALSE(parseMode("fast", &m));
  EXPECT_EQ(modeName(PropagationMode::kPaper), "paper");
  EXPECT_EQ(modeName(PropagationMode::kExact), "exact");
}

TEST(EngineControl, OptionValidation) {
  const Grid g({0, 0, 0}, 1.0, {16, 16, 16});
  EXPECT_TRUE(IsOk(validateBandOptions(g, BandOptions{})));
  auto bad = [&](auto mutate) {
    BandOptions o;
    mutate(o);
    return validateBandOptions(g, o);
  };
  constexpr Status::Code kInvalid = Status::Code::kInvalidArgument;
  EXPECT_TRUE(IsError(bad([](BandOptions& o) { o.segment_length_world = -1; }), kInvalid, "segment_length"));
  EXPECT_TRUE(IsError(bad([](BandOptions& o) { o.segment_length_world = std::nan(""); }), kInvalid, "segment_length"));
  EXPECT_TRUE(IsError(bad([](BandOptions& o) { o.limit_world = -1; }), kInvalid, "limit must be > 0"));
  EXPECT_TRUE(IsError(bad([](BandOptions& o) { o.limit_world = std::nan(""); }), kInvalid, "limit must be > 0"));
  EXPECT_TRUE(IsError(bad([](BandOptions& o) { o.threads = -3; }), kInvalid, "threads"));
  EXPECT_TRUE(IsError(bad([](BandOptions& o) { o.lifespan_alpha = std::nan(""); }), kInvalid, "lifespan_alpha"));
  EXPECT_TRUE(IsError(bad([](BandOptions& o) { o.segment_length_world = 1e-6, o.limit_world = 1; }), kInvalid,
                      "100000 segments"));
  EXPECT_TRUE(IsError(validateBandOptions(Grid({0, 0, 0}, 0.0, {16, 16, 16}), BandOptions{}), kInvalid, "grid: voxel size"));
}

TEST(EngineControl, PreconditionsThrowInvalidArgument) {
  const Grid g({0, 0, 0}, 1.0, {16, 16, 16});
  auto noop = [](SegmentBricks&&) {};
  Seeds outside;
  outside.points = {{1, 1, 1}};
  outside.band = {{{16, 0, 0}, 0}};
  EXPECT_THROW(computeBandField(g, outside, BandOptions{}, noop), std::invalid_argument);
  Seeds bad_site;
  bad_site.points = {{1, 1, 1}};
  bad_site.band = {{{1, 1, 1}, 5}};
  EXPECT_THROW(computeBandField(g, bad_site, BandOptions{}, noop), std::invalid_argument);
  Seeds ok;
  ok.points = {{1, 1, 1}};
  ok.band = {{{1, 1, 1}, 0}};
  BandOptions bad;
  bad.limit_world = -2;
  EXPECT_THROW(computeBandField(g, ok, bad, noop), std::invalid_argument);
  EXPECT_THROW(computeBandField(Grid({0, 0, 0}, 0.0, {16, 16, 16}), ok, BandOptions{}, noop),
               std::invalid_argument);
}

}  // namespace
}  // namespace distband

// Helpers shared by the benchmark programs: a steady clock and seconds since a time point, the median of timings,
// peak RSS of this process, running a child command (tests/support/run_command.h), reading the peak RSS that
// `/usr/bin/time -v` reports for it, and the seed volumes the benches share. Header-only; bench code only.
#pragma once

#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <tbb/parallel_for.h>

#include "core/types.h"
#include "tests/support/run_command.h"

namespace distband::bench {

using Clock = std::chrono::steady_clock;

/// Seconds from `t` to now.
inline double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

/// Median of a non-empty sample (the mean of the middle two for an even count).
inline double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

/// Peak resident set size of this process so far, in MiB (ru_maxrss is in KiB on Linux).
inline double peakRssMb() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_maxrss / 1024.0;
}

/// Runs a shell command, returning its stdout and exit status (tests/support/run_command.h).
using distband::runCommand;

/// The "Maximum resident set size" of `/usr/bin/time -v` output, in MiB.
inline std::optional<double> timeVPeakRssMb(const std::string& time_v_output) {
  constexpr const char* kKey = "Maximum resident set size (kbytes):";
  const size_t p = time_v_output.find(kKey);
  if (p == std::string::npos) return std::nullopt;
  return std::atof(time_v_output.c_str() + p + std::char_traits<char>::length(kKey)) / 1024.0;
}

/// An n^3 mask (x fastest) of a closed sphere shell 2 voxels thick, radius 0.3 n, centre off the lattice symmetry.
inline std::vector<uint8_t> sphereShellMask(int n) {
  std::vector<uint8_t> mask(size_t(n) * n * n, 0);
  const Vec3d c{0.5 * n + 0.25, 0.5 * n - 0.15, 0.5 * n + 0.35};
  const double r = 0.3 * n;
  tbb::parallel_for(0, n, [&](int z) {
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double d = (Vec3d{double(x), double(y), double(z)} - c).length();
        if (std::abs(d - r) <= 1.0) mask[(size_t(z) * n + y) * n + x] = 1;
      }
  });
  return mask;
}

/// An n^3 mask of 40 solid balls, radius 2%..8% of n, centres in the inner 80% of the box (seeded: reproducible).
inline std::vector<uint8_t> randomBlobsMask(int n) {
  std::vector<uint8_t> mask(size_t(n) * n * n, 0);
  std::vector<std::pair<Vec3d, double>> balls;
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> uc(0.1 * n, 0.9 * n), ur(0.02 * n, 0.08 * n);
  for (int i = 0; i < 40; ++i) {
    const double x = uc(rng), y = uc(rng), z = uc(rng), r = ur(rng);
    balls.push_back({{x, y, z}, r});
  }
  tbb::parallel_for(0, n, [&](int z) {
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const Vec3d p{double(x), double(y), double(z)};
        for (const auto& [c, r] : balls)
          if ((p - c).lengthSqr() <= r * r) {
            mask[(size_t(z) * n + y) * n + x] = 1;
            break;
          }
      }
  });
  return mask;
}

}  // namespace distband::bench

// Helpers shared by the benchmark programs: a steady clock and seconds since a time point, the median of timings,
// peak RSS of this process, running a child command (tests/support/run_command.h), reading the peak RSS that
// `/usr/bin/time -v` reports for it, writing a results file, and the seed and label volumes the benches share.
// Header-only; bench code only.
#pragma once

#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <tbb/parallel_for.h>

#include "core/seeds/label_volume.h"
#include "core/types.h"
#include "tests/support/run_command.h"

namespace distband::bench {

using Clock = std::chrono::steady_clock;

/// Seconds from `t` to now.
inline double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

/// Writes a results file (a bench's Markdown table), making its folder first; a failure is said on stderr (a missing
/// --out-dir folder used to drop the table without a word). False on failure.
inline bool writeResultFile(const std::string& path, const std::string& text) {
  const std::filesystem::path p(path);
  std::error_code ec;
  if (p.has_parent_path()) std::filesystem::create_directories(p.parent_path(), ec);
  std::ofstream out(p, std::ios::binary);
  out << text;
  out.close();
  if (out) return true;
  std::fprintf(stderr, "cannot write %s\n", path.c_str());
  return false;
}

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

/// An n^3 label volume (x fastest) of `labels` regions: the cells of a lattice of about labels^(1/3) per axis, their
/// faces warped by sines so boundaries run in every direction, labelled 1..labels in a shuffled order, with every
/// tenth region (when there are ten or more) the background, 0. uint16 below 65536 labels, else uint32. Seeded.
inline LabelVolume labelRegions(int n, int labels, uint64_t seed = 11) {
  const int per_axis = std::max(1, int(std::ceil(std::cbrt(double(labels)) - 1e-9)));
  const double cell = double(n) / per_axis;
  std::vector<uint32_t> ids(size_t(per_axis) * per_axis * per_axis);
  std::mt19937_64 rng(seed);
  for (size_t i = 0; i < ids.size(); ++i) ids[i] = uint32_t(i % size_t(labels)) + 1;
  std::shuffle(ids.begin(), ids.end(), rng);
  if (labels >= 10)
    for (uint32_t& id : ids)
      if (id % 10 == 0) id = 0;
  const VoxelType type = labels < 65536 ? VoxelType::kUint16 : VoxelType::kUint32;
  const size_t w = voxelTypeBytes(type);
  auto bytes = std::make_shared<std::vector<uint8_t>>(size_t(n) * n * n * w);
  const double amp = 0.15 * cell, period = 0.7 * n;
  tbb::parallel_for(0, n, [&](int z) {
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double wx = x + amp * std::sin(6.2831853 * (y + 0.5 * z) / period);
        const double wy = y + amp * std::sin(6.2831853 * (z + 0.3 * x) / period);
        const double wz = z + amp * std::sin(6.2831853 * (x + 0.7 * y) / period);
        auto index = [&](double v) { return std::clamp(int(std::floor(v / cell)), 0, per_axis - 1); };
        const uint32_t id = ids[(size_t(index(wz)) * per_axis + index(wy)) * per_axis + index(wx)];
        std::memcpy(bytes->data() + ((size_t(z) * n + y) * n + x) * w, &id, w);
      }
  });
  return LabelVolume({n, n, n}, type, bytes);
}

}  // namespace distband::bench

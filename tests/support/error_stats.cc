#include "tests/support/error_stats.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstdio>

namespace distband::oracle {

ErrorStats compareToOracle(const std::vector<float>& got_world, const std::vector<double>& expected_vox,
                           double voxel_size, const std::vector<uint8_t>* consider, double off_tolerance_vox) {
  ErrorStats s;
  double sum = 0;
  const size_t n = std::min(got_world.size(), expected_vox.size());
  for (size_t i = 0; i < n; ++i) {
    if (consider && !(*consider)[i]) continue;
    const float expected = static_cast<float>(expected_vox[i] * voxel_size);
    double err = std::fabs(double(got_world[i]) - double(expected)) / voxel_size;
    if (std::isnan(err)) err = std::numeric_limits<double>::infinity();
    ++s.count;
    sum += err;
    if (err > off_tolerance_vox) ++s.off;
    if (s.worst_index < 0 || err > s.max_err_vox) {
      s.max_err_vox = err;
      s.worst_index = static_cast<int64_t>(i);
      s.worst_expected_world = expected;
      s.worst_got_world = got_world[i];
    }
  }
  if (s.count) {
    s.mean_err_vox = sum / double(s.count);
    s.frac_off = double(s.off) / double(s.count);
  }
  return s;
}

std::string formatErrorStats(const ErrorStats& s, int nx, int ny) {
  char buf[256];
  int64_t i = s.worst_index < 0 ? 0 : s.worst_index;
  const int x = int(i % nx), y = int((i / nx) % ny), z = int(i / (int64_t(nx) * ny));
  std::snprintf(buf, sizeof buf, "max %.3g mean %.3g off %lld/%lld (%.3g) worst@(%d,%d,%d) exp %.7g got %.7g",
                s.max_err_vox, s.mean_err_vox, static_cast<long long>(s.off), static_cast<long long>(s.count),
                s.frac_off, x, y, z, s.worst_expected_world, s.worst_got_world);
  return buf;
}

}  // namespace distband::oracle

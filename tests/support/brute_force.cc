#include "tests/support/brute_force.h"

#include <cstddef>
#include <limits>

namespace distband::oracle {

std::vector<double> bruteForceDistanceSqr(int nx, int ny, int nz, const std::vector<std::array<double, 3>>& points) {
  std::vector<double> out(static_cast<size_t>(nx) * ny * nz, std::numeric_limits<double>::infinity());
  size_t i = 0;
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x, ++i) {
        double best = std::numeric_limits<double>::infinity();
        for (const auto& p : points) {
          const double dx = x - p[0], dy = y - p[1], dz = z - p[2];
          const double d2 = dx * dx + dy * dy + dz * dz;
          if (d2 < best) best = d2;
        }
        out[i] = best;
      }
  return out;
}

}  // namespace distband::oracle

#include "tests/support/brute_force.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>

namespace distband::oracle {

std::vector<double> bruteForceDistanceSqr(int nx, int ny, int nz, const std::vector<std::array<double, 3>>& points) {
  return bruteForceDistanceSqr(nx, ny, nz, points, {1, 1, 1});
}

std::vector<double> bruteForceDistanceSqr(int nx, int ny, int nz, const std::vector<std::array<double, 3>>& points,
                                          const std::array<double, 3>& s) {
  std::vector<double> out(static_cast<size_t>(nx) * ny * nz, std::numeric_limits<double>::infinity());
  size_t i = 0;
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x, ++i) {
        double best = std::numeric_limits<double>::infinity();
        for (const auto& p : points) {
          const double dx = s[0] * (x - p[0]), dy = s[1] * (y - p[1]), dz = s[2] * (z - p[2]);
          const double d2 = dx * dx + dy * dy + dz * dz;
          if (d2 < best) best = d2;
        }
        out[i] = best;
      }
  return out;
}

namespace {

struct Voxel {
  int x, y, z;
  uint32_t label;
};

double dist2(const Voxel& a, int x, int y, int z, const std::array<double, 3>& s) {
  const double dx = s[0] * (a.x - x), dy = s[1] * (a.y - y), dz = s[2] * (a.z - z);
  return dx * dx + dy * dy + dz * dz;
}

}  // namespace

std::vector<double> otherLabelDistance(int nx, int ny, int nz, const std::vector<uint32_t>& labels,
                                       const std::array<double, 3>& s, bool black_border) {
  std::vector<Voxel> all;
  all.reserve(labels.size());
  size_t i = 0;
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x, ++i) all.push_back({x, y, z, labels[i]});
  if (black_border) {  // one layer of label-0 voxels around the grid (its corners are never nearest)
    for (int z = -1; z <= nz; ++z)
      for (int y = -1; y <= ny; ++y)
        for (int x = -1; x <= nx; ++x)
          if (x < 0 || y < 0 || z < 0 || x == nx || y == ny || z == nz) all.push_back({x, y, z, 0});
  }
  std::vector<double> out(labels.size(), 0.0);
  for (size_t v = 0; v < labels.size(); ++v) {
    if (labels[v] == 0) continue;
    const Voxel& p = all[v];
    double best = std::numeric_limits<double>::infinity();
    for (const Voxel& q : all)
      if (q.label != p.label) best = std::min(best, dist2(q, p.x, p.y, p.z, s));
    out[v] = std::sqrt(best);
  }
  return out;
}

void nearestSeedLabel(int nx, int ny, int nz, const std::vector<uint32_t>& labels, const std::array<double, 3>& s,
                      std::vector<uint32_t>* label, std::vector<bool>* unique) {
  std::vector<Voxel> seeds;
  size_t i = 0;
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x, ++i)
        if (labels[i] != 0) seeds.push_back({x, y, z, labels[i]});
  label->assign(labels.size(), 0);
  unique->assign(labels.size(), false);
  i = 0;
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x, ++i) {
        double best = std::numeric_limits<double>::infinity(), second = best;
        uint32_t best_label = 0;
        for (const Voxel& q : seeds) {
          const double d = dist2(q, x, y, z, s);
          if (d < best) {
            second = best;
            best = d;
            best_label = q.label;
          } else if (d < second) {
            second = d;
          }
        }
        (*label)[i] = best_label;
        (*unique)[i] = second > best * (1 + 1e-9) + 1e-12;
      }
}

}  // namespace distband::oracle

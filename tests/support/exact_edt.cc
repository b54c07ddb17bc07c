#include "tests/support/exact_edt.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace distband::oracle {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// 1-D squared distance transform of f (n samples, stride apart in `data`), in place. Infinite samples never
// join the lower envelope, so an all-infinite line stays infinite and no inf - inf arithmetic occurs.
void transformLine(double* data, int n, long stride, double w2, std::vector<double>& f, std::vector<int>& v,
                   std::vector<double>& z) {
  for (int q = 0; q < n; ++q) f[q] = data[q * stride];
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (f[q] == kInf) continue;
    if (k < 0) {
      k = 0;
      v[0] = q;
      z[0] = -kInf;
      z[1] = kInf;
      continue;
    }
    double s;
    for (;;) {
      const int p = v[k];
      s = ((f[q] + w2 * double(q) * q) - (f[p] + w2 * double(p) * p)) / (2.0 * w2 * (q - p));
      if (s > z[k]) break;
      --k;  // z[0] = -inf, so k never drops below 0 here
    }
    ++k;
    v[k] = q;
    z[k] = s;
    z[k + 1] = kInf;
  }
  if (k < 0) return;  // the whole line is infinite
  k = 0;
  for (int q = 0; q < n; ++q) {
    while (z[k + 1] < q) ++k;
    const double d = q - v[k];
    data[q * stride] = w2 * d * d + f[v[k]];
  }
}

}  // namespace

std::vector<double> edtSqr(int nx, int ny, int nz, const std::vector<uint8_t>& mask) {
  const double unit[3] = {1, 1, 1};
  return edtSqr(nx, ny, nz, mask, unit);
}

std::vector<double> signedEdt(int nx, int ny, int nz, const std::vector<uint8_t>& mask) {
  const double unit[3] = {1, 1, 1};
  return signedEdt(nx, ny, nz, mask, unit);
}

std::vector<double> edtSqr(int nx, int ny, int nz, const std::vector<uint8_t>& mask, const double spacing[3]) {
  const size_t n = static_cast<size_t>(nx) * ny * nz;
  std::vector<double> d(n);
  for (size_t i = 0; i < n; ++i) d[i] = mask[i] ? 0.0 : kInf;
  const int m = std::max({nx, ny, nz});
  std::vector<double> f(m), z(m + 1);
  std::vector<int> v(m);
  const long sx = 1, sy = nx, sz = long(nx) * ny;
  for (int z_ = 0; z_ < nz; ++z_)
    for (int y = 0; y < ny; ++y) transformLine(&d[z_ * sz + y * sy], nx, sx, spacing[0] * spacing[0], f, v, z);
  for (int z_ = 0; z_ < nz; ++z_)
    for (int x = 0; x < nx; ++x) transformLine(&d[z_ * sz + x], ny, sy, spacing[1] * spacing[1], f, v, z);
  for (int y = 0; y < ny; ++y)
    for (int x = 0; x < nx; ++x) transformLine(&d[y * sy + x], nz, sz, spacing[2] * spacing[2], f, v, z);
  return d;
}

std::vector<double> signedEdt(int nx, int ny, int nz, const std::vector<uint8_t>& mask, const double spacing[3]) {
  std::vector<uint8_t> inverse(mask.size());
  for (size_t i = 0; i < mask.size(); ++i) inverse[i] = mask[i] == 0;
  const std::vector<double> outside = edtSqr(nx, ny, nz, mask, spacing);    // distance to the nearest mask voxel
  const std::vector<double> inside = edtSqr(nx, ny, nz, inverse, spacing);  // to the nearest non-mask voxel
  std::vector<double> out(mask.size());
  for (size_t i = 0; i < mask.size(); ++i) out[i] = std::sqrt(outside[i]) - std::sqrt(inside[i]);
  return out;
}

}  // namespace distband::oracle

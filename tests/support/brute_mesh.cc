#include "tests/support/brute_mesh.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace distband::testing {
namespace {

using V = std::array<double, 3>;
V vec(const Vec3d& a) { return {a.x, a.y, a.z}; }
V sub(const V& a, const V& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double dot(const V& a, const V& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
V cross(const V& a, const V& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double norm(const V& a) { return std::sqrt(dot(a, a)); }

// Squared distance from p to segment [a, b].
double segmentDist2(const V& p, const V& a, const V& b) {
  const V ab = sub(b, a), ap = sub(p, a);
  const double len2 = dot(ab, ab);
  const double t = len2 > 0 ? std::clamp(dot(ap, ab) / len2, 0.0, 1.0) : 0.0;
  const V q = {a[0] + t * ab[0] - p[0], a[1] + t * ab[1] - p[1], a[2] + t * ab[2] - p[2]};
  return dot(q, q);
}

// Squared point-triangle distance: if the projection of p onto the plane falls inside the triangle (all three
// edge half-space tests agree with the normal), the plane distance; otherwise the nearest of the three edges.
double triangleDist2(const V& p, const V& a, const V& b, const V& c) {
  const V n = cross(sub(b, a), sub(c, a));
  const double n2 = dot(n, n);
  if (n2 > 0) {
    const bool in = dot(cross(sub(b, a), sub(p, a)), n) >= 0 && dot(cross(sub(c, b), sub(p, b)), n) >= 0 &&
                    dot(cross(sub(a, c), sub(p, c)), n) >= 0;
    if (in) {
      const double h = dot(sub(p, a), n);
      return h * h / n2;
    }
  }
  return std::min({segmentDist2(p, a, b), segmentDist2(p, b, c), segmentDist2(p, c, a)});
}

}  // namespace

double bruteDistance(const TriangleMesh& mesh, const Vec3d& p, uint32_t* tri) {
  const V q = vec(p);
  double best = std::numeric_limits<double>::infinity();
  uint32_t best_t = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& f = mesh.triangles[t];
    const double d2 = triangleDist2(q, vec(mesh.vertices[f[0]]), vec(mesh.vertices[f[1]]), vec(mesh.vertices[f[2]]));
    if (d2 < best) best = d2, best_t = static_cast<uint32_t>(t);
  }
  if (tri) *tri = best_t;
  return std::sqrt(best);
}

double bruteWinding(const TriangleMesh& mesh, const Vec3d& p) {
  const V q = vec(p);
  double total = 0;
  for (const auto& f : mesh.triangles) {
    const V a = sub(vec(mesh.vertices[f[0]]), q), b = sub(vec(mesh.vertices[f[1]]), q),
            c = sub(vec(mesh.vertices[f[2]]), q);
    const double la = norm(a), lb = norm(b), lc = norm(c);
    const double det = dot(a, cross(b, c));
    const double div = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
    total += 2.0 * std::atan2(det, div);
  }
  return total / (4.0 * std::numbers::pi);
}

double bruteSignedDistance(const TriangleMesh& mesh, const Vec3d& p) {
  const double d = bruteDistance(mesh, p);
  return bruteWinding(mesh, p) > 0.5 ? -d : d;
}

TriangleMesh makeSphereMesh(const Vec3d& center, double radius, int rings, int segments) {
  TriangleMesh m;
  m.vertices.push_back(center + Vec3d{0, 0, radius});  // north pole
  for (int i = 1; i < rings; ++i) {
    const double th = std::numbers::pi * i / rings;
    for (int j = 0; j < segments; ++j) {
      const double ph = 2 * std::numbers::pi * j / segments;
      m.vertices.push_back(center + Vec3d{radius * std::sin(th) * std::cos(ph), radius * std::sin(th) * std::sin(ph),
                                          radius * std::cos(th)});
    }
  }
  m.vertices.push_back(center + Vec3d{0, 0, -radius});  // south pole
  const uint32_t south = static_cast<uint32_t>(m.vertices.size() - 1);
  auto at = [&](int ring, int seg) { return uint32_t(1 + (ring - 1) * segments + (seg % segments)); };
  for (int j = 0; j < segments; ++j) m.triangles.push_back({0, at(1, j), at(1, j + 1)});
  for (int i = 1; i + 1 < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      m.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      m.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  for (int j = 0; j < segments; ++j) m.triangles.push_back({south, at(rings - 1, j + 1), at(rings - 1, j)});
  return m;
}

double sphereSdf(const Vec3d& center, double radius, const Vec3d& p) { return (p - center).length() - radius; }

TriangleMesh makeBoxMesh(const Vec3d& lo, const Vec3d& hi) {
  TriangleMesh m;
  for (int i = 0; i < 8; ++i) m.vertices.push_back({i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z});
  // Quads listed counter-clockwise seen from outside.
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.triangles.push_back({uint32_t(q[0]), uint32_t(q[1]), uint32_t(q[2])});
    m.triangles.push_back({uint32_t(q[0]), uint32_t(q[2]), uint32_t(q[3])});
  }
  return m;
}

double boxSdf(const Vec3d& lo, const Vec3d& hi, const Vec3d& p) {
  const Vec3d c = (lo + hi) * 0.5, half = (hi - lo) * 0.5;
  const double qx = std::abs(p.x - c.x) - half.x, qy = std::abs(p.y - c.y) - half.y, qz = std::abs(p.z - c.z) - half.z;
  const double outside = std::sqrt(std::pow(std::max(qx, 0.0), 2) + std::pow(std::max(qy, 0.0), 2) +
                                   std::pow(std::max(qz, 0.0), 2));
  return outside + std::min(std::max({qx, qy, qz}), 0.0);
}

TriangleMesh makeTorusMesh(const Vec3d& center, double R, double r, int nu, int nv) {
  TriangleMesh m;
  for (int i = 0; i < nu; ++i) {
    const double u = 2 * std::numbers::pi * i / nu;
    for (int j = 0; j < nv; ++j) {
      const double v = 2 * std::numbers::pi * j / nv;
      m.vertices.push_back(center + Vec3d{(R + r * std::cos(v)) * std::cos(u), (R + r * std::cos(v)) * std::sin(u),
                                          r * std::sin(v)});
    }
  }
  auto at = [&](int i, int j) { return uint32_t((i % nu) * nv + (j % nv)); };
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      m.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      m.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  return m;
}

double torusSdf(const Vec3d& center, double R, double r, const Vec3d& p) {
  const Vec3d q = p - center;
  const double ring = std::sqrt(q.x * q.x + q.y * q.y) - R;
  return std::sqrt(ring * ring + q.z * q.z) - r;
}

}  // namespace distband::testing

#include "core/geometry.h"

#include <initializer_list>

namespace distband {

Vec3d closestPointOnTriangle(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  const Vec3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return a + ab * v;
  }
  const Vec3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return a + ac * w;
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return b + (c - b) * w;
  }
  const double denom = va + vb + vc;
  if (!(denom > 0)) {  // degenerate (zero-area) triangle: best of its three edges
    auto onSeg = [&](const Vec3d& s0, const Vec3d& s1) {
      const Vec3d d = s1 - s0;
      const double len2 = d.lengthSqr();
      double t = len2 > 0 ? (p - s0).dot(d) / len2 : 0.0;
      t = t < 0 ? 0 : (t > 1 ? 1 : t);
      return s0 + d * t;
    };
    Vec3d best = onSeg(a, b);
    for (const Vec3d& q : {onSeg(b, c), onSeg(c, a)})
      if ((p - q).lengthSqr() < (p - best).lengthSqr()) best = q;
    return best;
  }
  const double v = vb / denom, w = vc / denom;
  return a + ab * v + ac * w;
}

}  // namespace distband

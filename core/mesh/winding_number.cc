#include "core/mesh/winding_number.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

namespace distband {
namespace {
constexpr uint32_t kLeafSize = 8;
constexpr uint32_t kParallelBuild = 16384;  // nodes of this many triangles build their halves side by side
// The largest third-order term (times 4 pi) a cluster's expansion may leave out: query(), coarseQuery(),
// roughQuery().
constexpr double kThirdOrderTolerance = 1e-2;
constexpr double kCoarseThirdOrderTolerance = 1e-1;
constexpr double kRoughThirdOrderTolerance = 1.0;
// How far, in its radii, a cluster must be for roughQuery() to take its expansion (query() and coarseQuery(): the
// constructor's beta).
constexpr double kRoughBeta = 1.25;

Vec3d centroid(const std::array<Vec3d, 3>& t) { return (t[0] + t[1] + t[2]) * (1.0 / 3.0); }

// Van Oosterom–Strackee: a triangle's solid angle seen from the origin is 2 atan2(num, den).
struct HalfAngle {
  double num, den;
};
HalfAngle halfAngle(const std::array<Vec3d, 3>& t, const Vec3d& p) {
  const Vec3d a = t[0] - p, b = t[1] - p, c = t[2] - p;
  const double la = a.length(), lb = b.length(), lc = c.length();
  return {a.dot(b.cross(c)), la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la};
}

// The sum of many atan2(num_i, den_i) as the argument of the product of den_i + i num_i: a complex multiply per
// triangle instead of an atan2 (libm's atan2 was 55 % of an open mesh's narrow band: winding-number signs query
// dozens of near triangles per voxel). Each factor turns the product by less than pi, so the turns past the branch
// cut are counted from half-planes alone: a positive turn ends below the real axis only by crossing its negative side
// (and a negative one above it likewise); the readout uses the same convention, so the sum is consistent to
// rounding whatever the product's values. Factors with num = 0 (the point in a triangle's plane: angle 0 or +-pi,
// decided by signed zeros) keep atan2.
class AngleSum {
 public:
  void add(const HalfAngle& h) {
    if (h.num == 0) {
      exact_ += std::atan2(h.num, h.den);
      return;
    }
    const bool was_upper = upper(re_, im_);
    const double re = re_ * h.den - im_ * h.num, im = re_ * h.num + im_ * h.den;
    if (h.num > 0 && was_upper && !upper(re, im)) ++turns_;
    else if (h.num < 0 && !was_upper && upper(re, im)) --turns_;
    const double scale = 1.0 / (std::abs(re) + std::abs(im));  // factors are cubes of distances: keep it near 1
    re_ = re * scale, im_ = im * scale;
  }
  double radians() const {
    const double arg = im_ == 0 ? (re_ < 0 ? std::numbers::pi : 0.0) : std::atan2(im_, re_);
    return arg + 2.0 * std::numbers::pi * turns_ + exact_;
  }

 private:
  // The half-plane of angles (0, pi], the negative real axis included (read as +pi).
  static bool upper(double re, double im) { return im > 0 || (im == 0 && re < 0); }
  double re_ = 1, im_ = 0, exact_ = 0;
  int64_t turns_ = 0;
};
}  // namespace

WindingNumber::WindingNumber(std::vector<std::array<Vec3d, 3>> triangles, double beta, const Interrupter* interrupter)
    : tris_(std::move(triangles)), beta2_(beta * beta), interrupter_(interrupter) {
  ids_.resize(tris_.size());
  for (uint32_t i = 0; i < ids_.size(); ++i) ids_[i] = i;
  // Each triangle's centroid once (the split's sort key and every level's bounds read it).
  centroids_.resize(tris_.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, tris_.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) centroids_[i] = centroid(tris_[i]);
  });
  nodes_.resize(tris_.empty() ? 0 : nodeCount(uint32_t(tris_.size())));
  if (!tris_.empty()) build(0, static_cast<uint32_t>(tris_.size()), 0);
  std::vector<Vec3d>().swap(centroids_);
  // The build ordered ids_; put the triangles in the same order (leaves then hold contiguous ranges).
  std::vector<std::array<Vec3d, 3>> ordered(tris_.size());
  position_.resize(tris_.size());
  for (uint32_t i = 0; i < ids_.size(); ++i) {
    ordered[i] = tris_[ids_[i]];
    position_[ids_[i]] = i;
  }
  tris_ = std::move(ordered);
  interrupter_ = nullptr;
}

uint32_t WindingNumber::nodeCount(uint32_t triangles) {
  // A node over m > kLeafSize triangles has halves of floor(m / 2) and ceil(m / 2): so the counts of m and m + 1
  // follow from those of h = floor(m / 2) and h + 1, in O(log m) steps.
  struct Pair {
    uint32_t of_m, of_next;
  };
  const auto counts = [](const auto& self, uint32_t m) -> Pair {
    if (m + 1 <= kLeafSize) return {1, 1};
    const uint32_t h = m / 2;
    const Pair c = self(self, h);
    const uint32_t of_m = m <= kLeafSize ? 1 : (m % 2 == 0 ? 1 + 2 * c.of_m : 1 + c.of_m + c.of_next);
    const uint32_t of_next = m % 2 == 0 ? 1 + c.of_m + c.of_next : 1 + 2 * c.of_next;
    return {of_m, of_next};
  };
  return counts(counts, triangles).of_m;
}

void WindingNumber::build(uint32_t begin, uint32_t end, uint32_t id) {
  // Nodes of thousands of triangles take milliseconds each level: poll there (a stopped build is discarded).
  if (end - begin >= 4096 && isInterrupted(interrupter_)) return;
  Node n{};
  n.begin = begin, n.end = end;
  double total = 0;
  const auto tri = [&](uint32_t i) -> const std::array<Vec3d, 3>& { return tris_[ids_[i]]; };
  Vec3d weighted{}, lo = centroids_[ids_[begin]], hi = lo;
  for (uint32_t i = begin; i < end; ++i) {
    const auto& t = tri(i);
    const Vec3d av = (t[1] - t[0]).cross(t[2] - t[0]) * 0.5;
    const double a = av.length();
    const Vec3d c = centroids_[ids_[i]];
    n.area = n.area + av;
    n.abs_area += a;
    weighted = weighted + c * a;
    total += a;
    lo = {std::min(lo.x, c.x), std::min(lo.y, c.y), std::min(lo.z, c.z)};
    hi = {std::max(hi.x, c.x), std::max(hi.y, c.y), std::max(hi.z, c.z)};
  }
  n.center = total > 0 ? weighted * (1.0 / total) : (lo + hi) * 0.5;
  for (uint32_t i = begin; i < end; ++i) {
    const auto& t = tri(i);
    for (const Vec3d& v : t) n.radius2 = std::max(n.radius2, (v - n.center).lengthSqr());
    const Vec3d av = (t[1] - t[0]).cross(t[2] - t[0]) * 0.5, d = centroids_[ids_[i]] - n.center;
    const double a[3] = {av.x, av.y, av.z}, e[3] = {d.x, d.y, d.z};
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) n.moment[3 * r + c] += a[r] * e[c];
  }
  if (end - begin > kLeafSize) {
    const Vec3d e = hi - lo;
    const int axis = e.x >= e.y && e.x >= e.z ? 0 : (e.y >= e.z ? 1 : 2);
    const uint32_t mid = begin + (end - begin) / 2;
    auto key = [&](uint32_t i) {
      const Vec3d& c = centroids_[i];
      return axis == 0 ? c.x : (axis == 1 ? c.y : c.z);
    };
    std::nth_element(ids_.begin() + begin, ids_.begin() + mid, ids_.begin() + end,
                     [&](uint32_t a, uint32_t b) { return key(a) < key(b); });
    // Depth first, left before right: the same node numbers whichever thread builds which half.
    n.left = id + 1;
    n.right = id + 1 + nodeCount(mid - begin);
    const auto left = [&] { build(begin, mid, n.left); };
    const auto right = [&] { build(mid, end, n.right); };
    if (end - begin >= kParallelBuild)
      tbb::parallel_invoke(left, right);
    else
      left(), right();
  }
  nodes_[id] = n;
}

double WindingNumber::solidAngle(const std::array<Vec3d, 3>& t, const Vec3d& p) const {
  const HalfAngle h = halfAngle(t, p);
  return 2.0 * std::atan2(h.num, h.den);
}

double WindingNumber::exact(const Vec3d& p) const {
  double sum = 0;
  for (const auto& t : tris_) sum += solidAngle(t, p);
  return sum / (4.0 * std::numbers::pi);
}

double WindingNumber::query(const Vec3d& p) const { return sum(p, UINT32_MAX, kThirdOrderTolerance, beta2_); }

double WindingNumber::coarseQuery(const Vec3d& p) const {
  return sum(p, UINT32_MAX, kCoarseThirdOrderTolerance, beta2_);
}

double WindingNumber::roughQuery(const Vec3d& p) const {
  return sum(p, UINT32_MAX, kRoughThirdOrderTolerance, kRoughBeta * kRoughBeta);
}

double WindingNumber::principalValue(uint32_t t) const {
  const uint32_t at = position_[t];
  return sum(centroid(tris_[at]), at, kThirdOrderTolerance, beta2_);
}

double WindingNumber::sum(const Vec3d& p, uint32_t skip, double tolerance, double beta2) const {
  if (nodes_.empty()) return 0;
  double far = 0;
  AngleSum near;  // the exactly summed triangles' half solid angles
  uint32_t stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = nodes_[stack[--top]];
    const Vec3d d = n.center - p;
    const double d2 = d.lengthSqr();
    // Far enough for the expansion: beyond beta radii, and its next (third-order) term, of size
    // area * radius^2 / distance^4, small enough.
    if (d2 > beta2 * n.radius2 && n.abs_area * n.radius2 < tolerance * d2 * d2) {
      // Far field of the cluster's area elements a at x: a . (x - p) / |x - p|^3 expanded at the center: the dipole,
      // then the second-order term trace(J M^T) with J = I / r^3 - 3 r r^T / r^5 (r = center - p).
      const double inv_r = 1.0 / std::sqrt(d2), inv_r3 = inv_r * inv_r * inv_r;
      const std::array<double, 9>& m = n.moment;
      const double r[3] = {d.x, d.y, d.z};
      double rmr = 0;
      for (int i = 0; i < 3; ++i) rmr += r[i] * (m[3 * i] * r[0] + m[3 * i + 1] * r[1] + m[3 * i + 2] * r[2]);
      far += n.area.dot(d) * inv_r3 + ((m[0] + m[4] + m[8]) * inv_r3 - 3.0 * rmr * inv_r3 * inv_r * inv_r);
    } else if (n.left == 0) {
      for (uint32_t i = n.begin; i < n.end; ++i)
        if (i != skip) near.add(halfAngle(tris_[i], p));
    } else {
      stack[top++] = n.left;
      stack[top++] = n.right;
    }
  }
  return (far + 2.0 * near.radians()) / (4.0 * std::numbers::pi);
}

}  // namespace distband

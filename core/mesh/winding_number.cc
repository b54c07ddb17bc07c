#include "core/mesh/winding_number.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace distband {
namespace {
constexpr uint32_t kLeafSize = 8;
Vec3d centroid(const std::array<Vec3d, 3>& t) { return (t[0] + t[1] + t[2]) * (1.0 / 3.0); }
}  // namespace

WindingNumber::WindingNumber(std::vector<std::array<Vec3d, 3>> triangles, double beta, const Interrupter* interrupter)
    : tris_(std::move(triangles)), beta2_(beta * beta), interrupter_(interrupter) {
  nodes_.reserve(2 * tris_.size() / kLeafSize + 2);
  if (!tris_.empty()) build(0, static_cast<uint32_t>(tris_.size()));
  interrupter_ = nullptr;
}

uint32_t WindingNumber::build(uint32_t begin, uint32_t end) {
  const uint32_t id = static_cast<uint32_t>(nodes_.size());
  nodes_.push_back({});
  // Nodes of thousands of triangles take milliseconds each level: poll there (a stopped build is discarded).
  if (end - begin >= 4096 && isInterrupted(interrupter_)) return id;
  Node n{};
  n.begin = begin, n.end = end;
  double total = 0;
  Vec3d weighted{}, lo = centroid(tris_[begin]), hi = lo;
  for (uint32_t i = begin; i < end; ++i) {
    const auto& t = tris_[i];
    const Vec3d av = (t[1] - t[0]).cross(t[2] - t[0]) * 0.5;
    const double a = av.length();
    n.area = n.area + av;
    weighted = weighted + centroid(t) * a;
    total += a;
    const Vec3d c = centroid(t);
    lo = {std::min(lo.x, c.x), std::min(lo.y, c.y), std::min(lo.z, c.z)};
    hi = {std::max(hi.x, c.x), std::max(hi.y, c.y), std::max(hi.z, c.z)};
  }
  n.center = total > 0 ? weighted * (1.0 / total) : (lo + hi) * 0.5;
  for (uint32_t i = begin; i < end; ++i)
    for (const Vec3d& v : tris_[i]) n.radius2 = std::max(n.radius2, (v - n.center).lengthSqr());
  if (end - begin > kLeafSize) {
    const Vec3d e = hi - lo;
    const int axis = e.x >= e.y && e.x >= e.z ? 0 : (e.y >= e.z ? 1 : 2);
    const uint32_t mid = begin + (end - begin) / 2;
    auto key = [axis](const std::array<Vec3d, 3>& t) {
      const Vec3d c = centroid(t);
      return axis == 0 ? c.x : (axis == 1 ? c.y : c.z);
    };
    std::nth_element(tris_.begin() + begin, tris_.begin() + mid, tris_.begin() + end,
                     [&](const auto& a, const auto& b) { return key(a) < key(b); });
    n.left = build(begin, mid);
    n.right = build(mid, end);
  }
  nodes_[id] = n;
  return id;
}

double WindingNumber::solidAngle(const std::array<Vec3d, 3>& t, const Vec3d& p) const {
  const Vec3d a = t[0] - p, b = t[1] - p, c = t[2] - p;
  const double la = a.length(), lb = b.length(), lc = c.length();
  const double num = a.dot(b.cross(c));
  const double den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
  return 2.0 * std::atan2(num, den);
}

double WindingNumber::exact(const Vec3d& p) const {
  double sum = 0;
  for (const auto& t : tris_) sum += solidAngle(t, p);
  return sum / (4.0 * std::numbers::pi);
}

double WindingNumber::query(const Vec3d& p) const {
  if (nodes_.empty()) return 0;
  double sum = 0;
  uint32_t stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = nodes_[stack[--top]];
    const Vec3d d = n.center - p;
    const double d2 = d.lengthSqr();
    if (d2 > beta2_ * n.radius2) {
      sum += n.area.dot(d) / (d2 * std::sqrt(d2));  // dipole: solid angle of a far area element
    } else if (n.left == 0) {
      for (uint32_t i = n.begin; i < n.end; ++i) sum += solidAngle(tris_[i], p);
    } else {
      stack[top++] = n.left;
      stack[top++] = n.right;
    }
  }
  return sum / (4.0 * std::numbers::pi);
}

}  // namespace distband

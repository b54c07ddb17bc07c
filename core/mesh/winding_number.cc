#include "core/mesh/winding_number.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <numbers>
#include <unordered_map>

#if defined(__SSE__)
#include <xmmintrin.h>
#endif

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_sort.h>

#include "core/mesh/triangle_mesh.h"

namespace distband {
namespace {
// Leaves of at most 4 triangles (2 to 4): a query sums a leaf's triangles exactly when it is near, and near a mesh of
// big triangles (a CAD part at 512^3) leaves of 8 put several far ones among them (rough queries near the teapot's rim
// 17 % cheaper than with 8, for nodes 2x as many: tests/core/mesh/winding_number_test.cc measures the errors).
constexpr uint32_t kLeafSize = 4;
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

// halfAngle of a leaf's triangles, four lanes at a time in single precision: a near query sums tens of triangles,
// and one at a time in double they were 45 % of its instructions. The corners are stored relative to the leaf's center
// and p is taken there in double, so the lanes see p's offsets to the corners to ~1e-7 of their length; the triple
// product is a . ((b - a) x (c - a)), whose normal is the triangle's own, stored (a . (b x c) cancels to 1e-3 and
// worse when p is tens of leaf radii away). Single precision decides the angle where the product and the complex factor
// den + i num are well clear of their rounding (a few 1e-7 of la lb lc: an angle within ~2e-5 radians); nearly in a
// triangle's plane, near an edge or at a corner (a point on the surface, whose angle its signed zeros decide) a lane is
// `unsure` and the caller takes halfAngle in double.
constexpr float kSureSine2 = 1e-8f;  // (num / (la |normal|))^2 at least this: p 1e-4 radians off the plane or more
// |den + i num| / (la lb lc) at least this (squared): both vanish on an edge, where their rounding would turn the
// angle.
constexpr float kSureModulus2 = 1e-4f;
constexpr float kSureCorner2 = 1e-4f;  // every corner at least 1/100 of the leaf's radius from p (squared)
// On x86-64 the functions that run these lanes also have an AVX2 clone, picked when the program loads (the same
// four-lane arithmetic, without FMA: the same values; the three-operand encoding spares the register copies SSE needs,
// ~100 M of the teapot's 4 502 M instructions at 512^3). Only functions called from this file: clang names a clone
// set's dispatcher apart, so a call from another file would not find it.
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define DISTBAND_AVX2_CLONE __attribute__((target_clones("avx2", "default")))
#else
#define DISTBAND_AVX2_CLONE
#endif
// The lanes' helpers are always inlined: each runs in the instructions of the clone it is called from, and eight-lane
// values never cross a call (whose convention for them differs with and without AVX: -Wpsabi's note). Clang checks
// that convention before it inlines and refuses an AVX2 clone's call to a helper compiled without AVX: its builds (the
// sanitizers', the fuzzers') run the eight lanes without an AVX2 clone, as pairs of four (the same values).
#if defined(__GNUC__) || defined(__clang__)
#define DISTBAND_LANES [[gnu::always_inline]] inline
#pragma GCC diagnostic ignored "-Wpsabi"
#else
#define DISTBAND_LANES inline
#endif
#if defined(__clang__)
#define DISTBAND_AVX2_CLONE_EIGHT_LANES
#else
#define DISTBAND_AVX2_CLONE_EIGHT_LANES DISTBAND_AVX2_CLONE
#endif
using Float4 = float __attribute__((vector_size(16)));
using Int4 = int32_t __attribute__((vector_size(16)));
// Eight lanes: a planned query reads its far clusters eight at a time and its near leaves two at a time
// (Plan::FarLanes, NearLanes; in the AVX2 clone one instruction where four lanes took two, and each lane's arithmetic
// is the same).
using Float8 = float __attribute__((vector_size(32)));
Float4 loadLanes(const float* lanes) {
  Float4 v;
  std::memcpy(&v, lanes, sizeof(Float4));
  return v;
}
using Double4 = double __attribute__((vector_size(32)));
template <class Half>
DISTBAND_LANES auto joinLanes(Half first, Half second) {
  return __builtin_shufflevector(first, second, 0, 1, 2, 3, 4, 5, 6, 7);
}
using Int8 = decltype(Float8{} < Float8{});
DISTBAND_LANES Float8 loadLanes8(const float* lanes) {
  Float8 v;
  std::memcpy(&v, lanes, sizeof(Float8));
  return v;
}
/// The first and second blocks of four lanes (Float4 or Int4) of eight.
template <class Half, class Whole>
DISTBAND_LANES std::array<Half, 2> splitLanes(const Whole& v) {
  static_assert(sizeof(Whole) == 2 * sizeof(Half));
  return {__builtin_shufflevector(v, v, 0, 1, 2, 3), __builtin_shufflevector(v, v, 4, 5, 6, 7)};
}
Float4 sqrtLanes(Float4 v) {
#if defined(__SSE__)
  return Float4(_mm_sqrt_ps(__m128(v)));
#else
  for (int k = 0; k < 4; ++k) v[k] = std::sqrt(v[k]);
  return v;
#endif
}
DISTBAND_LANES Float8 sqrtLanes(Float8 v) {
  const auto [first, second] = splitLanes<Float4>(v);
  return joinLanes(sqrtLanes(first), sqrtLanes(second));  // no eight-lane square root in every clone's instructions
}
// atan2 lane by lane (Cephes' atanf: |y| / |x| or its inverse reduced to [0, tan(pi/8)] about pi/4, an odd
// polynomial of degree 9, then the quadrant): within ~3e-7 radians. A near query's angles as one sum: the product of
// the factors den + i num (a complex multiply each instead of libm's atan2) was a serial chain, 15 % of a query.
template <class Lanes>
DISTBAND_LANES Lanes atan2Lanes(Lanes y, Lanes x) {
  const Lanes ax = x < 0 ? -x : x, ay = y < 0 ? -y : y;
  const Lanes big = ax > ay ? ax : ay, small = ax > ay ? ay : ax;
  const Lanes a = small / big;  // in [0, 1]
  const auto past = a > 0.41421356f;
  const Lanes t = past ? (a - 1.0f) / (a + 1.0f) : a, z = t * t;
  Lanes r = (((8.05374449538e-2f * z - 1.38776856032e-1f) * z + 1.99777106478e-1f) * z - 3.33329491539e-1f) * z * t + t;
  r = past ? r + float(std::numbers::pi / 4) : r;
  r = ay > ax ? float(std::numbers::pi / 2) - r : r;
  r = x < 0 ? float(std::numbers::pi) - r : r;
  return y < 0 ? -r : r;
}
/// The half solid angles of one leaf's triangles (Float4) or of two leaves' (Float8), `p` taken relative to each
/// leaf's center (`relative`: the lanes of its coordinates; `near_corner`: kSureCorner2 times each leaf's squared
/// radius) and `load(row)` giving a row of the leaves' lanes: corner[c][axis] as row 3 c + axis, then normal[k] as
/// row 9 + k.
template <class Lanes>
struct LeafHalfAngles {
  Lanes angle;                         // atan2(num, den), for the lanes that are sure
  decltype(Lanes{} < Lanes{}) unsure;  // per lane: all bits set where the caller must take halfAngle in double
  template <class Load>
  DISTBAND_LANES LeafHalfAngles(const Load& load, const std::array<Lanes, 3>& relative, Lanes near_corner) {
    const Lanes ax = load(0) - relative[0], ay = load(1) - relative[1], az = load(2) - relative[2];
    const Lanes bx = load(3) - relative[0], by = load(4) - relative[1], bz = load(5) - relative[2];
    const Lanes cx = load(6) - relative[0], cy = load(7) - relative[1], cz = load(8) - relative[2];
    const Lanes nx = load(9), ny = load(10), nz = load(11), n2 = load(12);
    const Lanes la2 = ax * ax + ay * ay + az * az, lb2 = bx * bx + by * by + bz * bz, lc2 = cx * cx + cy * cy + cz * cz;
    const Lanes la = sqrtLanes(la2), lb = sqrtLanes(lb2), lc = sqrtLanes(lc2);
    const Lanes num = ax * nx + ay * ny + az * nz;
    const Lanes ab = ax * bx + ay * by + az * bz, ac = ax * cx + ay * cy + az * cz, bc = bx * cx + by * cy + bz * cz;
    const Lanes product = la * lb * lc;
    const Lanes den = product + ab * lc + ac * lb + bc * la;
    unsure = num * num <= kSureSine2 * la2 * n2 || num * num + den * den <= kSureModulus2 * product * product ||
             la2 <= near_corner || lb2 <= near_corner || lc2 <= near_corner;
    angle = atan2Lanes(num, den);
  }
};
/// A leaf's row (LeafHalfAngles' numbering).
template <class Leaf>
const float* leafRow(const Leaf& leaf, int row) {
  return row < 9 ? leaf.corner[row / 3][row % 3] : leaf.normal[row - 9];
}
/// farTerm of a plan's clusters (Plan::FarLanes) lane by lane, p relative to the plan's origin; `load(row)` gives a
/// row of their lanes: center[axis] as row axis, area[axis] as 3 + axis, moment[m] as 6 + m.
template <class Lanes, class Load>
DISTBAND_LANES Lanes farTerms(const Load& load, Lanes px, Lanes py, Lanes pz) {
  const Lanes dx = load(0) - px, dy = load(1) - py, dz = load(2) - pz;
  const Lanes inv_r = 1.0f / sqrtLanes(dx * dx + dy * dy + dz * dz), inv_r3 = inv_r * inv_r * inv_r;
  const Lanes m0 = load(6), m1 = load(7), m2 = load(8);
  const Lanes rmr =
      m0 * dx * dx + m1 * dy * dy + m2 * dz * dz + 2.0f * (load(9) * dx * dy + load(10) * dx * dz + load(11) * dy * dz);
  const Lanes dipole = load(3) * dx + load(4) * dy + load(5) * dz;
  return (dipole + m0 + m1 + m2) * inv_r3 - 3.0f * rmr * inv_r3 * inv_r * inv_r;
}
template <class Block>
const float* farRow(const Block& block, int row) {
  return row < 3 ? block.center[row] : row < 6 ? block.area[row - 3] : block.moment[row - 6];
}
/// Eight lanes of one value.
DISTBAND_LANES Float8 laneValue8(double v) { return Float8{} + float(v); }
/// Four lanes of one value, in single precision (p's coordinates relative to a leaf's center, as its corners).
Float4 laneValue(double v) { return Float4{} + float(v); }
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
  // The leaves' corners in lanes, relative to their centers (their triangles are contiguous in tris_ now).
  size_t leaf_count = 0;
  for (const Node& n : nodes_) leaf_count += n.left == 0;
  leaves_.assign(leaf_count, LeafTriangles{});
  uint32_t next = 0;
  for (Node& n : nodes_) {
    if (n.left != 0) continue;
    LeafTriangles& leaf = leaves_[next];
    for (uint32_t i = n.begin; i < n.end; ++i) {
      const uint32_t lane = i - n.begin;
      for (int c = 0; c < 3; ++c) {
        const Vec3d v = tris_[i][size_t(c)] - n.center;
        leaf.corner[c][0][lane] = float(v.x);
        leaf.corner[c][1][lane] = float(v.y);
        leaf.corner[c][2][lane] = float(v.z);
      }
      const auto& t = tris_[i];
      const Vec3d normal = (t[1] - t[0]).cross(t[2] - t[0]);
      leaf.normal[0][lane] = float(normal.x);
      leaf.normal[1][lane] = float(normal.y);
      leaf.normal[2][lane] = float(normal.z);
      leaf.normal[3][lane] = float(normal.lengthSqr());
    }
    n.right = next++;
  }
  interrupter_ = nullptr;
}

uint64_t WindingNumber::estimateBytes(uint64_t triangles) {
  // The triangles twice (the constructor's list and the ordered copy) with their centroids while building, the ids
  // and positions, the nodes (beyond 32-bit counts, one a triangle: leaves hold at least two) and the leaves' corners
  // (a binary tree's leaves are half its nodes, rounded up).
  const uint64_t nodes = triangles <= UINT32_MAX ? nodeCount(uint32_t(triangles)) : triangles;
  return triangles * (2 * sizeof(std::array<Vec3d, 3>) + sizeof(Vec3d) + 2 * sizeof(uint32_t)) + nodes * sizeof(Node) +
         (nodes / 2 + 1) * sizeof(LeafTriangles);
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
  const auto tri = [&](uint32_t i) -> const std::array<Vec3d, 3>& { return tris_[ids_[i]]; };
  Vec3d lo = centroids_[ids_[begin]], hi = lo;
  for (uint32_t i = begin; i < end; ++i) {
    const Vec3d& c = centroids_[ids_[i]];
    lo = {std::min(lo.x, c.x), std::min(lo.y, c.y), std::min(lo.z, c.z)};
    hi = {std::max(hi.x, c.x), std::max(hi.y, c.y), std::max(hi.z, c.z)};
  }
  std::array<double, 6> moment{};
  const auto addMoment = [&](const Vec3d& a, const Vec3d& e) {  // the symmetric part of a (x) e
    moment[0] += a.x * e.x, moment[1] += a.y * e.y, moment[2] += a.z * e.z;
    moment[3] += 0.5 * (a.x * e.y + a.y * e.x), moment[4] += 0.5 * (a.x * e.z + a.z * e.x);
    moment[5] += 0.5 * (a.y * e.z + a.z * e.y);
  };
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
    if (end - begin >= 4096 && isInterrupted(interrupter_)) return;  // a child may have stopped early (sticky)
    // The sums from the children's (each triangle is read once a level for the bounds and the radius only): the
    // moment about this center is the children's about theirs plus their area vectors times the shift.
    const Node& l = nodes_[n.left];
    const Node& r = nodes_[n.right];
    n.area = l.area + r.area;
    n.abs_area = l.abs_area + r.abs_area;
    n.center = n.abs_area > 0 ? (l.center * l.abs_area + r.center * r.abs_area) * (1.0 / n.abs_area) : (lo + hi) * 0.5;
    for (const Node* child : {&l, &r}) {
      for (int k = 0; k < 6; ++k) moment[size_t(k)] += child->moment[size_t(k)];
      addMoment(child->area, child->center - n.center);
    }
  } else {
    Vec3d weighted{};
    for (uint32_t i = begin; i < end; ++i) {
      const auto& t = tri(i);
      const Vec3d av = (t[1] - t[0]).cross(t[2] - t[0]) * 0.5;
      const double a = av.length();
      n.area = n.area + av;
      n.abs_area += a;
      weighted = weighted + centroids_[ids_[i]] * a;
    }
    n.center = n.abs_area > 0 ? weighted * (1.0 / n.abs_area) : (lo + hi) * 0.5;
    for (uint32_t i = begin; i < end; ++i) {
      const auto& t = tri(i);
      addMoment((t[1] - t[0]).cross(t[2] - t[0]) * 0.5, centroids_[ids_[i]] - n.center);
    }
  }
  for (int k = 0; k < 6; ++k) n.moment[size_t(k)] = float(moment[size_t(k)]);
  for (uint32_t i = begin; i < end; ++i)
    for (const Vec3d& v : tri(i)) n.radius2 = std::max(n.radius2, (v - n.center).lengthSqr());
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

WindingNumber::TierParameters WindingNumber::parameters(Tier tier) const {
  switch (tier) {
    case Tier::kRough: return {kRoughThirdOrderTolerance, kRoughBeta * kRoughBeta};
    case Tier::kCoarse: return {kCoarseThirdOrderTolerance, beta2_};
    case Tier::kFine: break;
  }
  return {kThirdOrderTolerance, beta2_};
}

double WindingNumber::query(const Vec3d& p) const { return sum(p, UINT32_MAX, parameters(Tier::kFine)); }

double WindingNumber::coarseQuery(const Vec3d& p) const { return sum(p, UINT32_MAX, parameters(Tier::kCoarse)); }

double WindingNumber::roughQuery(const Vec3d& p) const { return sum(p, UINT32_MAX, parameters(Tier::kRough)); }

double WindingNumber::principalValue(uint32_t t) const {
  const uint32_t at = position_[t];
  return sum(centroid(tris_[at]), at, parameters(Tier::kFine));
}

double WindingNumber::farTerm(const Node& n, const Vec3d& p) const {
  // Far field of the cluster's area elements a at x: a . (x - p) / |x - p|^3 expanded at the center: the dipole, then
  // the second-order term trace(J M^T) with J = I / r^3 - 3 r r^T / r^5 (r = center - p); J is symmetric, so only M's
  // symmetric part counts.
  const Vec3d d = n.center - p;
  const double inv_r = 1.0 / std::sqrt(d.lengthSqr()), inv_r3 = inv_r * inv_r * inv_r;
  const std::array<float, 6>& m = n.moment;
  const double rmr = m[0] * d.x * d.x + m[1] * d.y * d.y + m[2] * d.z * d.z +
                     2.0 * (m[3] * d.x * d.y + m[4] * d.x * d.z + m[5] * d.y * d.z);
  return n.area.dot(d) * inv_r3 + ((m[0] + m[1] + m[2]) * inv_r3 - 3.0 * rmr * inv_r3 * inv_r * inv_r);
}

DISTBAND_AVX2_CLONE double WindingNumber::leafHalfAngles(const Node& n, const Vec3d& p, uint32_t skip) const {
  const LeafTriangles& leaf = leaves_[n.right];
  const Vec3d q = p - n.center;
  const LeafHalfAngles<Float4> h([&](int row) { return loadLanes(leafRow(leaf, row)); },
                                 {laneValue(q.x), laneValue(q.y), laneValue(q.z)}, laneValue(kSureCorner2 * n.radius2));
  // The lanes in use: the leaf's triangles, `skip` left out.
  const Int4 lane = {0, 1, 2, 3};
  const Int4 used = lane < int32_t(n.end - n.begin) && lane != int32_t(skip - n.begin);
  const Float4 sure = used && !h.unsure ? h.angle : Float4{};
  double sum = double(sure[0]) + double(sure[1]) + double(sure[2]) + double(sure[3]);
  const Int4 redo = used && h.unsure;
  if (redo[0] | redo[1] | redo[2] | redo[3])
    for (uint32_t k = 0; k < 4; ++k)
      if (redo[k]) {
        const HalfAngle exact = halfAngle(tris_[n.begin + k], p);
        sum += std::atan2(exact.num, exact.den);
      }
  return sum;
}

namespace {
// Far enough for the expansion: beyond beta radii, and its next (third-order) term, of size area * radius^2 /
// distance^4, small enough.
bool farEnough(double d2, double radius2, double abs_area, double tolerance, double beta2) {
  return d2 > beta2 * radius2 && abs_area * radius2 < tolerance * d2 * d2;
}
}  // namespace

double WindingNumber::sum(const Vec3d& p, uint32_t skip, const TierParameters& tp) const {
  if (nodes_.empty()) return 0;
  double far = 0;
  double near = 0;  // the exactly summed triangles' half solid angles
  uint32_t stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = nodes_[stack[--top]];
    if (farEnough((n.center - p).lengthSqr(), n.radius2, n.abs_area, tp.tolerance, tp.beta2)) {
      far += farTerm(n, p);
    } else if (n.left == 0) {
      near += leafHalfAngles(n, p, skip);
    } else {
      stack[top++] = n.left;
      stack[top++] = n.right;
    }
  }
  return (far + 2.0 * near) / (4.0 * std::numbers::pi);
}

void WindingNumber::plan(const Vec3d& center, double radius, Tier tier, Plan* plan) const {
  const TierParameters tp = parameters(tier);
  plan->far.clear();
  plan->near.clear();
  if (nodes_.empty()) return;
  uint32_t stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const uint32_t id = stack[--top];
    const Node& n = nodes_[id];
    // The nearest point of the ball: every point's distance to the center is at least this.
    const double d = (n.center - center).length() - radius;
    if (d > 0 && farEnough(d * d, n.radius2, n.abs_area, tp.tolerance, tp.beta2)) {
      plan->far.push_back(id);
    } else if (n.left == 0) {
      plan->near.push_back(id);
    } else {
      stack[top++] = n.left;
      stack[top++] = n.right;
    }
  }
  plan->origin = center;
  Plan::FarLanes unused{};
  for (auto& axis : unused.center)
    for (float& v : axis) v = 1e6f;  // frame units beyond any grid's: 1e-18 of a unit area's term, times its zero area
  plan->far_lanes.assign((plan->far.size() + 7) / 8, unused);
  for (size_t k = 0; k < plan->far.size(); ++k) {
    const Node& n = nodes_[plan->far[k]];
    Plan::FarLanes& block = plan->far_lanes[k / 8];
    const size_t lane = k % 8;
    const Vec3d c = n.center - center;
    block.center[0][lane] = float(c.x), block.center[1][lane] = float(c.y), block.center[2][lane] = float(c.z);
    block.area[0][lane] = float(n.area.x), block.area[1][lane] = float(n.area.y), block.area[2][lane] = float(n.area.z);
    for (size_t m = 0; m < 6; ++m) block.moment[m][lane] = n.moment[m];
  }
  plan->near_lanes.assign((plan->near.size() + 1) / 2, Plan::NearLanes{});
  for (size_t k = 0; k < plan->near.size(); ++k) {
    const Node& n = nodes_[plan->near[k]];
    const LeafTriangles& leaf = leaves_[n.right];
    Plan::NearLanes& block = plan->near_lanes[k / 2];
    const size_t half = k % 2;
    for (size_t lane = 0; lane < 4; ++lane) {
      const size_t to = 4 * half + lane;
      for (size_t c = 0; c < 3; ++c)
        for (size_t axis = 0; axis < 3; ++axis) block.corner[c][axis][to] = leaf.corner[c][axis][lane];
      for (size_t row = 0; row < 4; ++row) block.normal[row][to] = leaf.normal[row][lane];
      block.near_corner[to] = float(kSureCorner2 * n.radius2);
      block.used[to] = lane < n.end - n.begin ? -1 : 0;
    }
    block.center[half] = n.center;
    block.begin[half] = n.begin;
  }
}

DISTBAND_AVX2_CLONE_EIGHT_LANES double WindingNumber::plannedLanes(const Plan& plan, const Vec3d& p) const {
  // farTerm in single precision (each term is within a few 1e-7 of its own size), then the near leaves' half angles,
  // two leaves a block, summed lane by lane in double.
  const Vec3d q = p - plan.origin;
  const Float8 px = laneValue8(q.x), py = laneValue8(q.y), pz = laneValue8(q.z);
  Float8 terms{};
  for (const Plan::FarLanes& block : plan.far_lanes)
    terms += farTerms([&](int row) { return loadLanes8(farRow(block, row)); }, px, py, pz);
  double far = 0, near = 0;  // near: the unsure lanes' angles, in double
  for (int lane = 0; lane < 8; ++lane) far += double(terms[lane]);
  Double4 first_angles{}, second_angles{};  // the sure lanes', of each block's first and second leaf
  for (const Plan::NearLanes& block : plan.near_lanes) {
    const Vec3d q1 = p - block.center[0], q2 = p - block.center[1];
    const LeafHalfAngles<Float8> h(
        [&](int row) { return loadLanes8(leafRow(block, row)); },
        {joinLanes(laneValue(q1.x), laneValue(q2.x)), joinLanes(laneValue(q1.y), laneValue(q2.y)),
         joinLanes(laneValue(q1.z), laneValue(q2.z))},
        loadLanes8(block.near_corner));
    Int8 used;
    std::memcpy(&used, block.used, sizeof(used));
    const auto [sure1, sure2] = splitLanes<Float4>(used && !h.unsure ? h.angle : Float8{});
    first_angles += __builtin_convertvector(sure1, Double4);
    second_angles += __builtin_convertvector(sure2, Double4);
    const Int8 redo = used && h.unsure;
    const auto [redo1, redo2] = splitLanes<Int4>(redo);
    const Int4 any = redo1 | redo2;
    if (any[0] | any[1] | any[2] | any[3])
      for (int lane = 0; lane < 8; ++lane)
        if (redo[lane]) {
          const HalfAngle exact = halfAngle(tris_[block.begin[lane / 4] + uint32_t(lane % 4)], p);
          near += std::atan2(exact.num, exact.den);
        }
  }
  const Double4 angles = first_angles + second_angles;
  near += angles[0] + angles[1] + angles[2] + angles[3];
  return (far + 2.0 * near) / (4.0 * std::numbers::pi);
}

double WindingNumber::planned(const Plan& plan, const Vec3d& p) const { return plannedLanes(plan, p); }

std::vector<ChainEdge> meshBoundaryChain(std::span<const std::array<uint32_t, 3>> triangles) {
  // Each use of an edge as one directed key (core/mesh/triangle_mesh.h: edgeKey).
  std::vector<uint64_t> uses(3 * triangles.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, triangles.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t t = r.begin(); t != r.end(); ++t)
      for (int e = 0; e < 3; ++e) uses[3 * t + e] = edgeKey(triangles[t][e], triangles[t][(e + 1) % 3], true);
  });
  tbb::parallel_sort(uses.begin(), uses.end());
  std::vector<ChainEdge> chain;
  for (size_t i = 0; i < uses.size();) {
    size_t j = i;
    int64_t net = 0;
    for (; j < uses.size() && uses[j] >> 1 == uses[i] >> 1; ++j) net += (uses[j] & 1) ? -1 : 1;
    const auto a = uint32_t(uses[i] >> 33), b = uint32_t(uses[i] >> 1);
    if (a != b && (j - i != 2 || net != 0)) chain.push_back({a, b, int32_t(net), uint32_t(j - i)});
    i = j;
  }
  return chain;
}

namespace {
// Closes a closed walk with fans of small triangles: each arc of kFanArc edges takes a fan from a point near its
// centroid, and the walk through the arcs' ends and those points (a quarter as long) is closed the same way, until
// one fan closes a walk of kFanArc edges or fewer. Near a point of the walk only a few small triangles lie close
// (one fan from the whole walk's centroid would put every triangle within a cluster radius of it: a query would sum
// them all). The apexes lie off the centroids by irrational fractions of the arc's extent: an apex at a lattice point
// (symmetric holes on a grid) would put fan edges through voxels, where the fans' solid angles are undefined.
constexpr size_t kFanArc = 8;
void closeWalk(std::vector<Vec3d> walk, std::vector<std::array<Vec3d, 3>>* fans) {
  const Vec3d kApexShift{(std::numbers::sqrt2 - 1) * 1e-3, (std::numbers::sqrt3 - 1) * 1e-3,
                         (std::sqrt(5.0) - 2) * 1e-3};
  const auto fan = [&](size_t begin, size_t end) {  // over edges begin .. end - 1 of the walk; returns the apex
    const size_t n = walk.size();
    Vec3d centre{};
    for (size_t i = begin; i <= end; ++i) centre = centre + walk[i % n];
    centre = centre * (1.0 / double(end - begin + 1));
    double extent = 0;
    for (size_t i = begin; i <= end; ++i) {
      const Vec3d d = walk[i % n] - centre;
      extent = std::max({extent, std::abs(d.x), std::abs(d.y), std::abs(d.z)});
    }
    const Vec3d apex = centre + kApexShift * extent;
    for (size_t i = begin; i < end; ++i) fans->push_back({apex, walk[i % n], walk[(i + 1) % n]});
    return apex;
  };
  while (walk.size() > kFanArc) {
    // The fans' boundary is the walk plus, for each arc, its end -> apex -> its start: the next walk runs the other
    // way, start -> apex -> end, so that the whole cap's boundary is the walk.
    std::vector<Vec3d> next;
    for (size_t begin = 0; begin < walk.size(); begin += kFanArc) {
      const Vec3d start = walk[begin];
      next.push_back(start);
      next.push_back(fan(begin, std::min(begin + kFanArc, walk.size())));
    }
    walk = std::move(next);
  }
  if (walk.size() >= 3) fan(0, walk.size());
}
}  // namespace

std::vector<std::array<Vec3d, 3>> boundaryFans(std::span<const Vec3d> vertices, std::span<const ChainEdge> chain) {
  struct Directed {
    uint32_t from, to;
  };
  std::vector<Directed> edges;
  for (const ChainEdge& e : chain)
    for (int32_t k = 0; k < std::abs(e.net); ++k) edges.push_back(e.net > 0 ? Directed{e.a, e.b} : Directed{e.b, e.a});
  std::sort(edges.begin(), edges.end(),
            [](const Directed& x, const Directed& y) { return x.from != y.from ? x.from < y.from : x.to < y.to; });
  std::vector<char> used(edges.size(), 0);
  std::unordered_map<uint32_t, size_t> next_out;  // a vertex's first outgoing edge not yet walked
  const auto take = [&](uint32_t v) -> size_t {
    auto [it, fresh] = next_out.try_emplace(v, 0);
    if (fresh)
      it->second = size_t(std::lower_bound(edges.begin(), edges.end(), v,
                                           [](const Directed& e, uint32_t from) { return e.from < from; }) -
                          edges.begin());
    for (size_t& i = it->second; i < edges.size() && edges[i].from == v; ++i)
      if (!used[i]) return used[i] = 1, i++;
    return edges.size();
  };
  std::vector<std::array<Vec3d, 3>> fans;
  std::vector<uint32_t> walk;
  for (size_t s = 0; s < edges.size(); ++s) {
    if (used[s]) continue;
    // In-degree equals out-degree at every vertex of a boundary, so a walk that leaves its start returns to it.
    used[s] = 1;
    walk.assign(1, edges[s].from);
    for (uint32_t v = edges[s].to; v != walk[0];) {
      walk.push_back(v);
      const size_t e = take(v);
      if (e == edges.size()) return {};  // not a boundary (never for a mesh's chain)
      v = edges[e].to;
    }
    std::vector<Vec3d> points(walk.size());
    for (size_t i = 0; i < walk.size(); ++i) points[i] = vertices[walk[i]];
    closeWalk(std::move(points), &fans);
  }
  return fans;
}

}  // namespace distband

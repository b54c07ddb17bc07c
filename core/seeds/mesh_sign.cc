#include "core/seeds/mesh_sign.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <numbers>
#include <span>
#include <stdexcept>
#include <tuple>
#include <type_traits>
#include <utility>

#include <dlfcn.h>
#include <embree3/rtcore.h>
#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/geometry.h"
#include "core/mesh/winding_number.h"
#include "core/seeds/internal/boundary_curves.h"
#include "core/seeds/seeds.h"

namespace distband {

std::string_view signMethodName(SignMethod method) {
  switch (method) {
    case SignMethod::kAuto: return "auto";
    case SignMethod::kPseudonormal: return "pseudonormal";
    case SignMethod::kWinding: return "winding";
    case SignMethod::kParity: return "parity";
    case SignMethod::kUnsigned: return "unsigned";
  }
  return "?";
}
bool parseSignMethod(std::string_view name, SignMethod* method) {
  for (SignMethod m : kSignMethods)
    if (name == signMethodName(m)) return *method = m, true;
  return false;
}

SignMethod resolveSignMethod(SignMethod requested, const MeshReport& report, std::string* reason) {
  if (requested != SignMethod::kAuto) {
    if (reason) *reason = "requested";
    return requested;
  }
  if (report.closed()) {
    // A face listed again the other way round closes its edges without enclosing anything: either copy's
    // pseudonormal puts one side inside, where the winding number (in which the two cancel) has 0.
    if (report.double_sided_faces > 0) {
      if (reason)
        *reason = fmt::format("auto: the mesh is closed but {} faces are double-sided (listed twice, once each way)",
                              report.double_sided_faces);
      return SignMethod::kWinding;
    }
    // Closed parts that cross or nest break the pseudonormal test (a point inside one part whose closest triangle is
    // another's takes that triangle's side); disjoint bounding boxes rule both out, cheaply.
    if (report.components_overlap) {
      if (reason)
        *reason = fmt::format("auto: the mesh is closed but its parts overlap ({} parts, bounding boxes intersect)",
                              report.components);
      return SignMethod::kWinding;
    }
    if (reason) *reason = "auto: the mesh is closed";
    return SignMethod::kPseudonormal;
  }
  if (reason) {
    std::string edges;
    if (report.boundary_edges > 0) edges = fmt::format("{} boundary edges", report.boundary_edges);
    if (report.non_manifold_edges > 0)
      edges += fmt::format("{}{} non-manifold edges", edges.empty() ? "" : ", ", report.non_manifold_edges);
    *reason = fmt::format("auto: the mesh is not closed ({})", edges);
  }
  return SignMethod::kWinding;
}

std::string describeSignShares(const SignShares& s) {
  const int64_t n = s.total();
  if (n == 0) return "";
  auto share = [n](int64_t k) { return fmt::format("{:.1f} %", 100.0 * double(k) / double(n)); };
  std::vector<std::string> parts;
  if (s.pseudonormal) parts.push_back(fmt::format("pseudonormal {}", share(s.pseudonormal)));
  if (s.winding_certified)
    parts.push_back(fmt::format("winding number by one query a brick {}", share(s.winding_certified)));
  if (s.winding_per_voxel) parts.push_back(fmt::format("winding number per voxel {}", share(s.winding_per_voxel)));
  if (s.parity) parts.push_back(fmt::format("ray parity {}", share(s.parity)));
  return fmt::format("{} voxels signed: {}", n, fmt::join(parts, ", "));
}

namespace {

Vec3d normalized(const Vec3d& v) {
  const double l = v.length();
  return l > 0 ? v * (1.0 / l) : Vec3d{};
}

// Embree's entry points, loaded when the first parity scene is built: linked, the library's relocations cost every
// process ~6 ms of start-up (a trivial program: 2 -> 8 ms), which every run paid and only parity signs use. Each is
// named once, below: a member of EmbreeLibrary and the symbol it is found by.
// clang-format off
#define DISTBAND_EMBREE_ENTRY_POINTS(X) \
  X(rtcNewDevice) \
  X(rtcReleaseDevice) \
  X(rtcNewScene) \
  X(rtcReleaseScene) \
  X(rtcSetSceneFlags) \
  X(rtcSetSceneProgressMonitorFunction) \
  X(rtcNewGeometry) \
  X(rtcSetNewGeometryBuffer) \
  X(rtcCommitGeometry) \
  X(rtcAttachGeometry) \
  X(rtcReleaseGeometry) \
  X(rtcCommitScene) \
  X(rtcIntersect1)
// clang-format on
struct EmbreeLibrary {
#define DISTBAND_EMBREE_DECLARE(name) decltype(&::name) name = nullptr;
  DISTBAND_EMBREE_ENTRY_POINTS(DISTBAND_EMBREE_DECLARE)
#undef DISTBAND_EMBREE_DECLARE
  bool loaded = false;  // every entry point found

  /// The process's one copy (the library stays loaded): `loaded` is false when it is not installed.
  static const EmbreeLibrary& get() {
    static const EmbreeLibrary library = [] {
      EmbreeLibrary l;
      void* handle = dlopen("libembree3.so.3", RTLD_NOW | RTLD_LOCAL);
      if (!handle) return l;
      const auto find = [handle](auto* entry, const char* name) {
        *entry = reinterpret_cast<std::remove_pointer_t<decltype(entry)>>(dlsym(handle, name));
        return *entry != nullptr;
      };
#define DISTBAND_EMBREE_FIND(name) &&find(&l.name, #name)
      l.loaded = true DISTBAND_EMBREE_ENTRY_POINTS(DISTBAND_EMBREE_FIND);
#undef DISTBAND_EMBREE_FIND
      return l;
    }();
    return library;
  }
};
#undef DISTBAND_EMBREE_ENTRY_POINTS

// Embree scene for ray parity; owns the device and scene for as long as a sign refers to it.
class ParityScene {
 public:
  ParityScene(const std::vector<std::array<Vec3d, 3>>& tris, const Interrupter* interrupter)
      : embree_(EmbreeLibrary::get()) {
    if (!embree_.loaded) return;
    device_ = embree_.rtcNewDevice(nullptr);
    if (!device_) return;
    scene_ = embree_.rtcNewScene(device_);
    embree_.rtcSetSceneFlags(scene_, RTC_SCENE_FLAG_ROBUST);
    // Embree calls this while it builds the BVH; returning false cancels the build.
    if (interrupter)
      embree_.rtcSetSceneProgressMonitorFunction(
          scene_, [](void* ptr, double) { return !static_cast<const Interrupter*>(ptr)->interrupted(); },
          const_cast<Interrupter*>(interrupter));
    RTCGeometry geom = embree_.rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(embree_.rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                                  3 * sizeof(float), tris.size() * 3));
    auto* idx = static_cast<unsigned*>(embree_.rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                       3 * sizeof(unsigned), tris.size()));
    for (size_t t = 0; t < tris.size(); ++t)
      for (int k = 0; k < 3; ++k) {
        v[9 * t + 3 * k + 0] = float(tris[t][k].x);
        v[9 * t + 3 * k + 1] = float(tris[t][k].y);
        v[9 * t + 3 * k + 2] = float(tris[t][k].z);
        idx[3 * t + k] = unsigned(3 * t + k);
      }
    embree_.rtcCommitGeometry(geom);
    embree_.rtcAttachGeometry(scene_, geom);
    embree_.rtcReleaseGeometry(geom);
    embree_.rtcCommitScene(scene_);
  }
  ~ParityScene() {
    if (scene_) embree_.rtcReleaseScene(scene_);
    if (device_) embree_.rtcReleaseDevice(device_);
  }
  ParityScene(const ParityScene&) = delete;
  ParityScene& operator=(const ParityScene&) = delete;
  bool ok() const { return scene_ != nullptr; }

  /// Majority vote of three rays in fixed, non-axis-aligned directions: odd crossing count = inside.
  bool inside(const Vec3d& p) const {
    static const float kDirs[3][3] = {{0.8273f, 0.4712f, 0.3057f}, {-0.3391f, 0.8617f, 0.3774f},
                                      {0.2719f, -0.4483f, 0.8515f}};
    int votes = 0;
    for (const auto& d : kDirs) votes += crossings(p, d) & 1;
    return votes >= 2;
  }

 private:
  int crossings(const Vec3d& p, const float* dir) const {
    int count = 0;
    float tnear = 0;
    for (int guard = 0; guard < 1 << 16; ++guard) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      RTCRayHit rh{};
      rh.ray.org_x = float(p.x), rh.ray.org_y = float(p.y), rh.ray.org_z = float(p.z);
      rh.ray.dir_x = dir[0], rh.ray.dir_y = dir[1], rh.ray.dir_z = dir[2];
      rh.ray.tnear = tnear;
      rh.ray.tfar = std::numeric_limits<float>::infinity();
      rh.ray.mask = ~0u;
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      embree_.rtcIntersect1(scene_, &ctx, &rh);
      if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) break;
      ++count;
      // Step past this hit; hits at the same distance (a shared edge or corner) count once.
      tnear = rh.ray.tfar + 1e-4f * std::max(1.0f, rh.ray.tfar);
    }
    return count;
  }
  const EmbreeLibrary& embree_;
  RTCDevice device_ = nullptr;
  RTCScene scene_ = nullptr;
};

// A unit normal in single precision: it only decides which side of the surface a point lies on, and the sign
// data of a large mesh is otherwise a good part of a thin band's memory.
struct Normal3f {
  float x = 0, y = 0, z = 0;
  Normal3f() = default;
  explicit Normal3f(const Vec3d& v) : x(float(v.x)), y(float(v.y)), z(float(v.z)) {}
  double dot(const Vec3d& v) const { return x * v.x + y * v.y + z * v.z; }
};

/// When the distance is the plane's (`plane`: p's signed distance to triangle t's plane), the closest point lies in
/// the face (up to ~0.5 % of the distance from its border, where any consistent pseudonormal agrees with the face
/// normal): the plane's sign is the answer, no region tests needed.
bool planeDecides(double plane, double dist) { return plane * plane >= dist * dist * (1 - 1e-5); }

// The voxels of each kEdge^3 box of a brick: box x + per y + per^2 z (per = 8 / kEdge boxes along an axis).
template <int kEdge>
constexpr std::array<BrickMask, (kBrickSize / kEdge) * (kBrickSize / kEdge) * (kBrickSize / kEdge)> makeBoxes() {
  constexpr int per = kBrickSize / kEdge;
  std::array<BrickMask, per * per * per> m{};
  for (int i = 0; i < kBrickVoxels; ++i) {
    const Coord c = brickLocal(i);
    m[size_t(c.x / kEdge + per * (c.y / kEdge) + per * per * (c.z / kEdge))].words[size_t(i >> 6)] |= uint64_t(1)
                                                                                                      << (i & 63);
  }
  return m;
}
constexpr auto kOctants = makeBoxes<4>();  // 4^3
constexpr auto kCells = makeBoxes<2>();    // 2^3
// The winding hierarchy's queries, cheapest first, each with its error bound: what
// tests/core/mesh/winding_number_test.cc measures near open meshes (query() below 0.011, coarseQuery() below 0.042,
// roughQuery() below 0.17), with room to spare. A sign takes the first whose value decides its question.
struct WindingTier {
  double (WindingNumber::*query)(const Vec3d&) const;
  double error;
};
constexpr WindingTier kWindingTiers[] = {
    {&WindingNumber::roughQuery, 0.3}, {&WindingNumber::coarseQuery, 0.1}, {&WindingNumber::query, 0.03}};
constexpr double kWindingQueryError = kWindingTiers[std::size(kWindingTiers) - 1].error;  // the finest
// On a sheet the winding number is 1/2 (the mean of its two sides): a voxel on an open disk, whose w is 1/2 there
// and below it everywhere else, takes the outside by its rounding alone. Ties within this go outside.
constexpr double kOnSheetTie = 1e-9;
bool insideByWinding(double w) { return w > 0.5 + kOnSheetTie; }
// Voxels nearer the surface than this (voxels) lie on it, up to the distance's rounding.
constexpr double kOnSheet = 1e-6;
/// Whether a voxel this far from the surface (voxels) lies on it.
bool onSheet(double distance) { return distance < kOnSheet; }
// A winding voxel's ball (signBrick) reaches its distance to the surface less this (voxels): five times the band's
// largest distance error measured against brute force.
constexpr double kWindingBallMargin = 0.5;
// The boundary fans' tier (MeshSign::Tables::fans) reads their winding number with the finest query: its value is as
// good as that query's.
constexpr double kFanTierError = kWindingQueryError;
// At most one fan triangle per this many mesh triangles (a mesh with more boundary, e.g. a soup whose triangles share
// no vertex, keeps the mesh's tiers): the fans' tree stays an eighth of the mesh's in memory budgets (estimateBytes).
constexpr size_t kMaxFansPerTriangle = 8;

}  // namespace

// Everything a method's test needs, immutable once built.
struct MeshSign::Tables {
  std::shared_ptr<const std::vector<Vec3d>> vert_table;  // shared with the caller (its triangle sites)
  std::shared_ptr<const std::vector<std::array<uint32_t, 3>>> corner_table;
  std::span<const Vec3d> verts;                      // the caller's frame
  std::span<const std::array<uint32_t, 3>> corners;  // mesh vertex ids
  std::vector<Normal3f> face_n, vertex_n;            // pseudonormals
  std::vector<uint8_t> double_sided;                 // winding: 1 for a face listed again the other way (or empty)
  /// Edge pseudonormals, through each half-edge's (3 per triangle) other triangle: a manifold edge's normal is computed
  /// where needed from its two faces (4 bytes a half-edge where a float normal took 12: a third of a big mesh's sign
  /// tables). kLoneEdge: a boundary edge (its face's normal); kManyUses: an edge of three or more uses, or used twice
  /// by one triangle, whose normal `shared_edge_n` keeps by half-edge (rare).
  static constexpr uint32_t kLoneEdge = std::numeric_limits<uint32_t>::max(), kManyUses = kLoneEdge - 1;
  std::vector<uint32_t> edge_mate;
  std::vector<std::pair<uint64_t, Normal3f>> shared_edge_n;  // sorted by half-edge 3 t + e
  std::unique_ptr<WindingNumber> winding;
  /// Winding: the fans that close the mesh's boundary (core/mesh/winding_number.h: boundaryFans), whose winding number
  /// differs from the mesh's by an integer; null when the mesh has no boundary or too long a one.
  std::unique_ptr<WindingNumber> fans;
  std::unique_ptr<ParityScene> parity;
  uint64_t triangles = 0;
  /// Winding: the boundary and non-manifold edges, the curves the winding number turns around without crossing the
  /// surface.
  seeds_internal::BoundaryCurves boundary;
  /// Winding: each triangle's connected part (findMeshParts), empty when the mesh is one part. Parts may cross or nest,
  /// so the certificate takes a brick only when all its voxels' closest triangles belong to one part.
  std::vector<uint32_t> part;

  /// `dist` is p's distance to triangle t, known to float precision.
  bool insidePseudonormal(const Vec3d& p, uint32_t t, double dist) const {
    const double plane = face_n[t].dot(p - verts[corners[t][0]]);
    return planeDecides(plane, dist) ? plane < 0 : insideByClosestFeature(p, t);
  }

  /// The pseudonormal test proper: the sign of p against the normal of the feature of triangle t closest to it.
  bool insideByClosestFeature(const Vec3d& p, uint32_t t) const {
    const auto& c = corners[t];
    TriangleFeature f;
    const Vec3d cp = closestPointOnTriangle(p, verts[c[0]], verts[c[1]], verts[c[2]], &f);
    Normal3f n;
    switch (f) {
      case TriangleFeature::kFace: n = face_n[t]; break;
      case TriangleFeature::kEdgeAB:
        n = edgeNormal(t, 0);
        break;
      case TriangleFeature::kEdgeBC:
        n = edgeNormal(t, 1);
        break;
      case TriangleFeature::kEdgeCA:
        n = edgeNormal(t, 2);
        break;
      case TriangleFeature::kVertexA: n = vertex_n[corners[t][0]]; break;
      case TriangleFeature::kVertexB: n = vertex_n[corners[t][1]]; break;
      case TriangleFeature::kVertexC: n = vertex_n[corners[t][2]]; break;
    }
    return n.dot(p - cp) < 0;
  }

  /// Triangle t's unit normal in double precision.
  Vec3d faceNormal(size_t t) const {
    const auto& c = corners[t];
    return normalized((verts[c[1]] - verts[c[0]]).cross(verts[c[2]] - verts[c[0]]));
  }
  /// The pseudonormal of triangle t's edge e (from corner e to e + 1): the normalized sum of the normals of the
  /// triangles that have it, in triangle order (a triangle with the edge twice counts twice).
  Normal3f edgeNormal(uint32_t t, int e) const {
    const uint32_t mate = edge_mate[3 * size_t(t) + size_t(e)];
    if (mate == kLoneEdge) return Normal3f(normalized(Vec3d{} + faceNormal(t)));
    if (mate == kManyUses)
      return std::lower_bound(shared_edge_n.begin(), shared_edge_n.end(), 3 * uint64_t(t) + uint64_t(e),
                              [](const auto& entry, uint64_t key) { return entry.first < key; })
          ->second;
    const uint32_t first = std::min(t, mate), second = std::max(t, mate);
    return Normal3f(normalized(Vec3d{} + faceNormal(first) + faceNormal(second)));
  }

  /// Signs the voxels of `subset` (delivered, each with a site) by the pseudonormal, keeping the last triangle's plane
  /// (a brick's neighbouring voxels mostly share their closest triangle).
  void signByPseudonormal(Brick& brick, const BrickMask& subset, const uint32_t* sites, const uint32_t* site_triangle,
                          double voxel_size, const Vec3d& scale) const;
  void buildPseudonormals(const Interrupter* interrupter);
  /// What the rough tier and the fans' tier read for every voxel of a brick (WindingNumber::plan), made when the first
  /// of its voxels takes a query of its own: the later ones read the same clusters without a traversal each.
  struct BrickPlans {
    Vec3d center;
    double radius = 0;
    bool made = false;
    WindingNumber::Plan rough, fans;
  };
  /// The winding number at p, as cheaply as its side of 1/2 allows (windingUntil); `error` gets the error bound of the
  /// value returned. With `plans`, p lies in their ball.
  double windingAt(const Vec3d& p, double* error, BrickPlans* plans = nullptr) const;
  /// The winding number at p by the cheapest tier whose value and error bound satisfy `decides(value, error)`, else
  /// by the finest; `error` gets the error bound of the value returned. When the rough value does not decide, the
  /// boundary fans' winding number (a query of the few fan triangles near p) plus the integer that brings it within
  /// the rough value's error of it is as good as the finest query, and cheaper than the coarse one: the whole mesh's
  /// near field is replaced by the boundary's. Should the rough value lie farther from every such sum than its error
  /// bound allows (it never has), the mesh's tiers go on.
  template <class Decides>
  double windingUntil(const Vec3d& p, const Decides& decides, double* error, BrickPlans* plans = nullptr) const {
    double w = 0;
    const bool planned = plans && (plans->made || makePlans(plans));
    for (const WindingTier& tier : kWindingTiers) {
      const bool rough = tier.query == &WindingNumber::roughQuery;
      w = planned && rough ? winding->planned(plans->rough, p) : ((*winding).*tier.query)(p), *error = tier.error;
      if (decides(w, *error)) break;
      if (fans && rough) {
        const double fan = planned ? fans->planned(plans->fans, p) : fans->query(p), k = std::round(w - fan);
        if (std::abs(w - fan - k) <= tier.error + kFanTierError) {
          *error = kFanTierError;
          return fan + k;
        }
      }
    }
    return w;
  }
  /// Makes a brick's plans; true.
  bool makePlans(BrickPlans* plans) const;
  /// The winding values a brick's certificates queried, by voxel, each with its error bound.
  class KnownWindings {
   public:
    struct Value {
      double w, error;
    };
    const Value* find(int voxel) const {
      if (!voxels_.test(voxel)) return nullptr;
      for (int k = 0; k < count_; ++k)
        if (values_[size_t(k)].voxel == voxel) return &values_[size_t(k)].value;
      return nullptr;
    }
    void add(int voxel, const Value& value) {
      if (count_ == int(values_.size())) return;  // never: one value a certificate, and a brick tries this many
      voxels_.set(voxel);
      values_[size_t(count_++)] = {voxel, value};
    }

   private:
    BrickMask voxels_;  // those in values_
    struct Entry {
      int voxel;
      Value value;
    };
    std::array<Entry, 1 + kOctants.size() + kCells.size()> values_;  // the brick's, its octants' and cells' (unset)
    int count_ = 0;
  };
  /// Signs the voxels of `subset` (delivered voxels of the brick, all within `radius` frame units of `center`) with
  /// one winding query when that provably agrees with the exact winding number (below); false, nothing signed, else.
  /// A reference in `known` is not queried again, and one queried is added (a refused certificate's value signs its
  /// reference later). With `plans` (the brick's: the octants' and cells' certificates), its query reads them.
  bool signWindingCertified(Brick& brick, const BrickMask& subset, const Vec3d& center, double radius,
                            const seeds_internal::BoundaryCurves::Near& near, const uint32_t* sites,
                            const uint32_t* site_triangle, double voxel_size, const Vec3d& scale, KnownWindings* known,
                            BrickPlans* plans = nullptr) const;
};

void MeshSign::Tables::buildPseudonormals(const Interrupter* interrupter) {
  const size_t nt = corners.size(), nv = verts.size();
  auto stop = [&](size_t i) { return (i & 0xFFFF) == 0 && isInterrupted(interrupter); };
  face_n.resize(nt);
  {
    std::vector<Vec3d> face(nt);
    // Vertex pseudonormal: the angle-weighted sum of the normals of the triangles around the vertex, in triangle order.
    std::vector<std::array<double, 3>> angles(nt);
    tbb::parallel_for(size_t(0), nt, [&](size_t t) {
      if (tbb::is_current_task_group_canceling()) return;
      const auto& c = corners[t];
      const Vec3d tri[3] = {verts[c[0]], verts[c[1]], verts[c[2]]};
      face[t] = faceNormal(t);
      face_n[t] = Normal3f(face[t]);
      for (int k = 0; k < 3; ++k) {
        const Vec3d e1 = normalized(tri[(k + 1) % 3] - tri[k]), e2 = normalized(tri[(k + 2) % 3] - tri[k]);
        angles[t][k] = std::acos(std::clamp(e1.dot(e2), -1.0, 1.0));
      }
    });
    std::vector<Vec3d> vertex(nv);
    for (size_t t = 0; t < nt; ++t) {
      if (stop(t)) return;
      for (int k = 0; k < 3; ++k) vertex[corners[t][k]] = vertex[corners[t][k]] + face[t] * angles[t][k];
    }
    vertex_n.resize(nv);
    // Independent per element, so in parallel (serial, these loops were a good part of the seeds' time).
    tbb::parallel_for(tbb::blocked_range<size_t>(0, nv, 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t v = r.begin(); v != r.end(); ++v) vertex_n[v] = Normal3f(normalized(vertex[v]));
    });
  }  // the normals, angles and sums go before the edges' tables come: a big mesh's peak memory is here
  if (isInterrupted(interrupter)) return;
  // Edge pseudonormal: the sum of the normals of the triangles that have the edge, in triangle order (a triangle
  // with the edge twice, a degenerate one, counts twice). Found through each vertex's triangles, listed in triangle
  // order once each (4 bytes a corner, where sorting every edge use took 16).
  auto firstUse = [&](size_t t, int k) {  // corner k is the first of triangle t at its vertex
    const uint32_t v = corners[t][k];
    return !((k > 0 && corners[t][0] == v) || (k > 1 && corners[t][1] == v));
  };
  std::vector<uint32_t> first(nv + 1, 0), around(3 * nt);
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k)
      if (firstUse(t, k)) ++first[corners[t][k] + 1];
  for (size_t v = 0; v < nv; ++v) first[v + 1] += first[v];
  {
    std::vector<uint32_t> next(first.begin(), first.end() - 1);
    for (size_t t = 0; t < nt; ++t) {
      if (stop(t)) return;
      for (int k = 0; k < 3; ++k)
        if (firstUse(t, k)) around[next[corners[t][k]]++] = uint32_t(t);
    }
  }
  // Calls visit(u) for each use of triangle t's edge e by a triangle u (t itself included), in triangle order.
  auto forEachUse = [&](size_t t, int e, auto&& visit) {
    const uint32_t a = std::min(corners[t][e], corners[t][(e + 1) % 3]);
    const uint32_t b = std::max(corners[t][e], corners[t][(e + 1) % 3]);
    for (uint32_t i = first[a]; i < first[a + 1]; ++i) {
      const auto& c = corners[around[i]];
      for (int f = 0; f < 3; ++f)
        if (std::min(c[f], c[(f + 1) % 3]) == a && std::max(c[f], c[(f + 1) % 3]) == b) visit(around[i]);
    }
  };
  // Each half-edge's other triangle. An edge with three or more uses, or used twice by one (degenerate) triangle, is
  // marked kManyUses and its normal summed in a serial pass below (in triangle order, as edgeNormal sums two): few
  // meshes have any.
  edge_mate.assign(3 * nt, kLoneEdge);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, nt, 1024), [&](const tbb::blocked_range<size_t>& r) {
    if (tbb::is_current_task_group_canceling()) return;
    for (size_t t = r.begin(); t != r.end(); ++t)
      for (int e = 0; e < 3; ++e) {
        int uses = 0;
        uint32_t other = kLoneEdge;
        forEachUse(t, e, [&](uint32_t u) {
          ++uses;
          if (u != t) other = u;
        });
        edge_mate[3 * t + e] = uses == 1 ? kLoneEdge : uses == 2 && other != kLoneEdge ? other : kManyUses;
      }
  });
  if (isInterrupted(interrupter)) return;
  for (size_t t = 0; t < nt; ++t) {
    if (stop(t)) return;
    for (int e = 0; e < 3; ++e) {
      if (edge_mate[3 * t + e] != kManyUses) continue;
      Vec3d sum{};
      forEachUse(t, e, [&](uint32_t u) { sum = sum + faceNormal(u); });
      shared_edge_n.emplace_back(3 * uint64_t(t) + uint64_t(e), Normal3f(normalized(sum)));
    }
  }
}

void MeshSign::Tables::signByPseudonormal(Brick& brick, const BrickMask& subset, const uint32_t* sites,
                                          const uint32_t* site_triangle, double voxel_size, const Vec3d& scale) const {
  uint32_t last = kNoSite;
  Vec3d n{}, v0{};
  subset.forEach([&](int i) {
    if (sites[i] == kNoSite) return;
    const uint32_t t = site_triangle ? site_triangle[sites[i]] : sites[i];
    if (t != last) {
      n = {double(face_n[t].x), double(face_n[t].y), double(face_n[t].z)};
      v0 = verts[corners[t][0]];
      last = t;
    }
    const Coord c = brick.origin + brickLocal(i);
    const Vec3d p{c.x * scale.x, c.y * scale.y, c.z * scale.z};
    const double dist = std::abs(brick.values[i]) / voxel_size;
    // insidePseudonormal, with the plane kept (the same arithmetic as Normal3f::dot).
    const Vec3d q = p - v0;
    const double plane = n.x * q.x + n.y * q.y + n.z * q.z;
    if (planeDecides(plane, dist) ? plane < 0 : insideByClosestFeature(p, t))
      brick.values[i] = -std::abs(brick.values[i]);
  });
}

// Winding signs at the pseudonormal's price where that is provably the same answer. Across a consistently oriented
// sheet the winding number jumps by exactly 1 (front w0, behind w0 + 1); away from boundary and non-manifold edges it
// varies smoothly along either side. So when a brick's voxels all have their closest triangle on one locally oriented
// patch (no two closest triangles face apart) far from any boundary, one exact query at the voxel nearest the brick's
// centre fixes w0: if w0 lies well inside (-1/2, 1/2), every voxel in front is outside and every voxel behind is
// inside, the pseudonormal's answer; well above 1/2 (the sheet inside another part's volume), every voxel is inside;
// well below -1/2, every voxel is outside. Otherwise (near holes, thin parts, w0 near +-1/2) the brick
// takes a winding query per voxel. The margins cover the turn of the winding number around the boundary curves
// across the brick and the hierarchy's error. Sheets of two connected parts in one brick (parts that cross, or nest
// with the same orientation: a voxel in front of one sheet can lie behind the other, which no single w0 describes)
// also send the brick to the per-voxel queries, as do double-sided faces (a face listed again the other way round:
// the copies' solid angles cancel, so w does not jump across them, yet either copy's pseudonormal has a side). The
// reference is a voxel off the sheets: on one, w is either side's value or their mean, and the jump says nothing.
// Not covered: one connected part that crosses itself, or stacks two sheets of the same orientation, within a brick.
bool MeshSign::Tables::signWindingCertified(Brick& brick, const BrickMask& subset, const Vec3d& center, double radius,
                                            const seeds_internal::BoundaryCurves::Near& near, const uint32_t* sites,
                                            const uint32_t* site_triangle, double voxel_size, const Vec3d& scale,
                                            KnownWindings* known, BrickPlans* plans) const {
  auto triangleOf = [site_triangle](uint32_t site) { return site_triangle ? site_triangle[site] : site; };
  const auto at = [&](int i) {
    const Coord c = brick.origin + brickLocal(i);
    return Vec3d{c.x * scale.x, c.y * scale.y, c.z * scale.z};
  };
  // Squared distances along each axis from a point to the brick's 8 planes of voxels: a voxel's squared distance is
  // the sum of three table entries (the scans below read every voxel of the subset).
  struct AxisTables {
    std::array<double, kBrickSize> x, y, z;
    AxisTables(const Coord& origin, const Vec3d& scale, const Vec3d& from) {
      const auto square = [](double v) { return v * v; };
      for (int l = 0; l < kBrickSize; ++l) {
        x[l] = square((origin.x + l) * scale.x - from.x);
        y[l] = square((origin.y + l) * scale.y - from.y);
        z[l] = square((origin.z + l) * scale.z - from.z);
      }
    }
    double distance2(int i) const {
      const Coord l = brickLocal(i);
      return x[l.x] + y[l.y] + z[l.z];
    }
  };
  const AxisTables from_center(brick.origin, scale, center);
  int ref = -1;
  uint32_t brick_part = 0, last = kNoSite;
  double ref_to_center = std::numeric_limits<double>::infinity();
  float farthest_value = 0;
  Vec3d normal{};
  const bool one_sheet = subset.forEach([&](int i) {
    if (sites[i] == kNoSite) return false;
    farthest_value = std::max(farthest_value, std::abs(brick.values[i]));
    const uint32_t t = triangleOf(sites[i]);
    if (t != last) {  // neighbouring voxels mostly share their closest triangle
      const Vec3d tn{face_n[t].x, face_n[t].y, face_n[t].z};
      if (last == kNoSite) normal = tn, brick_part = part.empty() ? 0 : part[t];
      if (normal.dot(tn) <= 0) return false;                     // thin parts: opposite sheets in one brick
      if (!double_sided.empty() && double_sided[t]) return false;  // its copy the other way round cancels it
      if (!part.empty() && part[t] != brick_part) return false;  // sheets of two parts
      last = t;
    }
    // The reference lies off the sheets: on one, its value is either side's (or their mean, to within the query's
    // error), and which side's says nothing of the jump.
    const double c2 = from_center.distance2(i);
    if (c2 < ref_to_center && !onSheet(std::abs(brick.values[i]) / voxel_size)) ref_to_center = c2, ref = i;
    return true;
  });
  if (!one_sheet || ref < 0) return false;
  const double farthest = double(farthest_value) / voxel_size;
  // Every point of the subset's box is at least this far from the boundary curves. Farther than every voxel's
  // distance to the surface, no voxel's closest point lies on a boundary edge, where "behind the pseudonormal" need not
  // mean across the sheet (beyond a rim, behind the face's plane, the winding number has not jumped).
  const double boundary_distance = boundary.distance(near, center, radius);
  if (boundary_distance <= farthest) return false;
  double spread2 = 0;  // the farthest voxel from the reference
  const AxisTables from_ref(brick.origin, scale, at(ref));
  subset.forEach([&](int i) { spread2 = std::max(spread2, from_ref.distance2(i)); });
  // Off the sheets the winding number turns around the boundary curves by at most the spread times its turn rate
  // over the box's ball (the straight way from the reference to a voxel stays in the box).
  const double spread = std::sqrt(spread2);
  const double drift =
      spread > 0 ? spread * boundary.turnRate(near, center, radius, (0.5 - kWindingQueryError) / spread) : 0.0;
  if (!(drift + kWindingQueryError < 0.5)) return false;
  const bool ref_behind = insidePseudonormal(at(ref), triangleOf(sites[ref]), std::abs(brick.values[ref]) / voxel_size);
  // The reference's value less its side's jump is w0, in front of the sheet: the voxels in front are inside when
  // w0 > 1/2, those behind when w0 + 1 > 1/2. The reference's value decides once w0 lies, less the drift and its
  // error, clear of both -1/2 and 1/2: mostly near 0 (the pseudonormal's answer), but also near 1 or -1, where another
  // part's volume holds this sheet (a part inside another, crossing parts: every voxel inside) or an inverted one
  // does (every voxel outside).
  const double jump = ref_behind ? 1.0 : 0.0;
  const auto decides = [&](double w, double w_error) {
    const double w0 = w - jump, margin = drift + w_error;
    return std::abs(w0 - 0.5) > margin && std::abs(w0 + 0.5) > margin;
  };
  KnownWindings::Value value;
  if (const KnownWindings::Value* found = known->find(ref)) {
    value = *found;
  } else {
    value.w = windingUntil(at(ref), decides, &value.error, plans);
    known->add(ref, value);
  }
  if (!decides(value.w, value.error)) return false;
  const double w0 = value.w - jump;
  const bool front_inside = w0 > 0.5, behind_inside = w0 > -0.5;
  if (front_inside == behind_inside) {  // one side of 1/2 throughout
    // Voxels on a sheet take the outside, as in signBrick.
    if (front_inside)
      subset.forEach([&](int i) {
        if (!onSheet(std::abs(brick.values[i]) / voxel_size)) brick.values[i] = -std::abs(brick.values[i]);
      });
    return true;
  }
  signByPseudonormal(brick, subset, sites, site_triangle, voxel_size, scale);
  return true;
}

double MeshSign::Tables::windingAt(const Vec3d& p, double* error, BrickPlans* plans) const {
  const auto far_from_half = [](double w, double w_error) { return std::abs(w - 0.5) > w_error; };
  return windingUntil(p, far_from_half, error, plans);
}

bool MeshSign::Tables::makePlans(BrickPlans* plans) const {
  winding->plan(plans->center, plans->radius, WindingNumber::Tier::kRough, &plans->rough);
  if (fans) fans->plan(plans->center, plans->radius, WindingNumber::Tier::kFine, &plans->fans);
  return plans->made = true;
}

MeshSign::MeshSign(SignMethod method) : method_(method), tables_(std::make_unique<Tables>()) {}
MeshSign::~MeshSign() = default;

Status MeshSign::build(std::shared_ptr<const std::vector<Vec3d>> vertices,
                       std::shared_ptr<const std::vector<std::array<uint32_t, 3>>> triangles, SignMethod method,
                       const Interrupter* interrupter, std::unique_ptr<MeshSign>* out) {
  if (method != SignMethod::kPseudonormal && method != SignMethod::kWinding && method != SignMethod::kParity)
    return Status::InvalidArgument(
        fmt::format("a mesh sign is built for pseudonormal, winding or parity (got {})", signMethodName(method)));
  if (!vertices || !triangles) throw std::invalid_argument("MeshSign::build: no vertex or triangle table");
  for (const auto& t : *triangles)
    for (uint32_t i : t)
      if (i >= vertices->size()) return Status::InvalidArgument("a triangle refers to a vertex that does not exist");
  if (method == SignMethod::kWinding && vertices->size() >= kDirectedKeyVertexLimit)
    return Status::InvalidArgument(
        fmt::format("the winding sign takes at most 2^31 vertices (the mesh has {})", vertices->size()));
  std::unique_ptr<MeshSign> sign(new MeshSign(method));
  Tables& tables = *sign->tables_;
  tables.triangles = triangles->size();
  auto keepTables = [&] {
    tables.vert_table = std::move(vertices);
    tables.corner_table = std::move(triangles);
    tables.verts = *tables.vert_table;
    tables.corners = *tables.corner_table;
  };
  if (method == SignMethod::kPseudonormal) {
    keepTables();
    tables.buildPseudonormals(interrupter);
  } else {
    const std::vector<Vec3d>& v = *vertices;
    const std::vector<std::array<uint32_t, 3>>& c = *triangles;
    std::vector<std::array<Vec3d, 3>> tris(c.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, tris.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t t = r.begin(); t != r.end(); ++t)
        for (int k = 0; k < 3; ++k) tris[t][k] = v[c[t][k]];
    });
    if (method == SignMethod::kWinding) {
      // Each triangle's part, for the certificate, when there are several.
      std::vector<uint32_t> vertex_part;
      if (findMeshParts(v.size(), c, &vertex_part, interrupter) > 1) {
        tables.part.resize(c.size());
        for (size_t t = 0; t < c.size(); ++t) tables.part[t] = vertex_part[c[t][0]];
      }
      std::vector<uint32_t>().swap(vertex_part);
      if (findDoubleSidedFaces(c, &tables.double_sided, interrupter) < 0) return interrupter->status();
      if (!isInterrupted(interrupter))
        tables.winding = std::make_unique<WindingNumber>(std::move(tris), 2.0, interrupter);
      // The certificate that signs most bricks with one query (signWindingCertified) reads pseudonormals and the
      // boundary's pieces; the fans closing the boundary make a cheap exact tier near it (windingUntil).
      keepTables();
      if (!isInterrupted(interrupter)) tables.buildPseudonormals(interrupter);
      if (!isInterrupted(interrupter)) {
        const std::vector<ChainEdge> chain = meshBoundaryChain(tables.corners);
        tables.boundary.build(tables.verts, chain, maxBoundaryPieces(tables.triangles));
        uint64_t walked = 0;  // the chain's edges with their multiplicity: the fans have at most 3/2 of these
        for (const ChainEdge& e : chain) walked += uint64_t(std::abs(e.net));
        if (walked > 0 && (3 * walked / 2 + 3) * kMaxFansPerTriangle <= tables.corners.size())
          tables.fans = std::make_unique<WindingNumber>(boundaryFans(tables.verts, chain), 2.0, interrupter);
      }
    } else {
      tables.parity = std::make_unique<ParityScene>(tris, interrupter);
      if (!isInterrupted(interrupter) && !tables.parity->ok())
        return Status::Internal(EmbreeLibrary::get().loaded
                                    ? "cannot create the Embree device for parity signs"
                                    : "parity signs need Embree (libembree3.so.3), which could not be loaded");
    }
  }
  if (isInterrupted(interrupter)) return interrupter->status();
  *out = std::move(sign);
  return Status::Ok();
}

bool MeshSign::inside(const Vec3d& p, uint32_t triangle, double distance) const {
  switch (method_) {
    case SignMethod::kPseudonormal: return tables_->insidePseudonormal(p, triangle, distance);
    case SignMethod::kWinding: {
      double error;
      return insideByWinding(tables_->windingAt(p, &error));
    }
    case SignMethod::kParity: return tables_->parity->inside(p);
    default: return false;
  }
}

SignShares MeshSign::signBrick(Brick& brick, const uint32_t* sites, const uint32_t* site_triangle, double voxel_size,
                               const Vec3d& scale) const {
  const Tables& s = *tables_;
  auto unitsOf = [&scale](const Coord& c) { return Vec3d{c.x * scale.x, c.y * scale.y, c.z * scale.z}; };
  auto triangleOf = [site_triangle](uint32_t site) { return site_triangle ? site_triangle[site] : site; };
  if (method_ == SignMethod::kPseudonormal) {
    // Pseudonormal signs (closed meshes, whose sign only changes across the surface), visiting only the delivered
    // voxels (bit by bit; a thin band's bricks are mostly undelivered) and keeping the last triangle's plane (a
    // brick's neighbouring voxels mostly share their closest triangle). A voxel farther from the surface than the
    // brick is wide (plus a margin for rounding) sees no surface inside the brick, so one sign test signs every
    // voxel of it; most bricks beyond a few voxels are like this.
    const double brick_diameter = 7 * std::sqrt(scale.lengthSqr()) + 0.5;  // units
    int far = -1;
    brick.mask.forEach([&](int i) {
      if (sites[i] != kNoSite && std::abs(brick.values[i]) > brick_diameter * voxel_size) far = i;
      return far < 0;
    });
    if (far >= 0) {
      const Vec3d p = unitsOf(brick.origin + brickLocal(far));
      if (s.insidePseudonormal(p, triangleOf(sites[far]), std::abs(brick.values[far]) / voxel_size))
        brick.mask.forEach([&](int i) { brick.values[i] = -std::abs(brick.values[i]); });
      return {brick.mask.count(), 0, 0, 0};
    }
    s.signByPseudonormal(brick, brick.mask, sites, site_triangle, voxel_size, scale);
    return {brick.mask.count(), 0, 0, 0};
  }
  BrickMask todo = brick.mask;  // the voxels still to sign
  int64_t certified = 0;        // signed by a certificate
  // Winding: a bound on the winding number's turn rate over the brick (and so along the path between two voxels).
  double brick_rate = std::numeric_limits<double>::infinity();
  seeds_internal::BoundaryCurves::Near near;  // winding: the boundary pieces near the brick
  Tables::KnownWindings known;  // winding: the voxels the certificates queried
  Tables::BrickPlans plans;     // winding: made for the voxels that take queries of their own
  if (method_ == SignMethod::kWinding) {
    auto boxCenter = [&](const Coord& lo, double half) {  // of the voxels lo .. lo + 2 half, in frame units
      return Vec3d{(lo.x + half) * scale.x, (lo.y + half) * scale.y, (lo.z + half) * scale.z};
    };
    const Vec3d brick_center = boxCenter(brick.origin, 3.5);
    const double brick_radius = 3.5 * std::sqrt(scale.lengthSqr());
    plans.center = brick_center, plans.radius = brick_radius;
    s.boundary.findNear(brick_center, brick_radius, &near);
    if (s.signWindingCertified(brick, brick.mask, brick_center, brick_radius, near, sites, site_triangle, voxel_size,
                               scale, &known))
      return {0, brick.mask.count(), 0, 0};
    // Refused whole (near a hole, a sharp edge, where parts meet): each 4^3 octant on its own, with half the spread
    // and, nearer the boundary, half the box, then each 2^3 cell of what is left, before any voxel takes a query of
    // its own.
    auto certifyBoxes = [&](const auto& boxes, int edge) {
      const int per_axis = kBrickSize / edge;
      const double half = 0.5 * (edge - 1);
      for (size_t k = 0; k < boxes.size() && !todo.empty(); ++k) {
        BrickMask box;
        for (int w = 0; w < kBrickVoxels / 64; ++w) box.words[w] = todo.words[w] & boxes[k].words[w];
        if (box.empty()) continue;
        const int i = int(k);
        const Coord lo{edge * (i % per_axis), edge * (i / per_axis % per_axis), edge * (i / (per_axis * per_axis))};
        if (!s.signWindingCertified(brick, box, boxCenter(brick.origin + lo, half), half * std::sqrt(scale.lengthSqr()),
                                    near, sites, site_triangle, voxel_size, scale, &known, &plans))
          continue;
        certified += box.count();
        for (int w = 0; w < kBrickVoxels / 64; ++w) todo.words[w] &= ~box.words[w];
      }
    };
    certifyBoxes(kOctants, 4);
    certifyBoxes(kCells, 2);
    if (!todo.empty())
      brick_rate = s.boundary.turnRate(near, brick_center, brick_radius, std::numeric_limits<double>::infinity());
  }
  // Winding number or parity, voxel by voxel: their sign on an open mesh also changes across its holes, away from the
  // surface. A voxel's distance to the surface is a ball around it that no surface crosses: a closed mesh's parity is
  // constant there, so a later voxel inside the ball (less a margin) takes its sign without a query. The winding number
  // also turns around the boundary curves inside such a ball, so it keeps its side of 1/2 only as far as its distance
  // from 1/2 (less the query's error) covers that turn.
  struct Ball {
    Vec3d c;
    double r2;
    bool inside;
    double slack;  // winding: |w - 1/2| at c less the query's error
    double drift;  // winding: the turn per unit of distance from c
  };
  // Winding: the voxels farthest from the surface first, whose balls reach farthest; a ball reaches its distance
  // less kWindingBallMargin (the band's distances are within a tenth of a voxel of the exact ones). Parity keeps index
  // order and a voxel of margin: on an open mesh ray parity is not constant off the surface (a ray's line sweeping
  // over a boundary edge changes it), so its values there depend on the order, and these are its recorded ones.
  // The order as keys (descending |value| for the winding number, then offset), sorted on the stack: a stable sort of
  // a vector, with its buffer, was ~1 % of the teapot's run at 256^3 (perf), and the balls grew by doubling.
  std::array<uint64_t, kBrickVoxels> order;
  int count = 0;
  todo.forEach([&](int i) {
    // A non-negative float's bits rank it; complemented, the largest first.
    const uint64_t rank = method_ == SignMethod::kWinding ? ~std::bit_cast<uint32_t>(std::abs(brick.values[i])) : 0;
    order[size_t(count++)] = rank << 32 | uint32_t(i);
  });
  std::sort(order.begin(), order.begin() + count);
  std::vector<Ball> balls;
  balls.reserve(size_t(count));
  const double min_step = std::min({scale.x, scale.y, scale.z});  // between two voxels, frame units
  const double ball_margin = method_ == SignMethod::kWinding ? kWindingBallMargin : 1.0;
  for (int k = 0; k < count; ++k) {
    const int i = int(uint32_t(order[size_t(k)]));
    const Vec3d p = unitsOf(brick.origin + brickLocal(i));
    bool in = false;
    bool found = false;
    for (auto it = balls.rbegin(); it != balls.rend(); ++it) {
      const double d2 = (p - it->c).lengthSqr();
      if (d2 < it->r2 && (method_ != SignMethod::kWinding || std::sqrt(d2) * it->drift < it->slack)) {
        in = it->inside, found = true;
        break;
      }
    }
    if (!found) {
      const double dist = std::abs(brick.values[i]) / voxel_size;
      const double r = dist - ball_margin;
      if (method_ == SignMethod::kWinding && onSheet(dist)) {
        // On a sheet the winding number is its two sides' mean, which the tiers read only to within their error (the
        // fans' tier gets one side's value or the other's): the sign of a zero distance goes outside, as ties do.
        in = false;
      } else if (method_ == SignMethod::kWinding) {
        double error;
        // A certificate's value decides here when far enough from 1/2, else the voxel takes its own query.
        const Tables::KnownWindings::Value* found = known.find(i);
        const bool decided = found && std::abs(found->w - 0.5) > found->error;
        const double w = decided ? found->w : s.windingAt(p, &error, &plans);
        if (decided) error = found->error;
        in = insideByWinding(w);
        // The path from the ball's centre to a voxel it signs lies in the brick and in the ball: the lower of their
        // turn rates bounds the turn along it. A ball that cannot sign even the nearest other voxel is not kept.
        const double slack = std::abs(w - 0.5) - error;
        if (sites[i] != kNoSite && r > 0 && slack > 0) {
          const double rate =
              std::min(brick_rate, s.boundary.turnRate(near, p, r, std::min(brick_rate, slack / min_step)));
          if (rate * min_step < slack) balls.push_back({p, r * r, in, slack, rate});
        }
      } else {
        in = s.parity->inside(p);
        if (r > 0) balls.push_back({p, r * r, in, 0, 0});
      }
    }
    if (in) brick.values[i] = -std::abs(brick.values[i]);
  }
  const int64_t n = todo.count();
  return method_ == SignMethod::kWinding ? SignShares{0, certified, n, 0} : SignShares{0, 0, 0, n};
}

static_assert(MeshSign::kBytesPerBoundaryPiece == seeds_internal::BoundaryCurves::kBytesPerPiece);

uint64_t MeshSign::memoryBytes() const {
  const Tables& t = *tables_;
  uint64_t bytes = sizeof(MeshSign) + sizeof(Tables) + t.verts.size() * sizeof(Vec3d) +
                   t.corners.size() * sizeof(t.corners[0]) +
                   (t.face_n.capacity() + t.vertex_n.capacity()) * sizeof(Normal3f) +
                   t.edge_mate.capacity() * sizeof(uint32_t) + t.shared_edge_n.capacity() * sizeof(t.shared_edge_n[0]) +
                   t.boundary.memoryBytes() + t.part.capacity() * sizeof(uint32_t) + t.double_sided.capacity();
  if (t.winding) bytes += t.winding->memoryBytes();
  if (t.fans) bytes += t.fans->memoryBytes();
  if (t.parity) bytes += estimateBytes(SignMethod::kParity, 0, t.triangles);
  return bytes;
}

uint64_t MeshSign::estimateBytes(SignMethod method, uint64_t vertices, uint64_t triangles) {
  switch (method) {
    case SignMethod::kPseudonormal:
      // Kept: vertices, corners and normals; while building, first face normals, angles and vertex sums, then (after
      // those are freed) each vertex's triangles, a third of that.
      return vertices * (sizeof(Vec3d) * 2 + sizeof(Normal3f)) +
             triangles * (sizeof(std::array<uint32_t, 3>) + sizeof(Normal3f) + 3 * sizeof(uint32_t) + sizeof(Vec3d) +
                          3 * sizeof(double));
    case SignMethod::kWinding: {
      // The mesh's winding tree, with each triangle's part; then each edge use's key (the boundary chain), the
      // boundary fans' tree, at most one fan triangle per kMaxFansPerTriangle, and the boundary's pieces, each in a
      // cell of its own at worst.
      return WindingNumber::estimateBytes(triangles) + triangles * (sizeof(uint32_t) + 1) +
             triangles * 3 * sizeof(uint64_t) + WindingNumber::estimateBytes(triangles / kMaxFansPerTriangle + 1) +
             maxBoundaryPieceBytes(triangles);
    }
    case SignMethod::kParity:
      // Embree's float vertices, indices and BVH (a generous 3x the buffers), and the triangles it is built from.
      return triangles * (sizeof(std::array<Vec3d, 3>) + 4 * (36 + 12));
    default: return 0;
  }
}

}  // namespace distband

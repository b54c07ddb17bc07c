#include "core/seeds/mesh_seeds.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <stdexcept>
#include <cmath>
#include <memory>
#include <type_traits>

#include <malloc.h>

#include <embree3/rtcore.h>
#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_group.h>

#include "core/first_touch.h"
#include "core/geometry.h"
#include "core/interruptible.h"
#include "core/mesh/winding_number.h"

namespace distband {

std::string_view meshSiteModeName(MeshSiteMode mode) {
  return mode == MeshSiteMode::kPaper ? "paper" : "exact-feature";
}
bool parseMeshSiteMode(std::string_view name, MeshSiteMode* mode) {
  if (name == "exact-feature") return *mode = MeshSiteMode::kExactFeature, true;
  if (name == "paper") return *mode = MeshSiteMode::kPaper, true;
  return false;
}
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

namespace {

Vec3d normalized(const Vec3d& v) {
  const double l = v.length();
  return l > 0 ? v * (1.0 / l) : Vec3d{};
}

// Embree scene for ray parity; owns the device and scene for as long as a sign function refers to it.
class ParityScene {
 public:
  ParityScene(const std::vector<std::array<Vec3d, 3>>& tris, const Interrupter* interrupter) {
    device_ = rtcNewDevice(nullptr);
    if (!device_) return;
    scene_ = rtcNewScene(device_);
    rtcSetSceneFlags(scene_, RTC_SCENE_FLAG_ROBUST);
    // Embree calls this while it builds the BVH; returning false cancels the build.
    if (interrupter)
      rtcSetSceneProgressMonitorFunction(
          scene_, [](void* ptr, double) { return !static_cast<const Interrupter*>(ptr)->interrupted(); },
          const_cast<Interrupter*>(interrupter));
    RTCGeometry geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(
        rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), tris.size() * 3));
    auto* idx = static_cast<unsigned*>(
        rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), tris.size()));
    for (size_t t = 0; t < tris.size(); ++t)
      for (int k = 0; k < 3; ++k) {
        v[9 * t + 3 * k + 0] = float(tris[t][k].x);
        v[9 * t + 3 * k + 1] = float(tris[t][k].y);
        v[9 * t + 3 * k + 2] = float(tris[t][k].z);
        idx[3 * t + k] = unsigned(3 * t + k);
      }
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene_, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(scene_);
  }
  ~ParityScene() {
    if (scene_) rtcReleaseScene(scene_);
    if (device_) rtcReleaseDevice(device_);
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
      rtcIntersect1(scene_, &ctx, &rh);
      if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) break;
      ++count;
      // Step past this hit; hits at the same distance (a shared edge or corner) count once.
      tnear = rh.ray.tfar + 1e-4f * std::max(1.0f, rh.ray.tfar);
    }
    return count;
  }
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

// Everything the sign function needs, immutable once built, shared by every copy of Seeds::sign.
struct MeshSigner {
  double voxel_size = 1;
  Vec3d scale{1, 1, 1};  // Grid::axisScale: voxel (x,y,z) sits at scale * (x,y,z) in unit space
  // A voxel farther from the surface than this (units) sees no surface inside its brick: the brick's diagonal plus a
  // margin for rounding.
  double brick_diameter = 7 * 1.7320508075688772 + 0.5;
  SignMethod method = SignMethod::kPseudonormal;
  std::vector<Vec3d> verts;                        // unit space
  std::vector<std::array<uint32_t, 3>> corners;    // mesh vertex ids
  std::vector<Normal3f> face_n, edge_n, vertex_n;  // pseudonormals (edge_n: 3 per triangle)
  std::vector<uint32_t> site_triangle;             // paper mode: site -> triangle (empty: site is the triangle)
  std::unique_ptr<WindingNumber> winding;
  std::unique_ptr<ParityScene> parity;

  uint32_t triangleOf(uint32_t site) const { return site_triangle.empty() ? site : site_triangle[site]; }
  Vec3d unitsOf(const Coord& c) const { return {c.x * scale.x, c.y * scale.y, c.z * scale.z}; }

  /// `dist` is p's distance to triangle t (voxels), known to float precision.
  bool insidePseudonormal(const Vec3d& p, uint32_t t, double dist) const {
    const double plane = face_n[t].dot(p - verts[corners[t][0]]);
    return planeDecides(plane, dist) ? plane < 0 : insideByClosestFeature(p, t);
  }

  /// When the distance is the plane's (`plane`: p's signed distance to triangle t's plane), the closest point lies in
  /// the face (up to ~0.5 % of the distance from its border, where any consistent pseudonormal agrees with the face
  /// normal): the plane's sign is the answer, no region tests needed.
  static bool planeDecides(double plane, double dist) { return plane * plane >= dist * dist * (1 - 1e-5); }

  /// The pseudonormal test proper: the sign of p against the normal of the feature of triangle t closest to it.
  bool insideByClosestFeature(const Vec3d& p, uint32_t t) const {
    const auto& c = corners[t];
    TriangleFeature f;
    const Vec3d cp = closestPointOnTriangle(p, verts[c[0]], verts[c[1]], verts[c[2]], &f);
    Normal3f n;
    switch (f) {
      case TriangleFeature::kFace: n = face_n[t]; break;
      case TriangleFeature::kEdgeAB: n = edge_n[3 * t + 0]; break;
      case TriangleFeature::kEdgeBC: n = edge_n[3 * t + 1]; break;
      case TriangleFeature::kEdgeCA: n = edge_n[3 * t + 2]; break;
      case TriangleFeature::kVertexA: n = vertex_n[corners[t][0]]; break;
      case TriangleFeature::kVertexB: n = vertex_n[corners[t][1]]; break;
      case TriangleFeature::kVertexC: n = vertex_n[corners[t][2]]; break;
    }
    return n.dot(p - cp) < 0;
  }

  // Pseudonormal signs (closed meshes, whose sign only changes across the surface), visiting only the delivered
  // voxels (bit by bit; a thin band's bricks are mostly undelivered) and keeping the last triangle's plane (a
  // brick's neighbouring voxels mostly share their closest triangle). A voxel farther from the surface than the
  // brick is wide (plus a margin for rounding) sees no surface inside the brick, so one sign test signs every voxel
  // of it; most bricks beyond a few voxels are like this.
  void signPseudonormal(Brick& brick, const uint32_t* sites) const {
    auto forEachDelivered = [&](auto&& visit) {
      for (int w = 0; w < kBrickVoxels / 64; ++w)
        for (uint64_t bits = brick.mask.words[w]; bits; bits &= bits - 1)
          if (!visit(w * 64 + std::countr_zero(bits))) return;
    };
    int far = -1;
    forEachDelivered([&](int i) {
      if (sites[i] != kNoSite && std::abs(brick.values[i]) > brick_diameter * voxel_size) far = i;
      return far < 0;
    });
    if (far >= 0) {
      const Vec3d p = unitsOf(brick.origin + brickLocal(far));
      if (insidePseudonormal(p, triangleOf(sites[far]), std::abs(brick.values[far]) / voxel_size))
        forEachDelivered([&](int i) {
          brick.values[i] = -std::abs(brick.values[i]);
          return true;
        });
      return;
    }
    uint32_t last = kNoSite;
    Vec3d n{}, v0{};
    forEachDelivered([&](int i) {
      if (sites[i] == kNoSite) return true;
      const uint32_t t = triangleOf(sites[i]);
      if (t != last) {
        n = {double(face_n[t].x), double(face_n[t].y), double(face_n[t].z)};
        v0 = verts[corners[t][0]];
        last = t;
      }
      const Vec3d p = unitsOf(brick.origin + brickLocal(i));
      const double dist = std::abs(brick.values[i]) / voxel_size;
      // insidePseudonormal, with the plane kept (the same arithmetic as Normal3f::dot).
      const Vec3d q = p - v0;
      const double plane = n.x * q.x + n.y * q.y + n.z * q.z;
      const bool inside = planeDecides(plane, dist) ? plane < 0 : insideByClosestFeature(p, t);
      if (inside) brick.values[i] = -std::abs(brick.values[i]);
      return true;
    });
  }

  void sign(Brick& brick, const uint32_t* sites) const {
    if (method == SignMethod::kPseudonormal) return signPseudonormal(brick, sites);
    // Winding number or parity: their sign on an open mesh also changes across its holes, away from the surface, so
    // no brick is signed by one test. A voxel's distance to the surface is a ball of one sign around it: a later
    // voxel inside a ball (less a voxel of margin) takes its sign without a query.
    struct Ball {
      Vec3d c;
      double r2;
      bool inside;
    };
    std::vector<Ball> balls;
    for (int i = 0; i < kBrickVoxels; ++i) {
      if (!brick.mask.test(i)) continue;
      const Vec3d p = unitsOf(brick.origin + brickLocal(i));
      bool inside = false;
      bool found = false;
      for (auto it = balls.rbegin(); it != balls.rend(); ++it)
        if ((p - it->c).lengthSqr() < it->r2) {
          inside = it->inside, found = true;
          break;
        }
      if (!found) {
        inside = method == SignMethod::kWinding ? winding->query(p) > 0.5 : parity->inside(p);
        const double r = std::abs(brick.values[i]) / voxel_size - 1.0;
        if (r > 0) balls.push_back({p, r * r, inside});
      }
      if (inside) brick.values[i] = -std::abs(brick.values[i]);
    }
  }
};

void buildPseudonormals(MeshSigner* s, const Interrupter* interrupter) {
  const size_t nt = s->corners.size();
  auto stop = [&](size_t i) { return (i & 0xFFFF) == 0 && isInterrupted(interrupter); };
  std::vector<Vec3d> face(nt);
  std::vector<std::array<double, 3>> angles(nt);
  tbb::parallel_for(size_t(0), nt, [&](size_t t) {
    if (tbb::is_current_task_group_canceling()) return;
    const auto& c = s->corners[t];
    const Vec3d tri[3] = {s->verts[c[0]], s->verts[c[1]], s->verts[c[2]]};
    face[t] = normalized((tri[1] - tri[0]).cross(tri[2] - tri[0]));
    for (int k = 0; k < 3; ++k) {
      const Vec3d e1 = normalized(tri[(k + 1) % 3] - tri[k]), e2 = normalized(tri[(k + 2) % 3] - tri[k]);
      angles[t][k] = std::acos(std::clamp(e1.dot(e2), -1.0, 1.0));
    }
  });
  std::vector<Vec3d> vertex(s->verts.size());
  for (size_t t = 0; t < nt; ++t) {
    if (stop(t)) return;
    for (int k = 0; k < 3; ++k) vertex[s->corners[t][k]] = vertex[s->corners[t][k]] + face[t] * angles[t][k];
  }
  s->vertex_n.resize(vertex.size());
  s->face_n.resize(nt);
  // Edge pseudonormal: the sum of the normals of the triangles sharing the edge.
  struct EdgeUse {
    uint64_t key;
    uint32_t slot;  // 3 * triangle + edge
  };
  std::vector<EdgeUse> uses(3 * nt);
  // Independent per element, so in parallel (serial, these loops were a good part of the seeds' time).
  tbb::parallel_for(tbb::blocked_range<size_t>(0, vertex.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t v = r.begin(); v != r.end(); ++v) s->vertex_n[v] = Normal3f(normalized(vertex[v]));
  });
  tbb::parallel_for(tbb::blocked_range<size_t>(0, nt, 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t t = r.begin(); t != r.end(); ++t) {
      s->face_n[t] = Normal3f(face[t]);
      for (int e = 0; e < 3; ++e) {
        const uint64_t a = s->corners[t][e], b = s->corners[t][(e + 1) % 3];
        uses[3 * t + e] = {std::min(a, b) << 32 | std::max(a, b), uint32_t(3 * t + e)};
      }
    }
  });
  if (isInterrupted(interrupter)) return;
  tbb::parallel_sort(uses.begin(), uses.end(), [](const EdgeUse& x, const EdgeUse& y) {
    return x.key < y.key || (x.key == y.key && x.slot < y.slot);
  });
  s->edge_n.resize(3 * nt);
  for (size_t i = 0; i < uses.size();) {
    if (stop(i)) return;
    size_t j = i;
    Vec3d sum{};
    while (j < uses.size() && uses[j].key == uses[i].key) sum = sum + face[uses[j++].slot / 3];
    for (size_t k = i; k < j; ++k) s->edge_n[uses[k].slot] = Normal3f(normalized(sum));
    i = j;
  }
}

// int(std::ceil(v)) and int(std::floor(v)), the same integers for every v (both convert by truncation), in a few
// instructions: baseline x86-64 has no roundsd, and the inline ceil and floor sequences, four for every row of
// voxels, were ~11 % of the seed scan's instructions (armadillo 256^3 hw3: 531 M -> 472 M).
inline int ceilInt(double v) {
  const int i = int(v);
  return i + (double(i) < v);
}
inline int floorInt(double v) {
  const int i = int(v);
  return i - (double(i) > v);
}

// Squared voxels: rounding in the bounding-box and exact distances of grid-sized coordinates is ~1e-12 of this.
constexpr double kBoxPruneMargin = 1e-6;

struct Candidate {
  int64_t brick;
  uint32_t tri;
};

}  // namespace

namespace {

// makeMeshSeeds' work, run under runInterruptible (every TBB task it starts stops when the interrupter trips); its
// serial loops poll too. TBB only cancels tasks not yet started, and a parallel_for hands a thread ranges of up to
// 1/(4 x threads) of the loop (hundreds of ms at 1024^3), so loop bodies check is_current_task_group_canceling().
Status buildMeshSeeds(const Grid& grid, const TriangleMesh& mesh, const MeshSeedOptions& options, Seeds* out,
                           MeshSeedStats* stats) {
  const auto start = std::chrono::steady_clock::now();
  const Interrupter* interrupter = options.interrupter;
  if (Status s = grid.validate(); !s.ok()) return s.withPrefix("grid");
  if (mesh.triangles.empty()) return Status::InvalidArgument("the mesh has no triangles");
  if (!(options.band_radius_voxels > 0 && options.band_radius_voxels <= 8))
    return Status::InvalidArgument(fmt::format("band radius must be in (0, 8] voxels (got {})", options.band_radius_voxels));
  if (!(options.limit_voxels > 0)) return Status::InvalidArgument(fmt::format("limit must be > 0 (got {})", options.limit_voxels));
  if (options.sign == SignMethod::kAuto) throw std::invalid_argument("makeMeshSeeds: the sign method auto must be resolved first (resolveSignMethod)");
  for (const auto& t : mesh.triangles)
    for (uint32_t i : t)
      if (i >= mesh.vertices.size()) return Status::InvalidArgument("a triangle refers to a vertex that does not exist");
  const size_t nt = mesh.triangles.size();
  if (nt >= kNoSite) return Status::ResourceExhausted(fmt::format("the mesh has {} triangles, more than the engine's {} sites", nt, kNoSite - 1));

  // Unit-space copies (core/grid.h), in parallel: serial, these loops were ~20 ms of a 52 k-triangle mesh's seeds.
  std::vector<Vec3d> verts(mesh.vertices.size());  // unit space
  tbb::parallel_for(tbb::blocked_range<size_t>(0, verts.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t v = r.begin(); v != r.end(); ++v) verts[v] = grid.unitsOf(mesh.vertices[v]);
  });
  std::vector<std::array<Vec3d, 3>> tris(nt);
  std::vector<Vec3d> normals(nt);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, nt, 4096), [&](const tbb::blocked_range<size_t>& r) {
    if (tbb::is_current_task_group_canceling()) return;
    for (size_t t = r.begin(); t != r.end(); ++t) {
      for (int k = 0; k < 3; ++k) tris[t][k] = verts[mesh.triangles[t][k]];
      normals[t] = normalized((tris[t][1] - tris[t][0]).cross(tris[t][2] - tris[t][0]));
    }
  });
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);
  // The band's radius in units: on an anisotropic grid a voxel step along an axis is up to maxAxisScale() units, and
  // the band must hold voxels on both sides of the surface along every axis.
  const double radius = std::min(options.band_radius_voxels * grid.maxAxisScale(), options.limit_voxels);
  const double r2 = radius * radius;
  const Coord dims = grid.dims();
  const Vec3d scale = grid.axisScale();
  const bool scaled = !grid.cubic();

  // Voxel box of each triangle's radius-neighbourhood, clipped to the grid (lo > hi: nothing to scan).
  auto voxelBox = [&](size_t t, Coord* lo, Coord* hi) {
    const auto& tri = tris[t];
    auto range = [&](double a, double b, double c, double s, int n, int32_t* l, int32_t* h) {
      const double mn = std::min({a, b, c}) - radius, mx = std::max({a, b, c}) + radius;  // units
      *l = static_cast<int32_t>(std::max(0.0, std::ceil(scaled ? mn / s : mn)));
      *h = static_cast<int32_t>(std::min(double(n - 1), std::floor(scaled ? mx / s : mx)));
    };
    range(tri[0].x, tri[1].x, tri[2].x, scale.x, dims.x, &lo->x, &hi->x);
    range(tri[0].y, tri[1].y, tri[2].y, scale.y, dims.y, &lo->y, &hi->y);
    range(tri[0].z, tri[1].z, tri[2].z, scale.z, dims.z, &lo->z, &hi->z);
    return lo->x <= hi->x && lo->y <= hi->y && lo->z <= hi->z;
  };
  // 1. (brick, triangle) candidates: every brick a triangle's neighbourhood overlaps.
  std::vector<uint64_t> offsets(nt + 1, 0);
  tbb::parallel_for(size_t(0), nt, [&](size_t t) {
    Coord lo, hi;
    if (tbb::is_current_task_group_canceling() || !voxelBox(t, &lo, &hi)) return;
    offsets[t + 1] = uint64_t((hi.x >> 3) - (lo.x >> 3) + 1) * ((hi.y >> 3) - (lo.y >> 3) + 1) *
                     ((hi.z >> 3) - (lo.z >> 3) + 1);
  });
  for (size_t t = 0; t < nt; ++t) offsets[t + 1] += offsets[t];
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);
  std::vector<Candidate> cand(offsets[nt]);
  tbb::parallel_for(size_t(0), nt, [&](size_t t) {
    Coord lo, hi;
    if (tbb::is_current_task_group_canceling() || !voxelBox(t, &lo, &hi)) return;
    uint64_t o = offsets[t];
    for (int z = lo.z >> 3; z <= hi.z >> 3; ++z)
      for (int y = lo.y >> 3; y <= hi.y >> 3; ++y)
        for (int x = lo.x >> 3; x <= hi.x >> 3; ++x)
          cand[o++] = {grid.brickIndex({x, y, z}), uint32_t(t)};
  });
  tbb::parallel_sort(cand.begin(), cand.end(), [](const Candidate& a, const Candidate& b) {
    return a.brick < b.brick || (a.brick == b.brick && a.tri < b.tri);
  });
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);
  std::vector<size_t> starts;
  for (size_t i = 0; i < cand.size(); ++i)
    if (i == 0 || cand[i].brick != cand[i - 1].brick) starts.push_back(i);
  starts.push_back(cand.size());
  const size_t nbricks = starts.size() - 1;

  // 2. Per brick: each voxel's closest triangle among its candidates, kept when within the radius. Compiled twice: on
  // a cubic grid voxel coordinates are unit-space coordinates; on an anisotropic one they are scaled (and unit-space
  // bounds divided back into voxel coordinates).
  std::vector<std::vector<BandVoxel>> per_brick(nbricks);
  auto scanBrick = [&](size_t b, auto scaled_tag) {
    constexpr bool kScaled = decltype(scaled_tag)::value;
    auto unitsX = [&](int x) { return kScaled ? x * scale.x : double(x); };
    auto unitsY = [&](int y) { return kScaled ? y * scale.y : double(y); };
    auto unitsZ = [&](int z) { return kScaled ? z * scale.z : double(z); };
    auto voxelZ = [&](double u) { return kScaled ? u / scale.z : u; };
    const int64_t key = cand[starts[b]].brick;
    const Coord borg = grid.brickOrigin(key);
    std::array<double, kBrickVoxels> best;
    std::array<uint32_t, kBrickVoxels> best_t;
    best.fill(r2);
    best_t.fill(kNoSite);
    for (size_t i = starts[b]; i < starts[b + 1]; ++i) {
      const uint32_t t = cand[i].tri;
      Coord lo, hi;
      voxelBox(t, &lo, &hi);
      lo = {std::max(lo.x, borg.x), std::max(lo.y, borg.y), std::max(lo.z, borg.z)};
      hi = {std::min(hi.x, borg.x + 7), std::min(hi.y, borg.y + 7), std::min(hi.z, borg.z + 7)};
      const auto& tri = tris[t];
      const TriangleDistance dist(tri[0], tri[1], tri[2]);
      const Vec3d n = normals[t];
      const double plane0 = n.dot(tri[0]);
      const double bx0 = std::min({tri[0].x, tri[1].x, tri[2].x}), bx1 = std::max({tri[0].x, tri[1].x, tri[2].x});
      const double by0 = std::min({tri[0].y, tri[1].y, tri[2].y}), by1 = std::max({tri[0].y, tri[1].y, tri[2].y});
      const double bz0 = std::min({tri[0].z, tri[1].z, tri[2].z}), bz1 = std::max({tri[0].z, tri[1].z, tri[2].z});
      for (int x = lo.x; x <= hi.x; ++x) {
        const double ux = unitsX(x);
        const double ex = ux < bx0 ? bx0 - ux : (ux > bx1 ? ux - bx1 : 0.0);
        for (int y = lo.y; y <= hi.y; ++y) {
          // Only the z-run within the radius of the triangle's bounding box can hold band voxels.
          const double uy = unitsY(y);
          const double ey = uy < by0 ? by0 - uy : (uy > by1 ? uy - by1 : 0.0);
          const double exy2 = ex * ex + ey * ey;
          const double rest = r2 - exy2;
          if (rest < 0) continue;
          const double reach = std::sqrt(rest);
          int z0 = std::max(lo.z, ceilInt(voxelZ(bz0 - reach))), z1 = std::min(hi.z, floorInt(voxelZ(bz1 + reach)));
          const double row_plane = n.x * ux + n.y * uy - plane0;
          // ... and within the radius of the triangle's plane (when the plane is not nearly parallel to z).
          if (std::abs(n.z) > 0.25) {
            const double za = (-radius - row_plane) / n.z, zb = (radius - row_plane) / n.z;
            z0 = std::max(z0, ceilInt(voxelZ(std::min(za, zb))));
            z1 = std::min(z1, floorInt(voxelZ(std::max(za, zb))));
          }
          for (int z = z0; z <= z1; ++z) {
            const double uz = unitsZ(z);
            const double plane = row_plane + n.z * uz;
            const int o = brickOffset(x & 7, y & 7, z & 7);
            if (plane * plane > best[o]) continue;
            // The bounding box is no farther than the triangle: a voxel already closer than it to another triangle
            // skips the exact distance (most do: the triangles near a voxel overlap). The margin is far above
            // rounding, so a tie or a closer triangle is never skipped.
            const double ez = uz < bz0 ? bz0 - uz : (uz > bz1 ? uz - bz1 : 0.0);
            if (exy2 + ez * ez > best[o] + kBoxPruneMargin) continue;
            const double d2 = dist.dist2({ux, uy, uz});
            if (d2 < best[o] || (d2 == best[o] && t < best_t[o])) best[o] = d2, best_t[o] = t;
          }
        }
      }
    }
    auto& v = per_brick[b];
    // One allocation of the exact size (growing by push_back reallocated ~8 times a brick, from every thread).
    v.reserve(size_t(std::count_if(best_t.begin(), best_t.end(), [](uint32_t t) { return t != kNoSite; })));
    for (int o = 0; o < kBrickVoxels; ++o)
      if (best_t[o] != kNoSite) v.push_back({borg + brickLocal(o), best_t[o]});
  };
  tbb::parallel_for(size_t(0), nbricks, [&](size_t b) {
    if (tbb::is_current_task_group_canceling()) return;
    scaled ? scanBrick(b, std::true_type{}) : scanBrick(b, std::false_type{});
  });
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);
  const size_t scratch_bytes = cand.size() * sizeof(Candidate);
  std::vector<Candidate>().swap(cand);
  std::vector<size_t> band_at(nbricks + 1, 0);
  for (size_t b = 0; b < nbricks; ++b) band_at[b + 1] = band_at[b] + per_brick[b].size();

  Seeds seeds;
  seeds.band_exact = true;  // each band voxel's closest triangle among all within the radius: its closest overall
  // Sized in steps of 256 Ki voxels (4 MiB) with a poll between them, its pages first touched in parallel: the
  // zero-fill first-touched fresh pages on one thread, which on some virtual machines costs ~3 ms a MiB (measured
  // here: 83 MB took 260 ms).
  seeds.band.reserve(band_at[nbricks]);
  touchPages(seeds.band.data(), band_at[nbricks] * sizeof(BandVoxel));
  for (size_t size = 0; size < band_at[nbricks];) {
    if (isInterrupted(interrupter)) return interruptedStatus(interrupter);
    size = std::min(band_at[nbricks], size + (size_t(256) << 10));
    seeds.band.resize(size);
  }
  tbb::parallel_for(size_t(0), nbricks, [&](size_t b) {
    if (tbb::is_current_task_group_canceling()) return;
    std::copy(per_brick[b].begin(), per_brick[b].end(), seeds.band.begin() + band_at[b]);
    std::vector<BandVoxel>().swap(per_brick[b]);
  });
  std::vector<std::vector<BandVoxel>>().swap(per_brick);
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);

  auto signer = std::make_shared<MeshSigner>();
  signer->voxel_size = grid.voxelSize();
  signer->scale = scale;
  if (scaled) {
    const double diagonal = std::sqrt(scale.lengthSqr());  // a voxel step along every axis, in units
    signer->brick_diameter = 7 * diagonal + 0.5;
  }
  signer->method = options.sign;
  if (options.mode == MeshSiteMode::kPaper) {
    // 3p. Paper mode: each band voxel's closest point becomes a site of its own.
    seeds.kind = SiteKind::kPoint;
    seeds.points.resize(seeds.band.size());
    if (options.sign == SignMethod::kPseudonormal) signer->site_triangle.resize(seeds.band.size());
    seeds.site_feature.resize(seeds.band.size());  // closest features: the triangle of each point site
    tbb::parallel_for(size_t(0), seeds.band.size(), [&](size_t i) {
      if (tbb::is_current_task_group_canceling()) return;
      BandVoxel& bv = seeds.band[i];
      const auto& tri = tris[bv.site];
      seeds.points[i] = closestPointOnTriangle(signer->unitsOf(bv.voxel), tri[0], tri[1], tri[2]);
      if (!signer->site_triangle.empty()) signer->site_triangle[i] = bv.site;
      seeds.site_feature[i] = bv.site;
      bv.site = static_cast<uint32_t>(i);
    });
  } else {
    seeds.kind = SiteKind::kTriangle;
  }
  switch (options.sign) {
    case SignMethod::kAuto:  // rejected above
    case SignMethod::kUnsigned: break;
    case SignMethod::kPseudonormal:
      signer->verts = std::move(verts);
      signer->corners = mesh.triangles;
      buildPseudonormals(signer.get(), interrupter);
      break;
    case SignMethod::kWinding:
      signer->winding = std::make_unique<WindingNumber>(tris, 2.0, interrupter);
      break;
    case SignMethod::kParity:
      signer->parity = std::make_unique<ParityScene>(tris, interrupter);
      if (isInterrupted(interrupter)) return interruptedStatus(interrupter);
      if (!signer->parity->ok()) return Status::Internal("cannot create the Embree device for parity signs");
      break;
  }
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);
  if (options.sign != SignMethod::kUnsigned)
    seeds.sign = [signer](Brick& brick, const uint32_t* sites) { signer->sign(brick, sites); };
  if (seeds.kind == SiteKind::kTriangle) seeds.triangles = std::move(tris);
  // The scan's temporaries (as large as the band) were freed in the worker threads' malloc arenas, which keep
  // the pages; when that is a sizeable amount, hand them back so the engine's bricks do not come on top of them.
  if (scratch_bytes + seeds.band.size() * sizeof(BandVoxel) >= (size_t(64) << 20)) ::malloc_trim(0);

  if (stats) {
    stats->band_voxels = static_cast<int64_t>(seeds.band.size());
    stats->bricks_scanned = static_cast<int64_t>(nbricks);
    stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  *out = std::move(seeds);
  return Status::Ok();
}

}  // namespace

Status makeMeshSeeds(const Grid& grid, const TriangleMesh& mesh, const MeshSeedOptions& options, Seeds* out,
                     MeshSeedStats* stats) {
  Status status;
  Seeds seeds;
  if (!runInterruptible(options.interrupter, [&] { status = buildMeshSeeds(grid, mesh, options, &seeds, stats); }))
    return interruptedStatus(options.interrupter);
  if (status.ok()) *out = std::move(seeds);
  return status;
}

}  // namespace distband

#include "core/seeds/mesh_sign.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

#include <embree3/rtcore.h>
#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "core/geometry.h"
#include "core/mesh/winding_number.h"
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

// Embree scene for ray parity; owns the device and scene for as long as a sign refers to it.
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

/// When the distance is the plane's (`plane`: p's signed distance to triangle t's plane), the closest point lies in
/// the face (up to ~0.5 % of the distance from its border, where any consistent pseudonormal agrees with the face
/// normal): the plane's sign is the answer, no region tests needed.
bool planeDecides(double plane, double dist) { return plane * plane >= dist * dist * (1 - 1e-5); }

}  // namespace

// Everything a method's test needs, immutable once built.
struct MeshSign::Tables {
  std::vector<Vec3d> verts;                        // the caller's frame
  std::vector<std::array<uint32_t, 3>> corners;    // mesh vertex ids
  std::vector<Normal3f> face_n, edge_n, vertex_n;  // pseudonormals (edge_n: 3 per triangle)
  std::unique_ptr<WindingNumber> winding;
  std::unique_ptr<ParityScene> parity;
  uint64_t triangles = 0;

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
      case TriangleFeature::kEdgeAB: n = edge_n[3 * t + 0]; break;
      case TriangleFeature::kEdgeBC: n = edge_n[3 * t + 1]; break;
      case TriangleFeature::kEdgeCA: n = edge_n[3 * t + 2]; break;
      case TriangleFeature::kVertexA: n = vertex_n[corners[t][0]]; break;
      case TriangleFeature::kVertexB: n = vertex_n[corners[t][1]]; break;
      case TriangleFeature::kVertexC: n = vertex_n[corners[t][2]]; break;
    }
    return n.dot(p - cp) < 0;
  }

  void buildPseudonormals(const Interrupter* interrupter);
};

void MeshSign::Tables::buildPseudonormals(const Interrupter* interrupter) {
  const size_t nt = corners.size();
  auto stop = [&](size_t i) { return (i & 0xFFFF) == 0 && isInterrupted(interrupter); };
  std::vector<Vec3d> face(nt);
  std::vector<std::array<double, 3>> angles(nt);
  tbb::parallel_for(size_t(0), nt, [&](size_t t) {
    if (tbb::is_current_task_group_canceling()) return;
    const auto& c = corners[t];
    const Vec3d tri[3] = {verts[c[0]], verts[c[1]], verts[c[2]]};
    face[t] = normalized((tri[1] - tri[0]).cross(tri[2] - tri[0]));
    for (int k = 0; k < 3; ++k) {
      const Vec3d e1 = normalized(tri[(k + 1) % 3] - tri[k]), e2 = normalized(tri[(k + 2) % 3] - tri[k]);
      angles[t][k] = std::acos(std::clamp(e1.dot(e2), -1.0, 1.0));
    }
  });
  std::vector<Vec3d> vertex(verts.size());
  for (size_t t = 0; t < nt; ++t) {
    if (stop(t)) return;
    for (int k = 0; k < 3; ++k) vertex[corners[t][k]] = vertex[corners[t][k]] + face[t] * angles[t][k];
  }
  vertex_n.resize(vertex.size());
  face_n.resize(nt);
  // Edge pseudonormal: the sum of the normals of the triangles sharing the edge.
  struct EdgeUse {
    uint64_t key;
    uint32_t slot;  // 3 * triangle + edge
  };
  std::vector<EdgeUse> uses(3 * nt);
  // Independent per element, so in parallel (serial, these loops were a good part of the seeds' time).
  tbb::parallel_for(tbb::blocked_range<size_t>(0, vertex.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t v = r.begin(); v != r.end(); ++v) vertex_n[v] = Normal3f(normalized(vertex[v]));
  });
  tbb::parallel_for(tbb::blocked_range<size_t>(0, nt, 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t t = r.begin(); t != r.end(); ++t) {
      face_n[t] = Normal3f(face[t]);
      for (int e = 0; e < 3; ++e) {
        const uint64_t a = corners[t][e], b = corners[t][(e + 1) % 3];
        uses[3 * t + e] = {std::min(a, b) << 32 | std::max(a, b), uint32_t(3 * t + e)};
      }
    }
  });
  if (isInterrupted(interrupter)) return;
  tbb::parallel_sort(uses.begin(), uses.end(), [](const EdgeUse& x, const EdgeUse& y) {
    return x.key < y.key || (x.key == y.key && x.slot < y.slot);
  });
  edge_n.resize(3 * nt);
  for (size_t i = 0; i < uses.size();) {
    if (stop(i)) return;
    size_t j = i;
    Vec3d sum{};
    while (j < uses.size() && uses[j].key == uses[i].key) sum = sum + face[uses[j++].slot / 3];
    for (size_t k = i; k < j; ++k) edge_n[uses[k].slot] = Normal3f(normalized(sum));
    i = j;
  }
}

MeshSign::MeshSign(SignMethod method) : method_(method), tables_(std::make_unique<Tables>()) {}
MeshSign::~MeshSign() = default;

Status MeshSign::build(std::vector<Vec3d> vertices, const std::vector<std::array<uint32_t, 3>>& triangles,
                       SignMethod method, const Interrupter* interrupter, std::unique_ptr<MeshSign>* out) {
  if (method != SignMethod::kPseudonormal && method != SignMethod::kWinding && method != SignMethod::kParity)
    return Status::InvalidArgument(
        fmt::format("a mesh sign is built for pseudonormal, winding or parity (got {})", signMethodName(method)));
  for (const auto& t : triangles)
    for (uint32_t i : t)
      if (i >= vertices.size()) return Status::InvalidArgument("a triangle refers to a vertex that does not exist");
  std::unique_ptr<MeshSign> sign(new MeshSign(method));
  Tables& tables = *sign->tables_;
  tables.triangles = triangles.size();
  if (method == SignMethod::kPseudonormal) {
    tables.verts = std::move(vertices);
    tables.corners = triangles;
    tables.buildPseudonormals(interrupter);
  } else {
    std::vector<std::array<Vec3d, 3>> tris(triangles.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, tris.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t t = r.begin(); t != r.end(); ++t)
        for (int k = 0; k < 3; ++k) tris[t][k] = vertices[triangles[t][k]];
    });
    std::vector<Vec3d>().swap(vertices);
    if (method == SignMethod::kWinding) {
      tables.winding = std::make_unique<WindingNumber>(std::move(tris), 2.0, interrupter);
    } else {
      tables.parity = std::make_unique<ParityScene>(tris, interrupter);
      if (!isInterrupted(interrupter) && !tables.parity->ok())
        return Status::Internal("cannot create the Embree device for parity signs");
    }
  }
  if (isInterrupted(interrupter)) return interrupter->status();
  *out = std::move(sign);
  return Status::Ok();
}

bool MeshSign::inside(const Vec3d& p, uint32_t triangle, double distance) const {
  switch (method_) {
    case SignMethod::kPseudonormal: return tables_->insidePseudonormal(p, triangle, distance);
    case SignMethod::kWinding: return tables_->winding->query(p) > 0.5;
    case SignMethod::kParity: return tables_->parity->inside(p);
    default: return false;
  }
}

void MeshSign::signBrick(Brick& brick, const uint32_t* sites, const uint32_t* site_triangle, double voxel_size) const {
  const Tables& s = *tables_;
  auto triangleOf = [site_triangle](uint32_t site) { return site_triangle ? site_triangle[site] : site; };
  if (method_ == SignMethod::kPseudonormal) {
    // Pseudonormal signs (closed meshes, whose sign only changes across the surface), visiting only the delivered
    // voxels (bit by bit; a thin band's bricks are mostly undelivered) and keeping the last triangle's plane (a
    // brick's neighbouring voxels mostly share their closest triangle). A voxel farther from the surface than the
    // brick is wide (plus a margin for rounding) sees no surface inside the brick, so one sign test signs every
    // voxel of it; most bricks beyond a few voxels are like this.
    constexpr double kBrickDiameter = 7 * 1.7320508075688772 + 0.5;
    auto forEachDelivered = [&](auto&& visit) {
      for (int w = 0; w < kBrickVoxels / 64; ++w)
        for (uint64_t bits = brick.mask.words[w]; bits; bits &= bits - 1)
          if (!visit(w * 64 + std::countr_zero(bits))) return;
    };
    int far = -1;
    forEachDelivered([&](int i) {
      if (sites[i] != kNoSite && std::abs(brick.values[i]) > kBrickDiameter * voxel_size) far = i;
      return far < 0;
    });
    if (far >= 0) {
      const Coord c = brick.origin + brickLocal(far);
      const Vec3d p{double(c.x), double(c.y), double(c.z)};
      if (s.insidePseudonormal(p, triangleOf(sites[far]), std::abs(brick.values[far]) / voxel_size))
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
        n = {double(s.face_n[t].x), double(s.face_n[t].y), double(s.face_n[t].z)};
        v0 = s.verts[s.corners[t][0]];
        last = t;
      }
      const Coord c = brick.origin + brickLocal(i);
      const Vec3d p{double(c.x), double(c.y), double(c.z)};
      const double dist = std::abs(brick.values[i]) / voxel_size;
      // insidePseudonormal, with the plane kept (the same arithmetic as Normal3f::dot).
      const Vec3d q = p - v0;
      const double plane = n.x * q.x + n.y * q.y + n.z * q.z;
      const bool in = planeDecides(plane, dist) ? plane < 0 : s.insideByClosestFeature(p, t);
      if (in) brick.values[i] = -std::abs(brick.values[i]);
      return true;
    });
    return;
  }
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
    const Coord c = brick.origin + brickLocal(i);
    const Vec3d p{double(c.x), double(c.y), double(c.z)};
    bool in = false;
    bool found = false;
    for (auto it = balls.rbegin(); it != balls.rend(); ++it)
      if ((p - it->c).lengthSqr() < it->r2) {
        in = it->inside, found = true;
        break;
      }
    if (!found) {
      in = inside(p, kNoSite, 0);
      const double r = std::abs(brick.values[i]) / voxel_size - 1.0;
      if (r > 0) balls.push_back({p, r * r, in});
    }
    if (in) brick.values[i] = -std::abs(brick.values[i]);
  }
}

uint64_t MeshSign::memoryBytes() const {
  const Tables& t = *tables_;
  uint64_t bytes = sizeof(MeshSign) + sizeof(Tables) + t.verts.capacity() * sizeof(Vec3d) +
                   t.corners.capacity() * sizeof(t.corners[0]) +
                   (t.face_n.capacity() + t.edge_n.capacity() + t.vertex_n.capacity()) * sizeof(Normal3f);
  if (t.winding) bytes += t.winding->memoryBytes();
  if (t.parity) bytes += estimateBytes(SignMethod::kParity, 0, t.triangles);
  return bytes;
}

uint64_t MeshSign::estimateBytes(SignMethod method, uint64_t vertices, uint64_t triangles) {
  switch (method) {
    case SignMethod::kPseudonormal:
      // Kept: vertices, corners and normals; while building: face normals, angles, vertex sums and edge uses.
      return vertices * (sizeof(Vec3d) * 2 + sizeof(Normal3f)) +
             triangles * (sizeof(std::array<uint32_t, 3>) + 4 * sizeof(Normal3f) + sizeof(Vec3d) +
                          3 * sizeof(double) + 3 * 16);
    case SignMethod::kWinding:
      // The triangles, twice while the tree is built, and about two nodes per leaf of a few triangles.
      return triangles * (2 * sizeof(std::array<Vec3d, 3>) + 64);
    case SignMethod::kParity:
      // Embree's float vertices, indices and BVH (a generous 3x the buffers), and the triangles it is built from.
      return triangles * (sizeof(std::array<Vec3d, 3>) + 4 * (36 + 12));
    default: return 0;
  }
}

}  // namespace distband

#include "core/seeds/mesh_seeds.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <stdexcept>
#include <cmath>
#include <memory>
#include <type_traits>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_group.h>

#include "core/first_touch.h"
#include "core/geometry.h"
#include "core/interruptible.h"

namespace distband {

std::string_view meshSiteModeName(MeshSiteMode mode) {
  return mode == MeshSiteMode::kPaper ? "paper" : "exact-feature";
}
bool parseMeshSiteMode(std::string_view name, MeshSiteMode* mode) {
  if (name == "exact-feature") return *mode = MeshSiteMode::kExactFeature, true;
  if (name == "paper") return *mode = MeshSiteMode::kPaper, true;
  return false;
}

namespace {

Vec3d normalized(const Vec3d& v) {
  const double l = v.length();
  return l > 0 ? v * (1.0 / l) : Vec3d{};
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
static_assert(sizeof(Candidate) == kMeshScanPairBytes);

// The voxels [*l, *h] along one axis whose coordinates lie in [mn, mx] units (voxel coordinate times `s` on an
// anisotropic grid, `scaled`), clipped to [clip_lo, clip_hi]; *l > *h when none. The bounds are clamped to just
// outside the clip range before they become integers (ceilInt and floorInt truncate), which changes none inside it.
inline void axisVoxels(double mn, double mx, double s, bool scaled, int clip_lo, int clip_hi, int32_t* l, int32_t* h) {
  const double lo = double(clip_lo) - 1, hi = double(clip_hi) + 1;
  *l = std::max(clip_lo, ceilInt(std::clamp(scaled ? mn / s : mn, lo, hi)));
  *h = std::min(clip_hi, floorInt(std::clamp(scaled ? mx / s : mx, lo, hi)));
}

// The voxels within `radius` units of triangle `tri` (unit space) by its bounding box, clipped to the grid; false
// when none (lo > hi).
bool scanBox(const Grid& grid, const std::array<Vec3d, 3>& tri, double radius, Coord* lo, Coord* hi) {
  const bool scaled = !grid.cubic();
  const Coord dims = grid.dims();
  const Vec3d scale = grid.axisScale();
  auto range = [&](double a, double b, double c, double s, int n, int32_t* l, int32_t* h) {
    axisVoxels(std::min({a, b, c}) - radius, std::max({a, b, c}) + radius, s, scaled, 0, n - 1, l, h);
  };
  range(tri[0].x, tri[1].x, tri[2].x, scale.x, dims.x, &lo->x, &hi->x);
  range(tri[0].y, tri[1].y, tri[2].y, scale.y, dims.y, &lo->y, &hi->y);
  range(tri[0].z, tri[1].z, tri[2].z, scale.z, dims.z, &lo->z, &hi->z);
  return lo->x <= hi->x && lo->y <= hi->y && lo->z <= hi->z;
}
// The bricks a scan box overlaps.
uint64_t scanBoxBricks(const Coord& lo, const Coord& hi) {
  return uint64_t((hi.x >> 3) - (lo.x >> 3) + 1) * ((hi.y >> 3) - (lo.y >> 3) + 1) * ((hi.z >> 3) - (lo.z >> 3) + 1);
}
// The scan's band radius in units: on an anisotropic grid a voxel step along an axis is up to maxAxisScale() units,
// and the band must hold voxels on both sides of the surface along every axis.
double scanRadius(const Grid& grid, const MeshSeedOptions& options) {
  return std::min(options.band_radius_voxels * grid.maxAxisScale(), options.limit_voxels);
}

}  // namespace

uint64_t meshScanPairs(const Grid& grid, const TriangleMesh& mesh, const MeshSeedOptions& options) {
  const double radius = scanRadius(grid, options);
  uint64_t pairs = 0;
  for (const auto& t : mesh.triangles) {
    if (t[0] >= mesh.vertices.size() || t[1] >= mesh.vertices.size() || t[2] >= mesh.vertices.size()) continue;
    const std::array<Vec3d, 3> tri{grid.unitsOf(mesh.vertices[t[0]]), grid.unitsOf(mesh.vertices[t[1]]),
                                   grid.unitsOf(mesh.vertices[t[2]])};
    Coord lo, hi;
    if (scanBox(grid, tri, radius, &lo, &hi)) pairs += scanBoxBricks(lo, hi);
  }
  return pairs;
}

namespace {

// The triangles of `mesh` that can matter in `grid`, as a sub-mesh in `sub` with `chosen[i]` the mesh's index of its
// triangle i (increasing, so ties between triangles resolve as on the whole mesh); `chosen` stays empty when all of
// them can. With a finite limit and pseudonormal or no signs, a triangle matters only if its bounding box grown by
// the limit (plus a voxel, for rounding) reaches the grid's box: a delivered voxel's closest triangle is within the
// limit, and so is every face around the closest feature whose pseudonormal signs it (each contains that feature's
// closest point), so values, closest triangles and signs are those of the whole mesh. Winding and parity signs read
// the whole surface, and without a limit every triangle may be a voxel's closest: then the whole mesh is used.
// Costs one pass over the triangles reading their corners, and memory for the chosen ones only: a tile of a
// multi-million-triangle mesh no longer copies, normalises and signs every triangle.
Status chooseTriangles(const Grid& grid, const TriangleMesh& mesh, const MeshSeedOptions& options, TriangleMesh* sub,
                       std::vector<uint32_t>* chosen) {
  if (!std::isfinite(options.limit_voxels) ||
      (options.sign != SignMethod::kPseudonormal && options.sign != SignMethod::kUnsigned))
    return Status::Ok();
  const size_t nt = mesh.triangles.size();
  // The grid's box grown by the reach, in world space (no division per corner; the voxel of margin is far above
  // rounding).
  const double reach = (options.limit_voxels * grid.maxAxisScale() + grid.maxAxisScale()) * grid.voxelSize();
  const Coord dims = grid.dims();
  const Vec3d lo = grid.worldOf({0, 0, 0}) - Vec3d{reach, reach, reach};
  const Vec3d hi = grid.worldOf({dims.x - 1, dims.y - 1, dims.z - 1}) + Vec3d{reach, reach, reach};
  std::vector<uint8_t> reaches(nt);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, nt, 4096), [&](const tbb::blocked_range<size_t>& r) {
    if (tbb::is_current_task_group_canceling()) return;
    for (size_t t = r.begin(); t != r.end(); ++t) {
      const auto& c = mesh.triangles[t];
      const Vec3d& a = mesh.vertices[c[0]];
      const Vec3d& b = mesh.vertices[c[1]];
      const Vec3d& d = mesh.vertices[c[2]];
      reaches[t] = std::max({a.x, b.x, d.x}) >= lo.x && std::min({a.x, b.x, d.x}) <= hi.x &&
                   std::max({a.y, b.y, d.y}) >= lo.y && std::min({a.y, b.y, d.y}) <= hi.y &&
                   std::max({a.z, b.z, d.z}) >= lo.z && std::min({a.z, b.z, d.z}) <= hi.z;
    }
  });
  if (isInterrupted(options.interrupter)) return interruptedStatus(options.interrupter);
  const size_t count = size_t(std::count(reaches.begin(), reaches.end(), uint8_t(1)));
  if (count == nt || count == 0) return Status::Ok();  // none: the scan finds an empty band, as it always has
  chosen->reserve(count);
  for (size_t t = 0; t < nt; ++t)
    if (reaches[t]) chosen->push_back(uint32_t(t));
  // The sub-mesh's vertices: the chosen triangles' corners, sorted (their order in the mesh).
  std::vector<uint32_t> used;
  used.reserve(3 * count);
  for (uint32_t t : *chosen) used.insert(used.end(), mesh.triangles[t].begin(), mesh.triangles[t].end());
  std::sort(used.begin(), used.end());
  used.erase(std::unique(used.begin(), used.end()), used.end());
  sub->vertices.resize(used.size());
  for (size_t v = 0; v < used.size(); ++v) sub->vertices[v] = mesh.vertices[used[v]];
  sub->triangles.resize(count);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i)
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = mesh.triangles[(*chosen)[i]][k];
        sub->triangles[i][k] = uint32_t(std::lower_bound(used.begin(), used.end(), v) - used.begin());
      }
  });
  return Status::Ok();
}

// makeMeshSeeds' work, run under runInterruptible (every TBB task it starts stops when the interrupter trips); its
// serial loops poll too. TBB only cancels tasks not yet started, and a parallel_for hands a thread ranges of up to
// 1/(4 x threads) of the loop (hundreds of ms at 1024^3), so loop bodies check is_current_task_group_canceling().
Status buildMeshSeeds(const Grid& grid, const TriangleMesh& whole_mesh, const MeshSeedOptions& options, Seeds* out,
                      MeshSeedStats* stats) {
  const auto start = std::chrono::steady_clock::now();
  const Interrupter* interrupter = options.interrupter;
  if (Status s = grid.validate(); !s.ok()) return s.withPrefix("grid");
  if (whole_mesh.triangles.empty()) return Status::InvalidArgument("the mesh has no triangles");
  if (!(options.band_radius_voxels > 0 && options.band_radius_voxels <= 8))
    return Status::InvalidArgument(fmt::format("band radius must be in (0, 8] voxels (got {})", options.band_radius_voxels));
  if (!(options.limit_voxels > 0)) return Status::InvalidArgument(fmt::format("limit must be > 0 (got {})", options.limit_voxels));
  if (options.sign == SignMethod::kAuto) throw std::invalid_argument("makeMeshSeeds: the sign method auto must be resolved first (resolveSignMethod)");
  for (const auto& t : whole_mesh.triangles)
    for (uint32_t i : t)
      if (i >= whole_mesh.vertices.size())
        return Status::InvalidArgument("a triangle refers to a vertex that does not exist");
  if (whole_mesh.triangles.size() >= kNoSite)
    return Status::ResourceExhausted(fmt::format("the mesh has {} triangles, more than the engine's {} sites",
                                                 whole_mesh.triangles.size(), kNoSite - 1));
  // Only the triangles that can reach the grid (a tile's window of a big mesh: a small share of it); `chosen` maps
  // the sub-mesh's triangles back to the mesh's (empty: every triangle reaches it, the mesh is used as it is).
  TriangleMesh sub;
  std::vector<uint32_t> chosen;
  if (Status s = chooseTriangles(grid, whole_mesh, options, &sub, &chosen); !s.ok()) return s;
  const TriangleMesh& mesh = chosen.empty() ? whole_mesh : sub;  // until its triangles become the sites' below
  const size_t nt = mesh.triangles.size();

  // The triangle sites: unit-space vertices (core/grid.h; in parallel: serial, this loop was ~20 ms of a 52 k-triangle
  // mesh's seeds) and the triangles' vertex ids, shared with the sign's tables.
  auto verts = std::make_shared<std::vector<Vec3d>>(mesh.vertices.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, verts->size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t v = r.begin(); v != r.end(); ++v) (*verts)[v] = grid.unitsOf(mesh.vertices[v]);
  });
  auto corners = chosen.empty() ? std::make_shared<std::vector<TriangleSites::Corners>>(mesh.triangles)
                                : std::make_shared<std::vector<TriangleSites::Corners>>(std::move(sub.triangles));
  std::vector<Vec3d>().swap(sub.vertices);
  const TriangleSites tris(verts, corners);
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);
  // The sign's tables read only the triangles. The winding number's and parity's are built beside the scan below,
  // whose parallel loops fill the threads the build leaves idle (the hierarchy's top levels, the part and boundary
  // searches are serial: on 2 threads a 49 k-triangle open mesh's 256^3 run 0.42 -> 0.39 s). The pseudonormal's stay
  // after it: their loops are parallel, and beside the scan's candidates they would raise a big closed mesh's peak
  // (3.3 M triangles at 512^3: 444 -> 565 MB). Every return waits for the build (it reads this frame's tables); a
  // stopped one (the interrupter, or a cancelled task group) leaves `built` empty.
  std::unique_ptr<MeshSign> built;
  Status sign_status;
  tbb::task_group sign_build;
  struct JoinOnReturn {
    tbb::task_group& group;
    ~JoinOnReturn() {
      try {
        group.wait();
      } catch (...) {  // an early return already has its answer; the build's error is the later one
      }
    }
  } join_on_return{sign_build};
  const auto buildSign = [&] { sign_status = MeshSign::build(verts, corners, options.sign, interrupter, &built); };
  const bool sign_beside_scan = options.sign == SignMethod::kWinding || options.sign == SignMethod::kParity;
  if (sign_beside_scan) sign_build.run(buildSign);
  const double radius = scanRadius(grid, options);
  const double r2 = radius * radius;
  const Coord dims = grid.dims();
  const Vec3d scale = grid.axisScale();
  const bool scaled = !grid.cubic();

  // Voxel box of each triangle's radius-neighbourhood, clipped to the grid (lo > hi: nothing to scan).
  auto voxelBox = [&](size_t t, Coord* lo, Coord* hi) { return scanBox(grid, tris[t], radius, lo, hi); };
  // 1. (brick, triangle) candidates: every brick a triangle's neighbourhood overlaps (meshScanPairs of the mesh).
  std::vector<uint64_t> offsets(nt + 1, 0);
  tbb::parallel_for(size_t(0), nt, [&](size_t t) {
    Coord lo, hi;
    if (tbb::is_current_task_group_canceling() || !voxelBox(t, &lo, &hi)) return;
    offsets[t + 1] = scanBoxBricks(lo, hi);
  });
  for (size_t t = 0; t < nt; ++t) offsets[t + 1] += offsets[t];
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);
  // Every entry is written below: unset storage, mapped on its own when large (given back when freed, not left in
  // the heap beside the engine's bricks).
  std::vector<Candidate, MappedAllocator<Candidate>> cand(offsets[nt]);
  tbb::parallel_for(size_t(0), nt, [&](size_t t) {
    Coord lo, hi;
    if (tbb::is_current_task_group_canceling() || !voxelBox(t, &lo, &hi)) return;
    uint64_t o = offsets[t];
    for (int z = lo.z >> 3; z <= hi.z >> 3; ++z)
      for (int y = lo.y >> 3; y <= hi.y >> 3; ++y)
        for (int x = lo.x >> 3; x <= hi.x >> 3; ++x)
          cand[o++] = {grid.brickIndex({x, y, z}), uint32_t(t)};
  });
  std::vector<uint64_t>().swap(offsets);
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
  // Each brick's band voxels, in its scanning thread's arena (a vector a brick was ~40 % of the run's page faults).
  struct BrickBand {
    const BandVoxel* voxels = nullptr;
    uint32_t count = 0;
  };
  std::vector<BrickBand> per_brick(nbricks);
  tbb::enumerable_thread_specific<ChunkArena<BandVoxel>> arenas;
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
      const std::array<Vec3d, 3> tri = tris[t];
      const TriangleDistance dist(tri[0], tri[1], tri[2]);
      const Vec3d n = normalized((tri[1] - tri[0]).cross(tri[2] - tri[0]));
      const double plane0 = n.dot(tri[0]);
      const double bx0 = std::min({tri[0].x, tri[1].x, tri[2].x}), bx1 = std::max({tri[0].x, tri[1].x, tri[2].x});
      const double by0 = std::min({tri[0].y, tri[1].y, tri[2].y}), by1 = std::max({tri[0].y, tri[1].y, tri[2].y});
      const double bz0 = std::min({tri[0].z, tri[1].z, tri[2].z}), bz1 = std::max({tri[0].z, tri[1].z, tri[2].z});
      // scanBox's voxels, clipped to the brick, from this bounding box.
      Coord lo, hi;
      axisVoxels(bx0 - radius, bx1 + radius, scale.x, kScaled, borg.x, std::min(dims.x - 1, borg.x + 7), &lo.x, &hi.x);
      axisVoxels(by0 - radius, by1 + radius, scale.y, kScaled, borg.y, std::min(dims.y - 1, borg.y + 7), &lo.y, &hi.y);
      axisVoxels(bz0 - radius, bz1 + radius, scale.z, kScaled, borg.z, std::min(dims.z - 1, borg.z + 7), &lo.z, &hi.z);
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
            // The plane and the bounding box are no farther than the triangle: a voxel already closer than either
            // to another triangle skips the exact distance (most do: the triangles near a voxel overlap). The box's
            // margin is far above rounding, so a tie or a closer triangle is never skipped. One test for both.
            const double ez = std::max(0.0, std::max(bz0 - uz, uz - bz1));
            if (std::max(plane * plane, exy2 + ez * ez - kBoxPruneMargin) > best[o]) continue;
            const double d2 = dist.dist2({ux, uy, uz});
            if (d2 < best[o] || (d2 == best[o] && t < best_t[o])) best[o] = d2, best_t[o] = t;
          }
        }
      }
    }
    const auto n = uint32_t(std::count_if(best_t.begin(), best_t.end(), [](uint32_t t) { return t != kNoSite; }));
    BandVoxel* v = arenas.local().take(n);
    per_brick[b] = {v, n};
    for (int o = 0; o < kBrickVoxels; ++o)
      if (best_t[o] != kNoSite) new (v++) BandVoxel{borg + brickLocal(o), best_t[o]};
  };
  tbb::parallel_for(size_t(0), nbricks, [&](size_t b) {
    if (tbb::is_current_task_group_canceling()) return;
    scaled ? scanBrick(b, std::true_type{}) : scanBrick(b, std::false_type{});
  });
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);
  decltype(cand)().swap(cand);
  std::vector<size_t> band_at(nbricks + 1, 0);
  for (size_t b = 0; b < nbricks; ++b) band_at[b + 1] = band_at[b] + per_brick[b].count;

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
    std::copy_n(per_brick[b].voxels, per_brick[b].count, seeds.band.begin() + band_at[b]);
  });
  std::vector<BrickBand>().swap(per_brick);
  arenas.clear();
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);

  // Paper mode with pseudonormal signs: each point site remembers its triangle (the test reads it).
  auto site_triangle = std::make_shared<std::vector<uint32_t>>();
  if (options.mode == MeshSiteMode::kPaper) {
    // 3p. Paper mode: each band voxel's closest point becomes a site of its own.
    seeds.kind = SiteKind::kPoint;
    seeds.points.resize(seeds.band.size());
    // The triangle of each point site: the pseudonormal test reads it, and the winding sign's certificate (a brick's
    // voxels on one far-from-boundary patch) does.
    if (options.sign == SignMethod::kPseudonormal || options.sign == SignMethod::kWinding)
      site_triangle->resize(seeds.band.size());
    seeds.site_feature.resize(seeds.band.size());  // closest features: the triangle of each point site
    tbb::parallel_for(size_t(0), seeds.band.size(), [&](size_t i) {
      if (tbb::is_current_task_group_canceling()) return;
      BandVoxel& bv = seeds.band[i];
      const std::array<Vec3d, 3> tri = tris[bv.site];
      const Vec3d p{bv.voxel.x * scale.x, bv.voxel.y * scale.y, bv.voxel.z * scale.z};  // units
      seeds.points[i] = closestPointOnTriangle(p, tri[0], tri[1], tri[2]);
      if (!site_triangle->empty()) (*site_triangle)[i] = bv.site;
      seeds.site_feature[i] = chosen.empty() ? bv.site : chosen[bv.site];
      bv.site = static_cast<uint32_t>(i);
    });
  } else {
    seeds.kind = SiteKind::kTriangle;
    seeds.site_feature = std::move(chosen);  // closest features name the mesh's triangles (empty: the same ids)
  }
  if (isInterrupted(interrupter)) return interruptedStatus(interrupter);
  if (options.sign != SignMethod::kUnsigned) {
    if (sign_beside_scan)
      sign_build.wait();
    else
      buildSign();
    if (isInterrupted(interrupter)) return interruptedStatus(interrupter);
    if (!sign_status.ok()) return sign_status;
    if (!built) return Status::Internal("the mesh's sign tables were not built");
    std::shared_ptr<const MeshSign> sign = std::move(built);
    const double voxel_size = grid.voxelSize();
    if (site_triangle->empty()) site_triangle.reset();
    // Per-test voxel counts, shared by the threads that sign bricks (a few relaxed adds a brick).
    auto tally = std::make_shared<std::array<std::atomic<int64_t>, 4>>();
    seeds.sign = [sign, site_triangle, voxel_size, scale, tally](Brick& brick, const uint32_t* sites) {
      const SignShares s =
          sign->signBrick(brick, sites, site_triangle ? site_triangle->data() : nullptr, voxel_size, scale);
      const int64_t counts[4] = {s.pseudonormal, s.winding_certified, s.winding_per_voxel, s.parity};
      for (int k = 0; k < 4; ++k)
        if (counts[k]) (*tally)[size_t(k)].fetch_add(counts[k], std::memory_order_relaxed);
    };
    seeds.sign_shares = [tally] {
      auto at = [&](int k) { return (*tally)[size_t(k)].load(std::memory_order_relaxed); };
      return SignShares{at(0), at(1), at(2), at(3)};
    };
  }
  if (seeds.kind == SiteKind::kTriangle) seeds.triangles = tris;

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

#include "server/request_validation.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include <fmt/format.h>

#include "core/field/band_extent.h"
#include "core/mesh/mesh_grid.h"
#include "core/seeds/mesh_seeds.h"
#include "server/asset_parsing.h"

namespace distband {
namespace {

Status invalid(std::string message) { return Status::InvalidArgument(std::move(message)); }

bool finite(const v1::Vec3& v) { return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z()); }
Vec3d toVec(const v1::Vec3& v) { return {v.x(), v.y(), v.z()}; }

constexpr int kMaxPoints = 1 << 20;
constexpr double kMaxSegments = 100000;

/// The seeds of a QueryRequest or a PointsHeader (the same oneof): `Seeds` is ResolvedQuery or ResolvedPoints.
template <typename Request, typename Seeds>
Status resolveSeeds(const Request& r, const ServerOptions& options, AssetCache& cache,
                    std::shared_ptr<const Asset> inline_mesh, Seeds* q) {
  switch (r.seeds_case()) {
    case Request::kAssetId: {
      if (r.asset_id().empty() || r.asset_id().size() > 128)
        return invalid(fmt::format("asset_id must be an id returned by an upload (got {} characters)",
                                   r.asset_id().size()));
      q->asset = cache.find(r.asset_id());
      if (!q->asset)
        return Status::NotFound(
            fmt::format("asset_id: no asset '{}' in the cache (never uploaded, or evicted: upload it again)",
                        r.asset_id()));
      q->seed_kind = q->asset->kind == Asset::Kind::kMesh ? SeedKind::kMesh
                                                           : SeedKind::kVolume;
      q->seeds_label = q->asset->id.substr(0, std::min<size_t>(q->asset->id.size(), 17)) +
                       (q->asset->name.empty() ? "" : "(" + q->asset->name + ")");
      return Status::Ok();
    }
    case Request::kMesh: {
      q->seed_kind = SeedKind::kMesh;
      q->seeds_label = fmt::format("inline-mesh({} bytes)", r.mesh().data().size());
      if (!inline_mesh) return Status::Internal("the inline mesh was not parsed before the query was resolved");
      q->asset = std::move(inline_mesh);
      return Status::Ok();
    }
    case Request::kPoints: {
      const auto& pts = r.points().points();
      if (pts.empty()) return invalid("points.points must hold at least one point");
      if (pts.size() > kMaxPoints)
        return invalid(fmt::format("points.points must hold at most {} points (got {})", kMaxPoints, pts.size()));
      q->points.reserve(pts.size());
      for (int i = 0; i < pts.size(); ++i) {
        if (!finite(pts[i]))
          return invalid(fmt::format("points.points[{}] must have finite coordinates (got {}, {}, {})", i,
                                     pts[i].x(), pts[i].y(), pts[i].z()));
        q->points.push_back(toVec(pts[i]));
      }
      q->seed_kind = SeedKind::kPoints;
      q->seeds_label = fmt::format("points({})", pts.size());
      return Status::Ok();
    }
    case Request::kVolume: {
      q->seed_kind = SeedKind::kVolume;
      q->seeds_label = fmt::format("inline-volume({}x{}x{})", r.volume().dims().x(), r.volume().dims().y(),
                                   r.volume().dims().z());
      return parseVolumeAsset(r.volume().dims(), r.volume().element_type(), r.volume().mask(), "inline volume", "volume",
                              options.max_voxels_per_query, nullptr, &q->asset);
    }
    case Request::SEEDS_NOT_SET:
      break;
  }
  return invalid("seeds: exactly one of asset_id, mesh, points, volume must be set");
}

// The request's sign for its seeds (UNSPECIFIED and AUTO leave it to the planner: meshes auto, points and volumes
// unsigned); proto3 enums are open, so unknown numbers are refused rather than cast.
Status readSign(v1::SignMode sign, SeedKind seeds, FieldRequest* fr) {
  if (sign < v1::SIGN_MODE_UNSPECIFIED || sign > v1::SIGN_MODE_AUTO)
    return invalid(fmt::format("sign must be a SignMode value 0..6 (got {})", int(sign)));
  const bool default_sign = sign == v1::SIGN_MODE_UNSPECIFIED || sign == v1::SIGN_MODE_AUTO;
  switch (seeds) {
    case SeedKind::kPoints:
      if (!default_sign && sign != v1::SIGN_MODE_UNSIGNED)
        return invalid(
            fmt::format("sign: point seeds only support SIGN_MODE_UNSIGNED (got {})", v1::SignMode_Name(sign)));
      break;
    case SeedKind::kVolume:
      if (!default_sign && sign != v1::SIGN_MODE_UNSIGNED && sign != v1::SIGN_MODE_MASK_INSIDE)
        return invalid(fmt::format("sign: volume seeds support SIGN_MODE_UNSIGNED or SIGN_MODE_MASK_INSIDE (got {})",
                                   v1::SignMode_Name(sign)));
      fr->inside_negative = sign == v1::SIGN_MODE_MASK_INSIDE;
      break;
    case SeedKind::kMesh:
      switch (sign) {
        case v1::SIGN_MODE_UNSIGNED:
          fr->mesh_sign = SignMethod::kUnsigned;
          break;
        case v1::SIGN_MODE_PSEUDONORMAL:
          fr->mesh_sign = SignMethod::kPseudonormal;
          break;
        case v1::SIGN_MODE_WINDING:
          fr->mesh_sign = SignMethod::kWinding;
          break;
        case v1::SIGN_MODE_PARITY:
          fr->mesh_sign = SignMethod::kParity;
          break;
        case v1::SIGN_MODE_MASK_INSIDE:
          return invalid(
              "sign: SIGN_MODE_MASK_INSIDE is for volume seeds; meshes take AUTO, UNSIGNED, PSEUDONORMAL, "
              "WINDING or PARITY");
        default:
          break;
      }
      break;
  }
  return Status::Ok();
}

// A volume covers the whole grid, or a tile's window only (then its dims are the window's and the grid needs dims).
// `field` carries the limit (for the default padding).
Status resolveGrid(const v1::GridSpec& g, const ResolvedQuery& q, bool tile, const FieldRequest& field, Grid* grid,
                   GridPadding* padding) {
  if (g.voxel_size() != 0 && !(std::isfinite(g.voxel_size()) && g.voxel_size() > 0))
    return invalid(fmt::format("grid.voxel_size must be finite and > 0 when set (got {})", g.voxel_size()));
  if (g.resolution() != 0 && (g.resolution() < 2 || g.resolution() > uint32_t(kMaxGridDim)))
    return invalid(fmt::format("grid.resolution must be in [2, {}] when set (got {})", kMaxGridDim, g.resolution()));
  if (g.has_padding() && g.padding() > uint32_t(kMaxPaddingVoxels))
    return invalid(fmt::format("grid.padding must be in [0, {}] voxels (got {})", kMaxPaddingVoxels, g.padding()));
  if (g.has_origin() && !finite(g.origin()))
    return invalid("grid.origin must have finite coordinates");
  if (g.has_spacing()) {
    const v1::Vec3& sp = g.spacing();
    if (!(std::isfinite(sp.x()) && sp.x() > 0 && std::isfinite(sp.y()) && sp.y() > 0 && std::isfinite(sp.z()) &&
          sp.z() > 0))
      return invalid(
          fmt::format("grid.spacing must be finite and > 0 on every axis (got {}, {}, {})", sp.x(), sp.y(), sp.z()));
    if (g.voxel_size() != 0)
      return invalid("grid.spacing and grid.voxel_size are mutually exclusive (voxel_size v means spacing v,v,v)");
  }
  const bool volume = q.seed_kind == SeedKind::kVolume;
  if (volume && tile && !g.has_dims())
    return invalid("grid.dims must be set for a tile of volume seeds (the volume covers only the tile's window)");

  if (g.has_dims() || volume) {  // way a
    if (g.has_box()) return invalid("grid.box and grid.dims are mutually exclusive");
    if (g.resolution() != 0) return invalid("grid.resolution cannot be combined with grid.dims (give voxel_size)");
    if (g.has_padding()) return invalid("grid.padding cannot be combined with grid.dims");
    Coord dims;
    if (g.has_dims()) {
      if (Status s = checkDims(g.dims(), "grid.dims"); !s.ok()) return s;
      dims = {int32_t(g.dims().x()), int32_t(g.dims().y()), int32_t(g.dims().z())};
      if (volume && !tile && !(dims == q.asset->volume.dims()))
        return invalid(fmt::format("grid.dims ({}x{}x{}) must equal the volume's dims ({}x{}x{}) or be omitted",
                                   dims.x, dims.y, dims.z, q.asset->volume.dims().x, q.asset->volume.dims().y, q.asset->volume.dims().z));
    } else {
      dims = q.asset->volume.dims();
    }
    const Vec3d origin = g.has_origin() ? toVec(g.origin()) : Vec3d{};
    if (g.has_spacing()) {
      *grid = Grid(origin, toVec(g.spacing()), dims);
      return grid->validate().withPrefix("grid.spacing");
    }
    double h = g.voxel_size();
    if (h == 0) {
      if (!volume) return invalid("grid.voxel_size or grid.spacing must be set (> 0) when grid.dims is given");
      h = kDefaultVoxelSize;
    }
    *grid = Grid(origin, h, dims);
    return grid->validate().withPrefix("grid");
  }

  if (g.has_origin()) return invalid("grid.origin is only used with grid.dims (the box or the seeds give it)");
  if (g.has_spacing())
    return invalid(
        "grid.spacing is only used with grid.dims or volume seeds (around a box or the seeds give "
        "voxel_size or resolution)");
  if ((g.voxel_size() > 0) == (g.resolution() > 0))
    return invalid("grid: give exactly one of voxel_size (> 0) and resolution (> 0)");
  MeshGridOptions mo;
  mo.voxel_size = g.voxel_size();
  mo.resolution = int(g.resolution());
  if (g.has_padding()) mo.padding_voxels = int(g.padding());
  TriangleMesh point_bounds;  // gridForMesh reads only the vertices' bounds
  const TriangleMesh* bounds = &point_bounds;
  if (g.has_box()) {  // way b
    if (!finite(g.box().min()) || !finite(g.box().max())) return invalid("grid.box corners must be finite");
    mo.box_min = toVec(g.box().min());
    mo.box_max = toVec(g.box().max());
    const Vec3d lo = *mo.box_min, hi = *mo.box_max;
    if (!(hi.x >= lo.x && hi.y >= lo.y && hi.z >= lo.z)) return invalid("grid.box.max must be >= grid.box.min");
  } else {  // way c
    if (q.seed_kind == SeedKind::kMesh) {
      bounds = q.asset->mesh.get();
    } else {
      point_bounds.vertices = q.points;
    }
  }
  return gridForMesh(*bounds, mo, field.limit(), grid, padding).withPrefix("grid");
}

Status resolveBox(const v1::VoxelBox& b, const Grid& grid, const char* field, VoxelBox* out) {
  const Coord dims = grid.dims();
  const uint32_t min[3] = {b.min_x(), b.min_y(), b.min_z()}, size[3] = {b.size_x(), b.size_y(), b.size_z()};
  const int extent[3] = {dims.x, dims.y, dims.z};
  for (int a = 0; a < 3; ++a) {
    const char axis = "xyz"[a];
    if (min[a] % kBrickSize != 0)
      return invalid(fmt::format("{}.min_{} must be a multiple of 8 (got {})", field, axis, min[a]));
    if (size[a] == 0 || uint64_t(min[a]) + size[a] > uint64_t(extent[a]))
      return invalid(fmt::format("{}: min_{} + size_{} must lie in [1, grid dims.{} = {}] (got {} + {})", field, axis,
                                 axis, axis, extent[a], min[a], size[a]));
    if ((min[a] + size[a]) % kBrickSize != 0 && min[a] + size[a] != uint32_t(extent[a]))
      return invalid(fmt::format("{}: min_{} + size_{} must be a multiple of 8 or the grid's extent {} (got {})", field,
                                 axis, axis, extent[a], min[a] + size[a]));
  }
  *out = {{int(min[0]), int(min[1]), int(min[2])}, {int(size[0]), int(size[1]), int(size[2])}};
  return Status::Ok();
}

Status resolveTile(const v1::Tile& t, const Grid& grid, ResolvedQuery* q) {
  TilePlan tile;
  if (Status s = resolveBox(t.window(), grid, "tile.window", &tile.window); !s.ok()) return s;
  if (Status s = resolveBox(t.deliver(), grid, "tile.deliver", &tile.deliver); !s.ok()) return s;
  if (!tile.window.contains(tile.deliver)) return invalid("tile.deliver must lie inside tile.window");
  if (q->seed_kind == SeedKind::kVolume && !(q->asset->volume.dims() == tile.window.dims))
    return invalid(fmt::format("volume: a tile's volume covers its window: dims must be {}x{}x{} (got {}x{}x{})",
                               tile.window.dims.x, tile.window.dims.y, tile.window.dims.z, q->asset->volume.dims().x,
                               q->asset->volume.dims().y, q->asset->volume.dims().z));
  q->tile = tile;
  return Status::Ok();
}

// The engine's site ids have 27 bits: reject what would overflow them before any seed is built.
constexpr uint64_t kMaxEngineSites = (uint64_t(1) << 27) - 2;

double meshAreaVoxels(const TriangleMesh& mesh, double voxel_size) {
  double area2 = 0;  // twice the area, world units
  for (const auto& t : mesh.triangles) {
    const Vec3d &a = mesh.vertices[t[0]], &b = mesh.vertices[t[1]], &c = mesh.vertices[t[2]];
    area2 += (b - a).cross(c - a).length();
  }
  return area2 / 2 / (voxel_size * voxel_size);
}

Status checkSites(const ResolvedQuery& q) {
  uint64_t sites = 0;
  std::string what;
  switch (q.seed_kind) {
    case SeedKind::kPoints: return Status::Ok();  // bounded by kMaxPoints
    case SeedKind::kVolume:
      sites = q.asset->footprint->boundary_voxels;
      what = "volume: the mask has {} boundary voxels (each one a site)";
      break;
    case SeedKind::kMesh:
      if (q.plan.mode == PropagationMode::kPaper) {
        sites = meshBandVoxelEstimate(meshAreaVoxels(*q.asset->mesh, q.grid.voxelSize()), 0, UINT64_MAX);
        what = "mesh: paper mode makes a site of every initial band voxel, about {} here";
      } else {
        sites = q.asset->mesh->triangles.size();
        what = "mesh: {} triangles";
      }
      break;
  }
  if (sites <= kMaxEngineSites) return Status::Ok();
  return Status::ResourceExhausted(fmt::format(fmt::runtime(what), sites) +
                                   fmt::format(", more than the engine's {} sites; use a coarser grid{}", kMaxEngineSites,
                                               q.seed_kind == SeedKind::kMesh ? " or exact mode" : ""));
}

// The touched-voxel bound of the seeds within the limit, and the peak bytes the query is admitted with.
void estimateMemory(ResolvedQuery* q) {
  const Grid grid = q->engineGrid();
  const double limit_voxels = q->plan.limitVoxels(grid);
  BandExtent extent(grid, limit_voxels);
  SeedCounts counts;
  switch (q->seed_kind) {
    case SeedKind::kPoints:
      counts.points = q->points.size();
      for (const Vec3d& p : q->points) extent.addPoint(grid.indexOf(p));
      break;
    case SeedKind::kVolume:
      counts.volume_seed_voxels = q->asset->footprint->seed_voxels;
      counts.volume_boundary_voxels = q->asset->footprint->boundary_voxels;
      addVolume(*q->asset->footprint, q->plan.volumeMeasure(), &extent);
      break;
    case SeedKind::kMesh: {
      const TriangleMesh& mesh = *q->asset->mesh;
      counts.mesh_vertices = mesh.vertices.size();
      counts.mesh_triangles = mesh.triangles.size();
      counts.mesh_area_voxels = meshAreaVoxels(mesh, grid.voxelSize());
      counts.mesh_scan_pairs = meshScanPairs(grid, mesh, q->plan.meshSeedOptions(grid));
      if (!extent.wholeGrid())
        for (const auto& t : mesh.triangles) {
          const Vec3d a = grid.indexOf(mesh.vertices[t[0]]), b = grid.indexOf(mesh.vertices[t[1]]),
                      c = grid.indexOf(mesh.vertices[t[2]]);
          extent.addBox({std::min({a.x, b.x, c.x}), std::min({a.y, b.y, c.y}), std::min({a.z, b.z, c.z})},
                        {std::max({a.x, b.x, c.x}), std::max({a.y, b.y, c.y}), std::max({a.z, b.z, c.z})});
        }
      break;
    }
  }
  q->touched_voxels_bound = extent.voxelBound();
  // What the query will likely deliver, for the client's progress: the band's volume (a shell around a mesh or a
  // volume's boundary, balls around points), at most the touched bound. Not an admission figure.
  double expected = double(q->touched_voxels_bound);
  if (std::isfinite(limit_voxels)) {
    const double l = limit_voxels;
    switch (q->seed_kind) {
      case SeedKind::kPoints: expected = double(q->points.size()) * 4.18879 * l * l * l; break;
      case SeedKind::kVolume:
        expected = double(counts.volume_seed_voxels) +
                   double(counts.volume_boundary_voxels) * l * (q->plan.inside_negative ? 2 : 1);
        break;
      case SeedKind::kMesh: expected = counts.mesh_area_voxels * 2 * l; break;
    }
  }
  q->expected_voxels = uint64_t(std::min(expected, double(q->touched_voxels_bound)));
  q->memory = estimateFieldMemory(q->plan, grid, counts, q->touched_voxels_bound, kQueryChunkBricks);
}

}  // namespace

Status resolveQuery(const v1::QueryRequest& r, const ServerOptions& options, AssetCache& cache,
                    std::shared_ptr<const Asset> inline_mesh, ResolvedQuery* out) {
  ResolvedQuery q;
  if (Status s = resolveSeeds(r, options, cache, std::move(inline_mesh), &q); !s.ok()) return s;

  // Enumerations (proto3 enums are open: unknown numbers must be rejected, not cast). What is left unset is decided
  // by core's planner (planField) below, as for every other caller.
  FieldRequest fr;
  fr.seeds = q.seed_kind;
  switch (r.stencil()) {
    case v1::STENCIL_UNSPECIFIED: break;
    case v1::STENCIL_CUBIC26: fr.stencil = StencilKind::kCubic26; break;
    case v1::STENCIL_CUBIC6: fr.stencil = StencilKind::kCubic6; break;
    case v1::STENCIL_CUBIC18: fr.stencil = StencilKind::kCubic18; break;
    case v1::STENCIL_FCC12: fr.stencil = StencilKind::kFcc12; break;
    default: return invalid(fmt::format("stencil must be a Stencil value 0..4 (got {})", int(r.stencil())));
  }
  switch (r.algorithm()) {
    case v1::ALGORITHM_UNSPECIFIED: break;
    case v1::ALGORITHM_BAND: fr.algorithm = FieldAlgorithm::kBand; break;
    case v1::ALGORITHM_SEPARABLE: fr.algorithm = FieldAlgorithm::kSeparable; break;
    default: return invalid(fmt::format("algorithm must be an Algorithm value 0..2 (got {})", int(r.algorithm())));
  }
  switch (r.mode()) {
    case v1::PROPAGATION_MODE_UNSPECIFIED: break;
    case v1::PROPAGATION_MODE_EXACT: fr.mode = PropagationMode::kExact; break;
    case v1::PROPAGATION_MODE_PAPER: fr.mode = PropagationMode::kPaper; break;
    default: return invalid(fmt::format("mode must be a PropagationMode value 0..2 (got {})", int(r.mode())));
  }
  switch (r.encoding()) {
    case v1::BRICK_ENCODING_UNSPECIFIED:
    case v1::BRICK_ENCODING_FLOAT32: q.encoding = v1::BRICK_ENCODING_FLOAT32; break;
    case v1::BRICK_ENCODING_FLOAT16: q.encoding = v1::BRICK_ENCODING_FLOAT16; break;
    default: return invalid(fmt::format("encoding must be a BrickEncoding value 0..2 (got {})", int(r.encoding())));
  }
  if (Status s = readSign(r.sign(), q.seed_kind, &fr); !s.ok()) return s;

  if (!(r.segment_length() >= 0) || !std::isfinite(r.segment_length()))
    return invalid(fmt::format("segment_length must be finite and >= 0 (got {})", r.segment_length()));
  if (std::isnan(r.limit()) || r.limit() < 0)
    return invalid(fmt::format("limit must be > 0, +infinity, or 0 for no limit (got {})", r.limit()));
  if (r.limit_voxels() != 0 && !(std::isfinite(r.limit_voxels()) && r.limit_voxels() > 0))
    return invalid(fmt::format("limit_voxels must be finite and > 0 when set (got {})", r.limit_voxels()));
  if (r.limit_voxels() != 0 && r.limit() != 0)
    return invalid("limit and limit_voxels are mutually exclusive: give the limit in world units or in voxels");
  fr.limit_world = r.limit() == 0 ? std::numeric_limits<double>::infinity() : r.limit();
  fr.limit_voxels = r.limit_voxels();
  fr.segment_length_world = r.segment_length();
  fr.closest_features = r.closest_feature();
  // Label volumes: checked here by name, then against the seeds and each other by core's planner.
  if (q.seed_kind != SeedKind::kVolume && (r.labels() || r.black_border() || r.nearest_label()))
    return invalid(fmt::format("{}: applies to volume seeds only", r.labels()         ? "labels"
                                                                   : r.black_border() ? "black_border"
                                                                                      : "nearest_label"));
  if (r.black_border() && !r.labels()) return invalid("black_border: applies with labels (the multi-label EDT)");
  if (r.labels() && (r.nearest_label() || r.closest_feature()))
    return invalid(fmt::format("labels: excludes {} (the multi-label EDT has no closest features)",
                               r.nearest_label() ? "nearest_label" : "closest_feature"));
  if (r.nearest_label() && r.closest_feature())
    return invalid("nearest_label: excludes closest_feature (one closest feature per voxel)");
  fr.labels = r.labels();
  fr.black_border = r.black_border();
  fr.nearest_label = r.nearest_label();

  q.batch_bytes = r.max_batch_bytes() == 0
                      ? options.batch_bytes
                      : std::clamp<uint32_t>(r.max_batch_bytes(), 64u << 10, options.max_message_bytes);

  if (q.seed_kind == SeedKind::kPoints) fr.point_layout = pointLayout(q.points);  // the planner's cost model
  if (!r.has_grid()) return invalid("grid must be set (voxel_size or resolution, or dims)");
  if (Status s = resolveGrid(r.grid(), q, r.has_tile(), fr, &q.grid, &q.padding); !s.ok()) return s;
  if (Status s = planField(fr, q.grid, q.seed_kind == SeedKind::kMesh ? &q.asset->mesh_report : nullptr, &q.plan);
      !s.ok())
    return s;
  if (q.seed_kind == SeedKind::kVolume && q.plan.inside_negative &&
      q.asset->footprint->seed_voxels == uint64_t(q.asset->volume.dims().x) * q.asset->volume.dims().y * q.asset->volume.dims().z)
    return invalid("sign: SIGN_MODE_MASK_INSIDE needs a zero voxel in the mask (every voxel is inside, so the "
                   "distance to the outside is undefined)");
  if (r.has_tile())
    if (Status s = resolveTile(r.tile(), q.grid, &q); !s.ok()) return s;
  // The budget bounds the work: the voxels computed (a tile's window, not the whole grid it belongs to).
  const Grid computed = q.engineGrid();
  const uint64_t voxels = uint64_t(computed.voxelCount());
  if (voxels > options.max_voxels_per_query)
    return Status::ResourceExhausted(
        fmt::format("{}: {}x{}x{} = {} voxels exceeds the server's voxel budget of {} per query",
                    q.tile ? "tile.window" : "grid", computed.dims().x, computed.dims().y, computed.dims().z, voxels,
                    options.max_voxels_per_query));
  if (Status s = validateRunOptions(q.engineGrid(), q.plan.runOptions()); !s.ok()) return s;
  // Without a limit the engine's own segment-count rule does not apply: bound it by the grid's diagonal, the
  // largest distance a voxel can have, so a tiny segment length cannot request millions of empty segments.
  if (q.plan.segment_length_world > 0) {
    const Coord d = q.grid.dims();
    const double diagonal = q.grid.diagonalWorld(d);
    const double span = std::min(q.plan.limit_world, diagonal);
    if (span / q.plan.segment_length_world > kMaxSegments)
      return invalid(fmt::format("segment_length {} would cut min(limit, grid diagonal) = {} into more than {} "
                                 "segments; use a longer segment_length",
                                 q.plan.segment_length_world, span, kMaxSegments));
  }
  if (Status s = checkSites(q); !s.ok()) return s;
  estimateMemory(&q);
  *out = std::move(q);
  return Status::Ok();
}

namespace {

template <typename Request>
Status checkInlineMeshOf(const Request& r, const ServerOptions& options) {
  if (r.seeds_case() != Request::kMesh) return Status::Ok();
  if (meshFormatExtension(r.mesh().format()).empty())
    return invalid(fmt::format("mesh.format must be one of MESH_FORMAT_OBJ, _OFF, _PLY, _STL (got {})",
                               int(r.mesh().format())));
  if (r.mesh().data().empty()) return invalid("mesh.data: the mesh data is empty");
  if (r.mesh().data().size() > options.max_upload_bytes)
    return Status::ResourceExhausted(fmt::format("mesh.data: {} bytes exceed the server's upload limit of {}",
                                                 r.mesh().data().size(), options.max_upload_bytes));
  return Status::Ok();
}

}  // namespace

Status checkInlineMesh(const v1::QueryRequest& r, const ServerOptions& options) {
  return checkInlineMeshOf(r, options);
}
Status checkInlineMesh(const v1::PointsHeader& h, const ServerOptions& options) {
  return checkInlineMeshOf(h, options);
}

Status resolvePointsHeader(const v1::PointsHeader& h, const ServerOptions& options, AssetCache& cache,
                           std::shared_ptr<const Asset> inline_mesh, ResolvedPoints* out) {
  ResolvedPoints p;
  if (Status s = resolveSeeds(h, options, cache, std::move(inline_mesh), &p); !s.ok()) return s;
  p.cached = h.seeds_case() == v1::PointsHeader::kAssetId;
  const bool volume = p.seed_kind == SeedKind::kVolume;
  if (!volume && (h.has_volume_origin() || h.volume_voxel_size() != 0))
    return invalid("volume_origin and volume_voxel_size place a volume's voxels; they apply to volume seeds only");
  if (volume) {
    if (h.has_volume_origin() && !finite(h.volume_origin()))
      return invalid("volume_origin must have finite coordinates");
    if (h.volume_voxel_size() != 0 && !(std::isfinite(h.volume_voxel_size()) && h.volume_voxel_size() > 0))
      return invalid(fmt::format("volume_voxel_size must be finite and > 0 when set (got {})", h.volume_voxel_size()));
    p.lattice = Grid(h.has_volume_origin() ? toVec(h.volume_origin()) : Vec3d{},
                     h.volume_voxel_size() != 0 ? h.volume_voxel_size() : kDefaultVoxelSize, p.asset->volume.dims());
  }
  FieldRequest fr;
  fr.seeds = p.seed_kind;
  if (Status s = readSign(h.sign(), p.seed_kind, &fr); !s.ok()) return s;
  if (std::isnan(h.limit()) || h.limit() < 0)
    return invalid(fmt::format("limit must be > 0, +infinity, or 0 for no limit (got {})", h.limit()));
  fr.limit_world = h.limit() == 0 ? std::numeric_limits<double>::infinity() : h.limit();
  if (Status s = planPoints(fr, p.seed_kind == SeedKind::kMesh ? &p.asset->mesh_report : nullptr,
                            volume ? &p.lattice : nullptr, &p.plan);
      !s.ok())
    return s;
  switch (h.coordinates()) {
    case v1::VALUE_TYPE_UNSPECIFIED:
    case v1::VALUE_TYPE_FLOAT32:
      p.packing.doubles = false;
      break;
    case v1::VALUE_TYPE_FLOAT64:
      p.packing.doubles = true;
      break;
    default:
      return invalid(fmt::format("coordinates must be a ValueType value 0..2 (got {})", int(h.coordinates())));
  }
  p.packing.wide_ids = volume;
  p.outputs = {h.closest_points(), h.closest_feature(), h.gradient()};
  switch (p.seed_kind) {
    case SeedKind::kPoints:
      p.counts.points = p.points.size();
      break;
    case SeedKind::kMesh:
      p.counts.mesh_vertices = p.asset->mesh->vertices.size();
      p.counts.mesh_triangles = p.asset->mesh->triangles.size();
      break;
    case SeedKind::kVolume: {
      const VolumeFootprint& f = *p.asset->footprint;
      const Coord d = p.asset->volume.dims();
      const uint64_t faces = 2 * (uint64_t(d.x) * d.y + uint64_t(d.y) * d.z + uint64_t(d.x) * d.z);
      p.counts.volume_boundary_voxels = f.boundary_voxels + std::min(f.seed_voxels, faces);
      if (p.plan.inside_negative && f.seed_voxels == uint64_t(d.x) * d.y * d.z)
        return invalid(
            "sign: SIGN_MODE_MASK_INSIDE needs a zero voxel in the mask (every voxel is inside, so the "
            "distance to the outside is undefined)");
      break;
    }
  }
  p.header = h;
  *out = std::move(p);
  return Status::Ok();
}

void fillPointsHeader(const ResolvedPoints& p, const std::string& query_id, v1::PointsReplyHeader* h) {
  FieldPlan sign;  // signOf reads the seeds and the sign of a plan
  sign.seeds = p.seed_kind;
  sign.mesh_sign = p.plan.mesh_sign;
  sign.inside_negative = p.plan.inside_negative;
  sign.closest_features = p.outputs.features;
  h->set_query_id(query_id);
  h->set_sign(signOf(sign));
  h->set_sign_reason(p.plan.sign_reason);
  h->set_signed_(p.plan.signedField());
  h->set_limit(p.plan.limit_world);
  h->set_closest_feature(closestOf(sign));
  h->set_values(p.packing.doubles ? v1::VALUE_TYPE_FLOAT64 : v1::VALUE_TYPE_FLOAT32);
  h->set_max_chunk_points(uint32_t(kMaxChunkPoints));
}

Status decodePointsChunk(const v1::PointsChunk& chunk, v1::ValueType type, uint64_t chunk_index, uint64_t first_point,
                         std::vector<Vec3d>* out) {
  const bool doubles = type == v1::VALUE_TYPE_FLOAT64;
  const size_t item = doubles ? 8 : 4, record = 3 * item;
  const std::string& xyz = chunk.xyz();
  if (xyz.size() % record != 0)
    return invalid(fmt::format("chunk {}: xyz holds {} bytes, not a whole number of points of {} bytes (x, y, z in {})",
                               chunk_index, xyz.size(), record, doubles ? "float64" : "float32"));
  const size_t n = xyz.size() / record;
  if (n == 0) return invalid(fmt::format("chunk {}: xyz holds no point", chunk_index));
  if (n > kMaxChunkPoints)
    return invalid(fmt::format("chunk {}: {} points, more than the {} a chunk may hold (max_chunk_points)", chunk_index,
                               n, kMaxChunkPoints));
  out->resize(n);
  const char* p = xyz.data();
  for (size_t i = 0; i < n; ++i, p += record) {
    double v[3];
    for (int k = 0; k < 3; ++k) {
      if (doubles) {
        std::memcpy(&v[k], p + 8 * k, 8);
      } else {
        float f;
        std::memcpy(&f, p + 4 * k, 4);
        v[k] = f;
      }
    }
    if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]))
      return invalid(
          fmt::format("chunk {}: point {} (point {} of the stream) has a coordinate that is not finite "
                      "({}, {}, {})",
                      chunk_index, i, first_point + i, v[0], v[1], v[2]));
    (*out)[i] = {v[0], v[1], v[2]};
  }
  return Status::Ok();
}

v1::SignMode signOf(const FieldPlan& plan) {
  if (plan.seeds == SeedKind::kVolume) return plan.inside_negative ? v1::SIGN_MODE_MASK_INSIDE : v1::SIGN_MODE_UNSIGNED;
  if (plan.seeds == SeedKind::kPoints) return v1::SIGN_MODE_UNSIGNED;
  switch (plan.mesh_sign) {
    case SignMethod::kPseudonormal: return v1::SIGN_MODE_PSEUDONORMAL;
    case SignMethod::kWinding: return v1::SIGN_MODE_WINDING;
    case SignMethod::kParity: return v1::SIGN_MODE_PARITY;
    default: return v1::SIGN_MODE_UNSIGNED;
  }
}

v1::Stencil stencilOf(const FieldPlan& plan) {
  switch (plan.stencil) {
    case StencilKind::kCubic6: return v1::STENCIL_CUBIC6;
    case StencilKind::kCubic18: return v1::STENCIL_CUBIC18;
    case StencilKind::kFcc12: return v1::STENCIL_FCC12;
    default: return v1::STENCIL_CUBIC26;
  }
}

v1::ClosestFeature closestOf(const FieldPlan& plan) {
  if (plan.nearest_label) return v1::CLOSEST_FEATURE_LABEL;
  if (!plan.closest_features) return v1::CLOSEST_FEATURE_NONE;
  switch (plan.seeds) {
    case SeedKind::kMesh: return v1::CLOSEST_FEATURE_TRIANGLE;
    case SeedKind::kVolume: return v1::CLOSEST_FEATURE_VOXEL;
    default: return v1::CLOSEST_FEATURE_POINT;
  }
}

v1::PropagationMode modeOf(const FieldPlan& plan) {
  return plan.mode == PropagationMode::kPaper ? v1::PROPAGATION_MODE_PAPER : v1::PROPAGATION_MODE_EXACT;
}

v1::Dims dimsOf(const Coord& c) {
  v1::Dims d;
  d.set_x(uint32_t(c.x));
  d.set_y(uint32_t(c.y));
  d.set_z(uint32_t(c.z));
  return d;
}

void fillQueryHeader(const ResolvedQuery& q, const std::string& query_id, v1::QueryHeader* h) {
  h->mutable_origin()->set_x(q.grid.origin().x);
  h->mutable_origin()->set_y(q.grid.origin().y);
  h->mutable_origin()->set_z(q.grid.origin().z);
  h->set_voxel_size(q.grid.voxelSize());
  *h->mutable_dims() = dimsOf(q.grid.dims());
  h->set_limit(q.plan.limit_world);
  h->set_signed_(q.plan.signedField());
  h->set_encoding(q.encoding);
  h->set_stencil(stencilOf(q.plan));
  h->set_mode(modeOf(q.plan));
  h->set_sign(signOf(q.plan));
  h->set_segment_length(q.plan.segment_length_world);
  h->set_query_id(query_id);
  h->set_sign_reason(q.plan.sign_reason);
  h->set_padding(uint32_t(q.padding.voxels));
  h->set_closest_feature(closestOf(q.plan));
  h->set_expected_voxels(q.expected_voxels);
  h->set_algorithm(std::string(algorithmName(q.plan.algorithm)));
  h->set_band_clipped(q.padding.band_clipped);
  h->mutable_spacing()->set_x(q.grid.spacing().x);
  h->mutable_spacing()->set_y(q.grid.spacing().y);
  h->mutable_spacing()->set_z(q.grid.spacing().z);
  h->set_labels(q.plan.labels);
  h->set_black_border(q.plan.labels && q.plan.black_border);
  if (q.seed_kind == SeedKind::kVolume && q.asset) h->set_label_type(v1VoxelType(q.asset->volume.type()));
}

}  // namespace distband

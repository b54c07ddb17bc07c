// Request validation: a distband.v1.QueryRequest checked field by field and resolved into what the engine needs.
// Contract: resolveQuery() never trusts the request and checks every rule the .proto states before any compute:
// kInvalidArgument (a field breaks a rule), kNotFound (asset_id not in the cache) or kResourceExhausted (voxel
// budget, engine site limit), with a message that names the field and the rule, e.g. "grid.resolution must be in
// [2, 16384] (got 1)". It is cheap: O(seeds + grid/512) for the touched-voxel bound, no allocation of the field.
// On OK, `out` holds the grid, the engine options (without an interrupter), the seeds' source and the memory
// estimate the query is admitted with; building the algorithm's inputs is compute work done later, by the query job
// (buildFieldInputs, core/field/compute_field.h).
// Thread-safe (the cache is).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/band/band_engine.h"
#include "core/field/field_plan.h"
#include "core/field/field_memory.h"
#include "core/status.h"
#include "core/grid.h"
#include "core/mesh/mesh_grid.h"
#include "core/field/tiling.h"
#include "core/points/point_plan.h"
#include "core/points/point_results.h"
#include "distband/v1/distband.pb.h"
#include "server/asset_cache.h"
#include "server/server_options.h"

namespace distband {

struct ResolvedQuery {
  using SeedKind = distband::SeedKind;
  SeedKind seed_kind = SeedKind::kPoints;
  std::vector<Vec3d> points;            ///< kPoints, world coordinates
  std::shared_ptr<const Asset> asset;   ///< kVolume / kMesh (cached or inline)
  std::string seeds_label;              ///< for logs, e.g. "points(2)" or "mesh-1a2b…(bunny.obj)"

  Grid grid;                            ///< the whole grid (what the header describes)
  GridPadding padding;                  ///< how the grid was padded around the seeds' bounds (ways b and c)
  /// Set for a tile (QueryRequest.tile): the engine computes grid.window(tile->window) and only the voxels of
  /// tile->deliver are streamed.
  std::optional<TilePlan> tile;
  FieldPlan plan;                       ///< every choice made by core's planner (mode, stencil, sign, limit, ...)
  v1::BrickEncoding encoding = v1::BRICK_ENCODING_FLOAT32;  ///< never UNSPECIFIED
  uint32_t batch_bytes = 1u << 20;
  uint64_t touched_voxels_bound = 0;    ///< BandExtent::voxelBound() of the seeds and limit
  uint64_t expected_voxels = 0;         ///< an estimate of the voxels delivered (QueryHeader.expected_voxels)
  FieldMemoryEstimate memory;           ///< peak bytes of seeds + engine + one output chunk

  /// The grid the engine computes on: the tile's window, or the whole grid.
  Grid engineGrid() const { return tile ? grid.window(tile->window) : grid; }
};

/// `inline_mesh`: the parsed QueryRequest.mesh when the request carries one (parsing is compute work that the
/// caller admits and runs first, see checkInlineMesh), else null.
Status resolveQuery(const v1::QueryRequest& request, const ServerOptions& options, AssetCache& cache,
                    std::shared_ptr<const Asset> inline_mesh, ResolvedQuery* out);

/// The cheap checks of QueryRequest.mesh (format, size) before it is parsed; OK for requests without one.
Status checkInlineMesh(const v1::QueryRequest& request, const ServerOptions& options);
/// The same for PointsHeader.mesh.
Status checkInlineMesh(const v1::PointsHeader& header, const ServerOptions& options);

/// A QueryPoints stream's header, checked and resolved: the seeds, core's point plan (sign, limit), the outputs and how
/// they are packed. Like resolveQuery it checks every rule before any work: kInvalidArgument naming the field,
/// kNotFound for an unknown asset_id; cheap (the search is built later, under admission).
struct ResolvedPoints {
  SeedKind seed_kind = SeedKind::kPoints;
  std::vector<Vec3d> points;           ///< kPoints, world coordinates
  std::shared_ptr<const Asset> asset;  ///< kVolume / kMesh (cached or inline)
  bool cached = false;                 ///< the asset is the cache's (asset_id): its search is kept with it
  std::string seeds_label;             ///< for logs
  Grid lattice;                        ///< volumes: where their voxels lie
  PointPlan plan;
  PointOutputs outputs;
  PointPacking packing;
  PointSeedCounts counts;   ///< what sizes the search (admission)
  v1::PointsHeader header;  ///< as received (a coordinator forwards it)
};
Status resolvePointsHeader(const v1::PointsHeader& header, const ServerOptions& options, AssetCache& cache,
                           std::shared_ptr<const Asset> inline_mesh, ResolvedPoints* out);

/// The header message of a QueryPoints stream.
void fillPointsHeader(const ResolvedPoints& points, const std::string& query_id, v1::PointsReplyHeader* header);

/// Checks and decodes chunk number `chunk` (its points' coordinates of `type`): at least one and at most
/// kMaxChunkPoints points, a whole number of them, every coordinate finite. kInvalidArgument naming the chunk and the
/// point otherwise, e.g. "chunk 3: point 17 (point 196625 of the stream) has a coordinate that is not finite".
Status decodePointsChunk(const v1::PointsChunk& chunk, v1::ValueType type, uint64_t chunk_index, uint64_t first_point,
                         std::vector<Vec3d>* out);

/// Output bricks the engine hands to a query's encoder at once (BandOptions::max_chunk_bricks).
inline constexpr size_t kQueryChunkBricks = 1024;

/// A plan's choices as the protocol names them (the header, and a coordinator's requests to its replicas).
v1::SignMode signOf(const FieldPlan& plan);
v1::Stencil stencilOf(const FieldPlan& plan);
v1::PropagationMode modeOf(const FieldPlan& plan);
/// What BrickData.closest carries for this plan (NONE unless it asks for closest features).
v1::ClosestFeature closestOf(const FieldPlan& plan);
/// Voxel counts as the protocol sends them.
v1::Dims dimsOf(const Coord& dims);

/// The header message describing a resolved query (first message of the stream).
void fillQueryHeader(const ResolvedQuery& query, const std::string& query_id, v1::QueryHeader* header);

}  // namespace distband

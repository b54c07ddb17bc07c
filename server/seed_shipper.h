// SeedShipper: how a tiled query's seeds reach its replicas (server/tiled_query.h) — what each tile's request
// carries for its seeds, and the uploads to every replica of the seeds that travel as assets.
// Contract:
//   * Points travel inline, in each tile's request only those within the limit of the tile, in their original order
//     (ties between equidistant sites then resolve as on one server). A replica's closest-point ids index the tile's
//     list; toQueryPointIds() turns them back into indices of the query's points.
//   * A mesh goes once to every replica as a canonical binary PLY (core/mesh/ply_writer.h, content-addressed;
//     remembered per replica), and each tile names it by id.
//   * A volume travels as the window's crop: inline when at most half of --max-message-bytes, else uploaded to every
//     replica and named by id (without a limit every window is the whole grid: one upload).
//   * addSeeds() says whether the tile has anything to compute: not when no point, no seed voxel (or, signed, no free
//     voxel) or, with a limit, no triangle whose box grown by the limit reaches it. Such a tile is not sent at all.
//   * ship() uploads to every replica not known to hold it; OK when at least one replica has it (a replica that
//     missed it answers NOT_FOUND to a tile: forgetUploads(), then ship() again). Its calls go through the
//     dispatcher (credentials, deadline, cancelled with the query's calls).
//   * The uploads themselves are ReplicaUploads', which a point query (server/points_fan_out.h) uses alike.
// Thread-safety: the first ship() runs alone, before any tile is sent (it settles the asset ids); after it, every
// method may be called from any thread.
#pragma once

#include <functional>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/field/tiling.h"
#include "core/status.h"
#include "distband/v1/distband.grpc.pb.h"
#include "server/asset_cache.h"
#include "server/replica_pool.h"
#include "server/request_validation.h"
#include "server/server_options.h"

namespace distband {

/// A mesh as a coordinator hands it on: a canonical binary PLY (core/mesh/ply_writer.h: the same vertices bit for bit,
/// the same triangles in the same order, whatever format the client uploaded) and the asset id a replica gives it.
struct ShippedMesh {
  std::string bytes;
  std::string id;
  std::string name;  ///< the upload's label, for the replicas' logs
};
ShippedMesh canonicalMesh(const Asset& mesh);

/// The assets one coordinated query uploads to its replicas, and which replica it knows to hold which (for the query's
/// life: a replica that already has the bytes answers already_cached). Each upload goes to every replica of
/// `replicas` not known to hold the asset; OK when at least one of them holds it (the others' failures are logged).
/// Calls go through `calls` (prepared, cancelled with the query's calls, none started once it stops). Thread-safe.
class ReplicaUploads {
 public:
  explicit ReplicaUploads(const ReplicaPool& pool) : pool_(pool) {}

  Status uploadMesh(const ShippedMesh& mesh, const std::vector<ReplicaPool::Replica>& replicas, ReplicaCalls& calls);
  /// `bytes`: the volume's voxels, x fastest, each of `type`; `id` is volumeAssetId() of them.
  Status uploadVolume(const v1::Dims& dims, VoxelType type, std::string_view bytes, const std::string& id,
                      const std::vector<ReplicaPool::Replica>& replicas, ReplicaCalls& calls);
  /// Whether `replica` (an address) is known to hold asset `id`.
  bool holds(const std::string& replica, const std::string& id) const;
  /// A replica lacked an upload: no replica is known to hold anything any more.
  void forget();

 private:
  using Upload = std::function<Status(v1::DistanceField::Stub&, grpc::ClientContext*)>;
  Status upload(const std::string& id, const std::vector<ReplicaPool::Replica>& replicas, ReplicaCalls& calls,
                const Upload& upload);

  const ReplicaPool& pool_;
  mutable std::mutex mu_;
  std::set<std::pair<std::string, std::string>> uploaded_;  ///< (replica, asset id) known to be there
};

class SeedShipper {
 public:
  /// `query` must outlive the shipper.
  SeedShipper(const ResolvedQuery& query, const ServerOptions& options, ReplicaPool& pool,
              const std::vector<TilePlan>& tiles);

  /// Puts the seeds into `tile`'s request; false when the tile has nothing to compute.
  bool addSeeds(size_t tile, v1::QueryRequest* request) const;
  /// Uploads the seeds that travel as assets to every replica not known to hold them.
  Status ship(ReplicaCalls& calls);
  /// A replica lacked an upload: no replica is known to hold anything any more.
  void forgetUploads();
  /// `tile`'s closest-point ids (BrickData.closest) as indices of the query's points; an id outside the tile's list
  /// (a faulty replica) becomes -1, which no client takes for a point. Nothing to do unless the query asks for
  /// closest points.
  void toQueryPointIds(size_t tile, v1::BrickBatch* batch) const;

 private:
  /// Per tile: whether a triangle comes within the limit (always true without a limit or for other seeds).
  std::vector<bool> meshReach() const;

  const ResolvedQuery& query_;
  const ServerOptions& options_;
  ReplicaPool& pool_;
  const std::vector<TilePlan> tiles_;
  /// Point seeds, per tile: the indices (in the query) of the points sent with it, in order.
  std::vector<std::vector<uint32_t>> point_index_;
  const std::vector<bool> mesh_reach_;

  ShippedMesh mesh_;  ///< fixed by the first ship()
  /// Windows whose volume crop is too large to send inline -> (window, uploaded asset id); fixed by the first ship().
  std::map<std::string, std::pair<VoxelBox, std::string>> volume_ids_;
  bool volumes_planned_ = false;
  ReplicaUploads uploads_;
};

}  // namespace distband

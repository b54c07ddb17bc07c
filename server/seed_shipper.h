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
// Thread-safety: the first ship() runs alone, before any tile is sent (it settles the asset ids); after it, every
// method may be called from any thread.
#pragma once

#include <functional>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "core/field/tiling.h"
#include "core/status.h"
#include "distband/v1/distband.grpc.pb.h"
#include "server/replica_pool.h"
#include "server/request_validation.h"
#include "server/server_options.h"
#include "server/tile_dispatcher.h"

namespace distband {

class SeedShipper {
 public:
  /// `query` must outlive the shipper.
  SeedShipper(const ResolvedQuery& query, const ServerOptions& options, ReplicaPool& pool,
              const std::vector<TilePlan>& tiles);

  /// Puts the seeds into `tile`'s request; false when the tile has nothing to compute.
  bool addSeeds(size_t tile, v1::QueryRequest* request) const;
  /// Uploads the seeds that travel as assets to every replica not known to hold them.
  Status ship(TileDispatcher& calls);
  /// A replica lacked an upload: no replica is known to hold anything any more.
  void forgetUploads();
  /// `tile`'s closest-point ids (BrickData.closest) as indices of the query's points; an id outside the tile's list
  /// (a faulty replica) becomes -1, which no client takes for a point. Nothing to do unless the query asks for
  /// closest points.
  void toQueryPointIds(size_t tile, v1::BrickBatch* batch) const;

 private:
  using Upload = std::function<Status(v1::DistanceField::Stub&, grpc::ClientContext*)>;
  Status uploadToReplicas(const std::string& id, TileDispatcher& calls, const Upload& upload);
  /// Per tile: whether a triangle comes within the limit (always true without a limit or for other seeds).
  std::vector<bool> meshReach() const;

  const ResolvedQuery& query_;
  const ServerOptions& options_;
  ReplicaPool& pool_;
  const std::vector<TilePlan> tiles_;
  /// Point seeds, per tile: the indices (in the query) of the points sent with it, in order.
  std::vector<std::vector<uint32_t>> point_index_;
  const std::vector<bool> mesh_reach_;

  std::string mesh_id_, mesh_bytes_;
  /// Windows whose volume crop is too large to send inline -> (window, uploaded asset id); fixed by the first ship().
  std::map<std::string, std::pair<VoxelBox, std::string>> volume_ids_;
  bool volumes_planned_ = false;

  std::mutex mu_;
  std::set<std::pair<std::string, std::string>> uploaded_;  ///< (replica, asset id) known to be there
};

}  // namespace distband

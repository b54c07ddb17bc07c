// TiledQuery: a Query spread over replicas by a coordinator (distband-server --peers).
// Contract (QueryStream, server/query_stream.h):
//   * The grid is cut into tiles of whole bricks (core/field/tiling.h, at most --tile-voxels each). Each tile is one Query
//     call (QueryRequest.tile) on the round_robin channel of the ReplicaPool, so balancing is per tile; at most
//     --tiles-in-flight calls per replica run at once (and at most 128 per query: one thread each). The tile's window is the tile grown by the limit plus two
//     bricks; without a limit, point seeds still use that margin (the engine is exact for sites outside its grid),
//     while meshes and volumes need the whole grid in every window (each tile then costs a whole computation).
//   * Seeds travel as follows: points inline, only those within the limit of the tile (order kept, so ties resolve
//     as on one server); a tile no seed comes within the limit of is not sent at all; meshes once per replica as a canonical binary PLY (content-addressed, remembered); volumes
//     as the window's crop, inline when small, else uploaded to every replica.
//   * The merged stream keeps the protocol's order: segment s's bricks are forwarded as tiles deliver them, and its
//     SegmentDone is sent once every tile has finished segment s; what tiles deliver of later segments meanwhile is
//     held (at most --tile-buffer-bytes, else RESOURCE_EXHAUSTED). Tiles are brick-aligned, so no brick straddles
//     two tiles and every voxel is delivered once.
//   * Faults: a tile that fails (replica gone, busy, its --tile-timeout passed, asset missing) is retried, after a
//     short back-off, up to --tile-retries times, on a replica it has not failed on (a stalled replica still looks
//     connected to round_robin, so retries pick their replica themselves). What a
//     failed attempt had forwarded is not sent twice (bricks already forwarded are skipped in the replay), and
//     replicas compute deterministically, so the field is the same. Beyond the retries: UNAVAILABLE naming the tile
//     and the last error.
//   * The call's Interrupter (client cancel, deadline, shutdown) cancels every tile call within a poll (5 ms).
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <unordered_set>
#include <utility>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "core/interrupter.h"
#include "core/field/tiling.h"
#include "server/query_stream.h"
#include "server/replica_pool.h"
#include "server/request_validation.h"
#include "server/server_options.h"

namespace distband {

class TiledQuery final : public QueryStream {
 public:
  struct Config {
    const ServerOptions& options;
    ReplicaPool& pool;
    Interrupter& interrupter;
    std::chrono::system_clock::time_point client_deadline;
  };

  TiledQuery(ResolvedQuery query, Config config);
  ~TiledQuery() override;

  void start() override;
  void stop() override;
  void join() override;
  BoundedQueue<Message>& queue() override { return queue_; }
  const Status& status() const override { return status_; }
  bool interrupted() const override { return interrupted_; }
  Clock::time_point stopped() const override { return stopped_; }
  void summarize(v1::QuerySummary* summary) const override;
  std::string logStats() const override;
  int tiles() const override;
  int retries() const override;

  /// Bytes a coordinator's query is admitted with: its stream buffer and the later segments it may hold.
  static uint64_t reservedBytes(const ServerOptions& options);
  /// The tile plan a query gets (the halo rule above).
  static std::vector<TilePlan> plan(const ResolvedQuery& query, uint64_t tile_voxels);

 private:
  struct Tile {
    TilePlan plan;
    /// Point seeds: the indices (in the request) of the points sent with this tile, in order; a replica's
    /// closest-feature ids index this list.
    std::vector<uint32_t> point_index;
    int attempts = 0;
    uint32_t completed = 0;   ///< segments finished (their SegmentDone seen)
    bool finished = false;    ///< its last segment finished
    uint32_t last = 0;        ///< index of its last segment, when finished
    std::map<uint32_t, std::vector<Message>> ahead;  ///< batches of segments after the merged one
    uint64_t ahead_bytes = 0;
    std::unordered_set<uint64_t> forwarded;  ///< brick origins of the merged segment already sent
    std::vector<v1::SegmentDone> segments;   ///< its SegmentDone per finished segment
    v1::QuerySummary summary;
    std::set<std::string> failed_on;         ///< replicas (peer addresses) an attempt failed on
  };
  struct Attempt {
    Status status;
    bool asset_missing = false;
    std::string peer;  ///< the replica it ran on (as gRPC names it, e.g. "ipv4:10.0.0.1:50051")
  };

  /// Keeps a call in calls_ (so stop() and fail() cancel it) for its scope.
  class RegisteredCall {
   public:
    RegisteredCall(TiledQuery& query, grpc::ClientContext* context);
    ~RegisteredCall();
    RegisteredCall(const RegisteredCall&) = delete;
    RegisteredCall& operator=(const RegisteredCall&) = delete;

   private:
    TiledQuery& query_;
    grpc::ClientContext* context_;
  };

  void run();
  void worker();
  /// Under mu_: cancels every registered call and wakes the waiters.
  void cancelCalls();
  Attempt runTile(size_t index);
  /// Under mu_: one message of tile `index`'s stream.
  void onMessage(size_t index, v1::QueryReply& message);
  void forward(Tile& tile, Message message);
  void advance();
  void fail(Status status);
  bool stopping() const;
  Status prepareSeeds();
  Status uploadToReplicas(const std::string& id, const std::function<Status(v1::DistanceField::Stub&,
                                                                             grpc::ClientContext*)>& upload);
  v1::QueryRequest tileRequest(const Tile& tile) const;
  std::vector<bool> meshReach() const;
  std::chrono::system_clock::time_point tileDeadline() const;

  const ResolvedQuery query_;
  const Config config_;
  BoundedQueue<Message> queue_;
  std::thread thread_;

  // Seeds as the replicas get them.
  std::string mesh_id_, mesh_bytes_;
  /// Windows whose volume crop is too large to send inline -> (window, uploaded asset id); fixed once planned.
  std::map<std::string, std::pair<VoxelBox, std::string>> volume_ids_;
  bool volumes_planned_ = false;

  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::vector<Tile> tiles_;
  std::vector<bool> mesh_reach_;  ///< per tile: whether a triangle comes within the limit (always true otherwise)
  std::vector<size_t> pending_;  ///< tiles waiting for a worker
  size_t running_ = 0, done_tiles_ = 0;
  uint32_t merged_ = 0;  ///< the segment being merged
  bool all_sent_ = false;
  uint64_t ahead_bytes_ = 0, value_bytes_ = 0;
  int retries_ = 0;
  std::set<grpc::ClientContext*> calls_;
  std::set<std::pair<std::string, std::string>> uploaded_;  ///< (replica, asset id) known to be there
  std::vector<v1::SegmentTiming> timings_;
  std::atomic<bool> stop_{false};
  Status status_;
  bool interrupted_ = false;
  size_t replicas_ = 0;
  Clock::time_point started_{}, stopped_{};
};

}  // namespace distband

// TiledQuery: a Query spread over replicas by a coordinator (distband-server --peers).
// Contract (QueryStream, server/query_stream.h):
//   * The grid is cut into tiles of whole bricks (core/field/tiling.h, at most --tile-voxels each). Each tile is one Query
//     call (QueryRequest.tile) on the round_robin channel of the ReplicaPool, so balancing is per tile; at most
//     --tiles-in-flight calls per replica run at once (and at most 128 per query: one thread each). The tile's window
//     is the tile grown by the limit plus two bricks; without a limit, point seeds on the separable point EDT (exact
//     for points outside its grid) still use that margin, while the band and meshes and volumes need the whole grid
//     in every window (each tile then costs a whole computation). Every tile runs the whole grid's algorithm.
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
//   * Metrics: the bytes the merger holds are reported as they change (distband_coordinator_merge_buffer_bytes) and
//     given back when the query ends; tile calls are reported by the dispatcher.
// Parts: SeedShipper (server/seed_shipper.h) ships the seeds and fills each tile's seeds, TileDispatcher
// (server/tile_dispatcher.h) runs the tile calls with their retries, SegmentMerger (server/segment_merger.h) merges
// their streams; TiledQuery plans the tiles, builds their requests and wires the three on its own thread.
// summarize(), logStats(), tiles() and retries() are for after join() (QueryStream's contract).
#pragma once

#include <chrono>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "core/field/tiling.h"
#include "core/interrupter.h"
#include "server/query_stream.h"
#include "server/replica_pool.h"
#include "server/request_validation.h"
#include "server/seed_shipper.h"
#include "server/segment_merger.h"
#include "server/server_options.h"
#include "server/tile_dispatcher.h"

namespace distband {

class TiledQuery final : public QueryStream, private TileDispatcher::Tiles {
 public:
  using Config = TileDispatcher::Config;

  TiledQuery(ResolvedQuery query, Config config);
  ~TiledQuery() override;

  void start() override;
  void stop() override;
  void join() override;
  BoundedQueue<Message>& queue() override { return queue_; }
  const Status& status() const override { return dispatcher_.status(); }
  bool interrupted() const override { return interrupted_; }
  Clock::time_point stopped() const override { return stopped_; }
  void summarize(v1::QuerySummary* summary) const override;
  void logStats(LogLine& line) const override;
  int tiles() const override { return int(plans_.size()); }
  int retries() const override { return dispatcher_.retries(); }

  /// Bytes a coordinator's query is admitted with: its stream buffer and the later segments it may hold.
  static uint64_t reservedBytes(const ServerOptions& options);
  /// The tile plan a query gets (the halo rule above).
  static std::vector<TilePlan> plan(const ResolvedQuery& query, uint64_t tile_voxels);

 private:
  void run();

  // TileDispatcher::Tiles: the dispatcher's questions, answered by the shipper and the merger.
  std::optional<v1::QueryRequest> request(size_t tile) override;
  Status onReply(size_t tile, v1::QueryReply& reply) override;
  bool sawLastSegment(size_t tile) const override { return merger_->sawLastSegment(tile); }
  bool everythingMerged(size_t tile) const override { return merger_->everythingMerged(tile); }
  void onTileDone(size_t tile) override {
    merger_->onTileFinished(tile);
    reportHeldBytes();
  }
  void onAttemptFailed(size_t tile) override {
    merger_->onAttemptFailed(tile);
    reportHeldBytes();
  }
  bool complete() const override { return merger_->complete(); }
  Status reship() override;
  /// onReply's merge of one message.
  Status merge(size_t tile, v1::QueryReply& reply);
  /// Reports the change of the merger's held bytes since the last report (under the dispatcher's lock).
  void reportHeldBytes();

  const ResolvedQuery query_;
  const Config config_;
  BoundedQueue<Message> queue_;
  TileDispatcher dispatcher_;
  std::thread thread_;
  // Set by run() before any tile is dispatched.
  std::vector<TilePlan> plans_;
  std::optional<SeedShipper> shipper_;
  std::optional<SegmentMerger> merger_;
  size_t replicas_ = 0;
  uint64_t reported_held_bytes_ = 0;
  bool interrupted_ = false;
  Clock::time_point started_{}, stopped_{};
};

}  // namespace distband

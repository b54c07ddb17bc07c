// TileDispatcher: runs a tiled query's tiles as Query calls on its replicas (server/tiled_query.h): a pool of worker
// threads, one call per tile attempt, retries, each call's deadline and the cancellation of every call in flight.
// It holds the dispatch state — tiles waiting for a worker, tiles running and done, each tile's attempts and the
// replicas it failed on, the calls in flight, the query's first error — and leaves what a tile carries and what its
// replies mean to the query it serves (Tiles).
// Contract:
//   * run() starts min(tiles, replicas x --tiles-in-flight, 128) workers (the synchronous client API: one thread
//     per call in flight) and returns once the merged stream is complete and every tile is done, or on the first
//     error, stop() or the query's Interrupter (polled every 5 ms); every call still in flight is then cancelled and
//     every worker joined.
//   * A call's deadline is the client's, or --tile-timeout from now when that is sooner. First attempts go where
//     round_robin sends them; a retry goes to a replica the tile has not failed on (a stalled replica still looks
//     connected to round_robin), after a back-off of 100 ms per attempt made (round_robin needs a moment to see that
//     a replica is gone).
//   * A failed attempt (UNAVAILABLE, RESOURCE_EXHAUSTED, DEADLINE_EXCEEDED, CANCELLED, NOT_FOUND, INTERNAL; NOT_FOUND
//     re-ships the seeds first) is retried up to --tile-retries times; beyond them, or on another code, the query
//     fails with UNAVAILABLE (INTERNAL for a code not worth retrying) naming the tile and the last error. A failed
//     attempt loses nothing when everything its tile had to deliver was already merged: the tile is then done.
//   * As the query's ReplicaCalls (server/replica_pool.h) it prepares any other call of the query (the seeds'
//     uploads) like a tile call (credentials, the tile deadline, the query's x-request-id) and cancels it with them.
//   * Every tile call is reported to Metrics by the replica it reached (dispatched; failed, and whether it is
//     retried); a retry's log line carries the query's request id.
// Thread-safe. The Tiles methods marked "locked" are called under the dispatcher's lock, one at a time, and only
// while the query has not failed; the others from workers, without it.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "core/field/tiling.h"
#include "core/interrupter.h"
#include "core/status.h"
#include "distband/v1/distband.pb.h"
#include "server/metrics.h"
#include "server/replica_pool.h"
#include "server/server_options.h"

namespace distband {

class TileDispatcher final : public ReplicaCalls {
 public:
  struct Config {
    const ServerOptions& options;
    ReplicaPool& pool;
    Interrupter& interrupter;
    std::chrono::system_clock::time_point client_deadline;
    Metrics& metrics;
    std::string request_id;  ///< sent to the replicas as x-request-id (server/request_id.h)
  };

  /// The query whose tiles are dispatched.
  class Tiles {
   public:
    virtual ~Tiles() = default;
    /// Unlocked: `tile`'s request, or none when it has nothing to compute (it is then done without a call).
    virtual std::optional<v1::QueryRequest> request(size_t tile) = 0;
    /// Locked: one message of `tile`'s stream; an error fails the query.
    virtual Status onReply(size_t tile, v1::QueryReply& reply) = 0;
    /// Locked: whether `tile`'s stream so far ended its band (a call that ends well without it failed).
    virtual bool sawLastSegment(size_t tile) const = 0;
    /// Locked: whether everything `tile` has to deliver is merged already.
    virtual bool everythingMerged(size_t tile) const = 0;
    /// Locked: `tile` is done (its call ended well, it had nothing to compute, or everything it had is merged).
    virtual void onTileDone(size_t tile) = 0;
    /// Locked: `tile`'s attempt failed; it runs again from its start (or the query fails).
    virtual void onAttemptFailed(size_t tile) = 0;
    /// Locked: the merged stream is complete.
    virtual bool complete() const = 0;
    /// Unlocked: a replica lacked an asset the query's seeds were uploaded as; upload them again.
    virtual Status reship() = 0;
  };

  TileDispatcher(Config config, Tiles& tiles);

  /// Dispatches `plans` (one per tile) over `replicas` replicas until the contract's end; see status().
  void run(const std::vector<TilePlan>& plans, size_t replicas);
  /// Fails the query (the first error is kept) and cancels its calls.
  void fail(Status status);
  /// Any thread: cancels every call and makes run() return.
  void stop();
  /// Why calls must not start now (the Interrupter's status, or CANCELLED after stop()); OK while they may.
  Status stopReason() const override;

  const std::string& requestId() const override { return config_.request_id; }

  /// After run(): OK, or the query's first error.
  const Status& status() const { return status_; }
  int retries() const;

 private:
  struct TileAttempts {
    int attempts = 0;
    std::set<std::string> failed_on;  ///< replicas (peer addresses) an attempt failed on
  };
  struct Attempt {
    Status status;
    bool asset_missing = false;
    bool called = false;  ///< a call was made (it reached a replica or tried to)
    std::string peer;  ///< the replica it ran on (as gRPC names it, e.g. "ipv4:10.0.0.1:50051")
  };

  /// ReplicaCalls: a call prepared like a tile's (the tile deadline) and registered in calls_.
  void enroll(grpc::ClientContext* context) override;
  void withdraw(grpc::ClientContext* context) override;
  void worker(const std::vector<TilePlan>& plans);
  Attempt runTile(size_t index);
  /// Under mu_.
  void failLocked(Status status);
  /// Under mu_: cancels every registered call and wakes the waiters.
  void cancelCalls();
  bool stopping() const;
  std::chrono::system_clock::time_point tileDeadline() const;

  const Config config_;
  Tiles& tiles_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::vector<TileAttempts> attempts_;
  std::vector<size_t> pending_;  ///< tiles waiting for a worker
  size_t running_ = 0, done_tiles_ = 0;
  int retries_ = 0;
  std::set<grpc::ClientContext*> calls_;
  std::atomic<bool> stop_{false};
  Status status_;
};

}  // namespace distband

// PointsFanOut: a coordinator's QueryPoints (distband-server --peers): the client's point chunks fan out to replicas
// and their results come back to the client in the client's chunk order.
// Contract (the caller, DistanceFieldService, has validated the header and admitted the call with reservedBytes()):
//   * open(): the seeds reach the replicas as a tiled query's do (server/seed_shipper.h): an asset_id names the
//     mesh's canonical PLY or the whole volume, uploaded to each replica not known to hold it; inline seeds travel in
//     the header exactly as the client sent them. Then one QueryPoints stream per replica, at most kMaxStreams (calls
//     take turns at which replica comes first), each sent the header (with the shipped asset id); the call's
//     x-request-id and the client's deadline go with every stream. A replica that answers no header within
//     --tile-timeout, or refuses it with UNAVAILABLE, RESOURCE_EXHAUSTED, NOT_FOUND, DEADLINE_EXCEEDED, CANCELLED or
//     INTERNAL (down, busy, its cache lost the upload), is left out of the call; another refusal fails the call
//     (INVALID_ARGUMENT passed through, anything else INTERNAL), naming the replica; so does a reply header that
//     describes the query otherwise than the coordinator's own (sign, signed, limit, closest feature, value type,
//     a smaller max_chunk_points): INTERNAL. No replica left: UNAVAILABLE.
//   * serve(): the client gets the coordinator's header, then each chunk is validated here as a replica would
//     (decodePointsChunk: INVALID_ARGUMENT naming the chunk and the point, in the client's numbering, after every
//     earlier chunk's results were forwarded) and sent on, chunk i to stream i mod streams. A replica answers its
//     chunks in order, so the results of the oldest outstanding chunk are the next reply of the stream it went to: a
//     merge thread forwards them as they arrive, `chunk` and `first_point` rewritten to the client's numbering.
//   * Flow control and memory: at most kWindow chunks are outstanding on a stream; the client's next chunk waits for a
//     slot, so the coordinator holds at most kWindow results per stream (what reservedBytes() counts) and one chunk,
//     and a client sending faster than the replicas compute, or reading slowly, is paused by gRPC's flow control. A
//     reader thread per stream drains its replies (it never blocks on anything but its stream), so no replica stalls
//     on a full coordinator and the call cannot deadlock.
//   * End: after the client half-closes, every stream is half-closed, the remaining results forwarded, and each
//     replica's summary read; summarize() then merges them (see PointsSummary in the .proto).
//   * Failure: the first error ends the call and cancels every replica stream and upload (ClientContext::TryCancel):
//     a replica's stream failing mid-call (UNAVAILABLE, or INVALID_ARGUMENT passed through, naming the replica), a
//     replica silent for --tile-timeout while it owes results (or its summary), a malformed reply, the client's
//     cancel or deadline or the call's Interrupter (polled every 5 ms). A failure while the client owes its next chunk
//     (the handler blocked in Read, e.g. a client that waits for each chunk's results before sending the next)
//     cancels the client's call with that status (grpc_call_cancel_with_status, what ServerContext::TryCancel does
//     with CANCELLED): a synchronous handler cannot return while it reads.
//   * The handler waits on its client (ActiveCalls' idle watchdog, through `waiting`) while a reply to it is being
//     written, or while it reads the next chunk with no chunk outstanding; not while replicas compute.
//   * The destructor cancels whatever still runs and joins every thread.
// Thread-safe as used: open() and serve() from the handler's thread, the rest after serve().
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "core/interrupter.h"
#include "core/status.h"
#include "distband/v1/distband.grpc.pb.h"
#include "server/replica_pool.h"
#include "server/request_validation.h"
#include "server/seed_shipper.h"
#include "server/server_options.h"

namespace distband {

class PointsFanOut final : private ReplicaCalls {
 public:
  using ClientStream = grpc::ServerReaderWriter<v1::PointsReply, v1::PointsRequest>;
  struct Config {
    const ServerOptions& options;
    ReplicaPool& pool;
    Interrupter& interrupter;  ///< the call's
    grpc::ServerContext& client_context;
    ClientStream& client;
    std::function<void(bool)> waiting;  ///< ActiveCalls::Call::waitingForClient
    std::string request_id;             ///< sent to the replicas as x-request-id
  };

  /// Most replica streams one call opens (one reader thread each).
  static constexpr size_t kMaxStreams = 8;
  /// Chunks outstanding on one stream: one computing, one queued at the replica, one result on its way back.
  static constexpr size_t kWindow = 3;
  /// The streams a call opens when `replicas` replicas resolve (at least 1, for admission).
  static size_t streamsFor(size_t replicas);
  /// The bytes a call is admitted with: kWindow results of the largest chunk per stream, the chunk in hand and its
  /// decoded copy, and a mesh asset's canonical PLY while it is uploaded.
  static uint64_t reservedBytes(const ResolvedPoints& points, size_t streams);

  /// `points` must outlive the fan-out.
  PointsFanOut(const ResolvedPoints& points, Config config);
  ~PointsFanOut() override;
  PointsFanOut(const PointsFanOut&) = delete;
  PointsFanOut& operator=(const PointsFanOut&) = delete;

  /// Ships the seeds and opens the replica streams; `header` is what the client will get (the replicas' must agree).
  Status open(const v1::PointsReplyHeader& header);
  /// Sends the client the header, then fans the chunks out and forwards the results until every replica summarized
  /// (OK) or the first error.
  Status serve();
  /// After serve(): the replicas' summaries merged (queue_seconds: the longest replica's wait; total_seconds unset).
  void summarize(v1::PointsSummary* summary) const;
  /// Chunks and points forwarded to the client so far, streams in use.
  uint64_t chunks() const;
  uint64_t points() const;
  size_t streams() const;

 private:
  struct Stream;
  struct Outstanding {
    size_t stream;         ///< index in streams_
    uint64_t chunk;        ///< the client's numbering
    uint64_t first_point;  ///< the client's numbering
    uint32_t points;
  };
  using Clock = std::chrono::steady_clock;

  // ReplicaCalls: the seeds' uploads, prepared like tile calls (credentials, --tile-timeout, the request id).
  Status stopReason() const override;
  const std::string& requestId() const override { return config_.request_id; }
  void enroll(grpc::ClientContext* context) override;
  void withdraw(grpc::ClientContext* context) override;

  /// Uploads an asset_id's seeds to `replicas` and names them in `header`; keeps only the replicas that hold them.
  Status shipSeeds(std::vector<ReplicaPool::Replica>* replicas, v1::PointsHeader* header);
  void openStream(const ReplicaPool::Replica& replica, const v1::PointsRequest& header);
  /// A stream's reader thread.
  void readReplies(Stream& stream);
  /// The merge thread: forwards results in order, watches the client, the Interrupter and stalled replicas.
  void merge();
  /// Under mu_: the first error ends the call (see the contract).
  void failLocked(Status status);
  Status fail(Status status);
  /// Under mu_: the client's cancel, the Interrupter, a stalled replica.
  void checkStopLocked();
  /// Under mu_: tells the idle watchdog whether the call now waits on its client.
  void updateWaitingLocked();
  /// Under mu_: whether `stream`'s header describes the query as header_ does.
  Status agreementLocked(const Stream& stream) const;
  /// Sends chunk number `chunk` (`points` points from `first_point`) to its stream once the stream has a free slot;
  /// false once the call failed.
  bool sendChunk(const v1::PointsRequest& request, uint64_t chunk, uint64_t first_point, uint32_t points);
  bool writeClient(const v1::PointsReply& reply);
  /// Why the client's side ended (its cancel, the deadline, the Interrupter, or it went away).
  Status clientGone() const;
  Status replicaFailure(const Stream& stream, const Status& status) const;
  /// Under mu_: every stream in use has ended.
  bool allEndedLocked() const;
  void halfCloseStreams();
  Clock::duration tileTimeout() const;

  const ResolvedPoints& points_;
  const Config config_;
  ReplicaUploads uploads_;
  v1::PointsReplyHeader header_;

  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::vector<std::unique_ptr<Stream>> streams_;  ///< every stream opened; fixed once open() returns
  std::vector<size_t> in_use_;                    ///< the streams chunks go to (indices in streams_)
  std::set<grpc::ClientContext*> uploads_in_flight_;
  std::deque<Outstanding> outstanding_;  ///< chunks sent and not yet forwarded, oldest first
  Status failure_;
  bool input_done_ = false;                                   ///< the client half-closed, or sent a malformed chunk
  bool input_failed_ = false;                                 ///< ... the latter: no summaries are awaited
  bool reading_ = false, writing_ = false, waiting_ = false;  ///< the client's side (the idle bracket)
  uint64_t chunks_ = 0, points_forwarded_ = 0;
  std::thread merger_;
};

}  // namespace distband

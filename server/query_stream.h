// QueryStream: what produces a Query's messages after its header — a QueryJob computing the field here, or a
// TiledQuery gathering it from replicas — so one handler streams either to the client.
// Contract:
//   * start() begins producing BrickBatch / SegmentDone messages into queue() (bounded in bytes: production pauses
//     while the client reads slowly); the queue is closed when production ends (done, failed or interrupted).
//   * stop() (any thread; the caller trips the query's Interrupter first) drops queued messages, refuses new ones and
//     unblocks the producer; join() waits for it.
//   * After join(): status() (OK, or why production failed), interrupted(), stopped() (when compute ended) and
//     summarize(), which fills the QuerySummary's totals and per-segment timings (not messages, queue or total time,
//     which the handler knows).
#pragma once

#include <chrono>
#include <memory>
#include <string>

#include "core/status.h"
#include "distband/v1/distband.pb.h"
#include "server/bounded_queue.h"
#include "server/log_line.h"

namespace distband {

class QueryStream {
 public:
  using Clock = std::chrono::steady_clock;
  using Message = std::unique_ptr<v1::QueryReply>;

  virtual ~QueryStream() = default;
  virtual void start() = 0;
  virtual void stop() = 0;
  virtual void join() = 0;
  virtual BoundedQueue<Message>& queue() = 0;

  virtual const Status& status() const = 0;
  virtual bool interrupted() const = 0;
  virtual Clock::time_point stopped() const = 0;
  virtual void summarize(v1::QuerySummary* summary) const = 0;
  /// Tiles the query was split into and tile attempts retried (a coordinator's; 0 for a query computed here).
  virtual int tiles() const { return 0; }
  virtual int retries() const { return 0; }
  /// Adds the figures of the query's log line (segments, voxels, ...).
  virtual void logStats(LogLine& line) const = 0;
};

}  // namespace distband

// QueryJob: the compute side of one Query — seeds, engine, encoding — on its own thread, feeding a bounded queue.
// Contract:
//   * start() launches a dedicated compute thread (never a gRPC thread) that enters the server's shared TBB
//     arena, builds the seeds and runs computeBandField with threads = 0 (the arena's workers help).
//   * The engine hands finished bricks over in chunks of at most kQueryChunkBricks; each chunk is encoded into
//     BrickBatch messages (<= batch_bytes each) pushed into a byte-bounded queue, and a segment's last chunk is
//     followed by its SegmentDone. When the writer (the gRPC handler) falls behind, push blocks and the engine
//     pauses: what waits for a slow client is bounded by the queue capacity plus one chunk, never a whole segment.
//   * Every phase polls the call's Interrupter; stop() (any thread) also drops queued messages at once and makes a
//     blocked push return, so the engine sees the interrupter at its next poll.
//   * When compute ends (normally, by error or by interruption) the queue is closed; the consumer drains it, then
//     join()s and reads the outcome.
#pragma once

#include <atomic>
#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <tbb/task_arena.h>

#include "core/band/band_engine.h"
#include "core/interrupter.h"
#include "core/status.h"
#include "distband/v1/distband.pb.h"
#include "server/bounded_queue.h"
#include "server/query_stream.h"
#include "server/request_validation.h"

namespace distband {

class QueryJob final : public QueryStream {
 public:
  QueryJob(ResolvedQuery query, tbb::task_arena* arena, uint64_t buffer_bytes, Interrupter* interrupter);
  ~QueryJob() override;  ///< stops and joins if still running
  QueryJob(const QueryJob&) = delete;
  QueryJob& operator=(const QueryJob&) = delete;

  void start() override;
  /// Drops queued messages and refuses new ones; the caller trips the interrupter (with its reason) first.
  void stop() override;
  void join() override;
  BoundedQueue<Message>& queue() override { return queue_; }

  // Valid after join().
  const Status& status() const override { return status_; }  ///< seed or engine failure (OK when none)
  bool interrupted() const override { return result_.interrupted; }
  Clock::time_point stopped() const override { return engine_stopped_; }
  void summarize(v1::QuerySummary* summary) const override;
  void logStats(LogLine& line) const override;
  const FieldRunResult& result() const { return result_; }
  Clock::time_point started() const { return started_; }

 private:
  void run();
  void emitChunk(SegmentBricks&& chunk);

  ResolvedQuery query_;
  tbb::task_arena* arena_;
  BoundedQueue<Message> queue_;
  Interrupter* interrupter_;
  std::thread thread_;

  Status status_;
  FieldRunResult result_;
  double seed_seconds_ = 0;
  Clock::time_point started_{}, engine_stopped_{}, segment_started_{};
  double segment_compute_seconds_ = 0;
  uint64_t segment_voxels_ = 0, segment_bricks_so_far_ = 0;  ///< of the segment being emitted
  /// Streamed (for a tile: the voxels of its `deliver` box; the engine's counts include the halo).
  uint64_t bricks_sent_ = 0, voxels_sent_ = 0, value_bytes_ = 0;
  std::vector<uint64_t> segment_voxels_sent_;
  std::vector<double> segment_sent_seconds_;
  std::vector<uint64_t> segment_bricks_;
};

}  // namespace distband

// QueryJob: the compute side of one Query — seeds, engine, encoding — on its own thread, feeding a bounded queue.
// Contract:
//   * start() launches a dedicated compute thread (never a gRPC thread) that enters the server's shared TBB
//     arena, builds the seeds and runs computeDistanceField with threads = 0 (the arena's workers help).
//   * Each finished segment is encoded into BrickBatch messages (<= batch_bytes each) followed by a SegmentDone,
//     pushed into a byte-bounded queue: when the writer (the gRPC handler) falls behind, push blocks and the
//     engine pauses — memory stays bounded by the queue capacity plus the engine's own state.
//   * cancel() (from any thread) makes the engine stop at its next step and drops queued messages at once.
//   * When compute ends (normally, by error or by cancel) the queue is closed; the consumer drains it, then
//     join()s and reads the outcome.
#pragma once

#include <atomic>
#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <tbb/task_arena.h>

#include "core/engine.h"
#include "distband/v1/distband.pb.h"
#include "server/bounded_queue.h"
#include "server/request_validation.h"

namespace distband {

class QueryJob {
 public:
  using Clock = std::chrono::steady_clock;
  using Message = std::unique_ptr<v1::QueryReply>;

  QueryJob(ResolvedQuery query, tbb::task_arena* arena, uint64_t buffer_bytes);
  ~QueryJob();  ///< cancels and joins if still running
  QueryJob(const QueryJob&) = delete;
  QueryJob& operator=(const QueryJob&) = delete;

  void start();
  void cancel();
  void join();
  BoundedQueue<Message>& queue() { return queue_; }

  // Valid after join().
  const std::string& error() const { return error_; }  ///< seed or engine failure ("" when none)
  bool outOfMemory() const { return out_of_memory_; }  ///< the failure was an allocation failure
  bool cancelled() const { return cancelled_.load(); }
  const EngineResult& result() const { return result_; }
  double seedSeconds() const { return seed_seconds_; }
  Clock::time_point engineStopped() const { return engine_stopped_; }
  Clock::time_point started() const { return started_; }
  uint64_t bricksSent() const { return bricks_sent_; }
  uint64_t valueBytes() const { return value_bytes_; }
  const std::vector<double>& segmentSentSeconds() const { return segment_sent_seconds_; }
  const std::vector<uint64_t>& segmentBricks() const { return segment_bricks_; }

 private:
  void run();
  void emitSegment(SegmentBricks&& segment);

  ResolvedQuery query_;
  tbb::task_arena* arena_;
  BoundedQueue<Message> queue_;
  std::thread thread_;
  std::atomic<bool> cancelled_{false};

  std::string error_;
  bool out_of_memory_ = false;
  EngineResult result_;
  double seed_seconds_ = 0;
  Clock::time_point started_{}, engine_stopped_{}, last_callback_end_{};
  uint64_t bricks_sent_ = 0, value_bytes_ = 0;
  std::vector<double> segment_sent_seconds_;
  std::vector<uint64_t> segment_bricks_;
};

}  // namespace distband

#include "server/query_job.h"

#include <exception>
#include <new>

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "proto/brick_codec.h"
#include "server/seed_builder.h"

namespace distband {
namespace {
double secondsBetween(QueryJob::Clock::time_point a, QueryJob::Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}
}  // namespace

QueryJob::QueryJob(ResolvedQuery query, tbb::task_arena* arena, uint64_t buffer_bytes)
    : query_(std::move(query)), arena_(arena), queue_(buffer_bytes) {}

QueryJob::~QueryJob() {
  if (thread_.joinable()) {
    cancel();
    thread_.join();
  }
}

void QueryJob::start() {
  started_ = Clock::now();
  thread_ = std::thread([this] { run(); });
}

void QueryJob::cancel() {
  cancelled_.store(true);
  queue_.abort();
}

void QueryJob::join() {
  if (thread_.joinable()) thread_.join();
}

void QueryJob::run() {
  try {
    arena_->execute([&] {
      const auto t0 = Clock::now();
      Seeds seeds;
      std::string e = buildSeeds(query_, &seeds);
      seed_seconds_ = secondsBetween(t0, Clock::now());
      if (!e.empty()) {
        error_ = "seeds: " + e;
        return;
      }
      if (cancelled_.load()) {
        result_.interrupted = true;
        return;
      }
      EngineOptions options = query_.engine;
      options.threads = 0;  // the shared arena we are executing in
      options.interrupted = [this] { return cancelled_.load(std::memory_order_relaxed); };
      last_callback_end_ = Clock::now();
      result_ = computeDistanceField(query_.grid, std::move(seeds), options,
                                     [this](SegmentBricks&& s) { emitSegment(std::move(s)); });
    });
  } catch (const std::bad_alloc&) {
    out_of_memory_ = true;
    error_ = "the server ran out of memory for this query; lower the resolution or set a limit";
  } catch (const std::exception& ex) {
    error_ = ex.what();
  }
  engine_stopped_ = Clock::now();
  queue_.close();
}

void QueryJob::emitSegment(SegmentBricks&& segment) {
  const double compute_seconds = secondsBetween(last_callback_end_, Clock::now());
  const v1::BrickEncoding enc = query_.encoding;
  uint64_t voxels = 0, bricks = 0;
  const size_t n = segment.bricks.size();
  // Batches: always at least one brick per message; a batch stops before exceeding the byte bound.
  struct Batch {
    size_t begin, end, bytes;
  };
  std::vector<Batch> batches;
  for (size_t i = 0; i < n;) {
    Batch batch{i, i, 32};
    do {
      const Brick& b = segment.bricks[i];
      const int count = b.mask.count();
      const size_t need = encodedBrickBytes(count, enc);
      if (batch.end > batch.begin && batch.bytes + need > query_.batch_bytes) break;
      batch.bytes += need;
      voxels += uint64_t(count);
      value_bytes_ += need - 24;
      ++bricks;
      batch.end = ++i;
    } while (i < n);
    batches.push_back(batch);
  }
  // Encoded in parallel on the query's arena (the engine waits for this callback anyway), a wave at a time so a
  // large segment is never held encoded all at once; sent in order.
  const size_t wave = 4 * size_t(std::max(1, tbb::this_task_arena::max_concurrency()));
  std::vector<std::unique_ptr<v1::QueryReply>> messages;
  for (size_t w0 = 0; w0 < batches.size() && !cancelled_.load(std::memory_order_relaxed); w0 += wave) {
    const size_t w1 = std::min(batches.size(), w0 + wave);
    messages.clear();
    messages.resize(w1 - w0);
    tbb::parallel_for(size_t(w0), w1, [&](size_t k) {
      auto msg = std::make_unique<v1::QueryReply>();
      v1::BrickBatch* batch = msg->mutable_bricks();
      batch->set_segment(uint32_t(segment.index));
      batch->set_lower(segment.lower_world);
      batch->set_upper(segment.upper_world);
      batch->mutable_bricks()->Reserve(int(batches[k].end - batches[k].begin));
      for (size_t i = batches[k].begin; i < batches[k].end; ++i) encodeBrick(segment.bricks[i], enc, batch->add_bricks());
      messages[k - w0] = std::move(msg);
    });
    for (size_t k = w0; k < w1; ++k)
      if (!queue_.push(std::move(messages[k - w0]), batches[k].bytes)) return;  // cancelled
  }
  segment.bricks.clear();
  segment.bricks.shrink_to_fit();
  if (cancelled_.load()) return;
  auto done = std::make_unique<v1::QueryReply>();
  v1::SegmentDone* d = done->mutable_segment_done();
  d->set_segment(uint32_t(segment.index));
  d->set_lower(segment.lower_world);
  d->set_upper(segment.upper_world);
  d->set_voxels(voxels);
  d->set_bricks(bricks);
  d->set_compute_seconds(compute_seconds);
  d->set_last(segment.last);
  bricks_sent_ += bricks;
  segment_bricks_.push_back(bricks);
  segment_sent_seconds_.push_back(secondsBetween(started_, Clock::now()));
  queue_.push(std::move(done), 64);
  last_callback_end_ = Clock::now();
}

}  // namespace distband

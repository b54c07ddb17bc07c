#include "server/query_job.h"

#include <exception>
#include <new>

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
  size_t i = 0;
  const size_t n = segment.bricks.size();
  while (i < n && !cancelled_.load(std::memory_order_relaxed)) {
    auto msg = std::make_unique<v1::QueryReply>();
    v1::BrickBatch* batch = msg->mutable_bricks();
    batch->set_segment(uint32_t(segment.index));
    batch->set_lower(segment.lower_world);
    batch->set_upper(segment.upper_world);
    size_t bytes = 32;
    // Always at least one brick per message; stop before exceeding the batch bound.
    do {
      const Brick& b = segment.bricks[i];
      const int count = b.mask.count();
      const size_t need = encodedBrickBytes(count, enc);
      if (batch->bricks_size() > 0 && bytes + need > query_.batch_bytes) break;
      encodeBrick(b, enc, batch->add_bricks());
      bytes += need;
      voxels += uint64_t(count);
      value_bytes_ += need - 24;
      ++bricks;
      ++i;
    } while (i < n);
    if (!queue_.push(std::move(msg), bytes)) return;  // cancelled
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

#include "server/query_job.h"

#include <exception>
#include <new>

#include <fmt/format.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "core/field/compute_field.h"
#include "proto/brick_codec.h"

namespace distband {
namespace {

double secondsBetween(QueryJob::Clock::time_point a, QueryJob::Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

}  // namespace

QueryJob::QueryJob(ResolvedQuery query, tbb::task_arena* arena, uint64_t buffer_bytes, Interrupter* interrupter)
    : query_(std::move(query)), arena_(arena), queue_(buffer_bytes), interrupter_(interrupter) {}

QueryJob::~QueryJob() {
  if (thread_.joinable()) {
    interrupter_->cancel(Status::Code::kCancelled, "the query was abandoned");
    stop();
    thread_.join();
  }
}

void QueryJob::start() {
  started_ = Clock::now();
  thread_ = std::thread([this] { run(); });
}

void QueryJob::stop() { queue_.abort(); }

void QueryJob::join() {
  if (thread_.joinable()) thread_.join();
}

void QueryJob::run() {
  try {
    arena_->execute([&] {
      FieldRunOptions options = query_.plan.runOptions();
      options.threads = 0;  // the shared arena we are executing in
      options.interrupter = interrupter_;
      options.max_chunk_bricks = kQueryChunkBricks;
      SeedSource source;
      source.points = &query_.points;
      if (query_.asset) {
        source.volume = query_.asset->volume;  // a tile's volume covers its window (checked by resolveQuery)
        source.mesh = query_.asset->mesh.get();
      }
      FieldInputs inputs;
      const auto t0 = Clock::now();
      const Status built = buildFieldInputs(query_.plan, query_.grid, query_.tile ? &query_.tile->window : nullptr,
                                            source, interrupter_, &inputs);
      seed_seconds_ = secondsBetween(t0, Clock::now());
      if (interrupter_->interrupted()) {
        result_.interrupted = true;
        return;
      }
      if (!built.ok()) {
        // Every rule a request can break was checked before compute: what fails here is the server's fault.
        status_ = Status::Internal("seeds: " + built.message());
        return;
      }
      segment_started_ = Clock::now();
      result_ = computeField(query_.plan, query_.engineGrid(), std::move(inputs), options,
                             [this](SegmentBricks&& s) { emitChunk(std::move(s)); });
    });
  } catch (const std::bad_alloc&) {
    status_ = Status::ResourceExhausted(
        "the server ran out of memory for this query (its estimate was too low); lower the resolution or set a limit");
  } catch (const std::exception& ex) {
    status_ = Status::Internal(fmt::format("the engine failed: {}", ex.what()));
  }
  if (interrupter_->interrupted()) result_.interrupted = true;
  engine_stopped_ = Clock::now();
  queue_.close();
}

void QueryJob::summarize(v1::QuerySummary* s) const {
  s->set_voxels(voxels_sent_);
  s->set_bricks(bricks_sent_);
  s->set_value_bytes(value_bytes_);
  s->set_steps(uint32_t(result_.steps));
  s->set_seed_seconds(seed_seconds_);
  s->set_compute_seconds(result_.seconds);
  if (result_.sign_shares.total() > 0) {
    v1::SignShares* shares = s->mutable_sign_shares();
    shares->set_pseudonormal(uint64_t(result_.sign_shares.pseudonormal));
    shares->set_winding_certified(uint64_t(result_.sign_shares.winding_certified));
    shares->set_winding_per_voxel(uint64_t(result_.sign_shares.winding_per_voxel));
    shares->set_parity(uint64_t(result_.sign_shares.parity));
  }
  for (size_t i = 0; i < result_.segments.size(); ++i) {
    const SegmentStats& st = result_.segments[i];
    v1::SegmentTiming* t = s->add_segments();
    t->set_segment(uint32_t(st.index));
    t->set_lower(st.lower_world);
    t->set_upper(st.upper_world);
    t->set_voxels(i < segment_voxels_sent_.size() ? segment_voxels_sent_[i] : uint64_t(st.voxels));
    t->set_bricks(i < segment_bricks_.size() ? segment_bricks_[i] : uint64_t(st.bricks));
    t->set_steps(uint32_t(st.steps));
    t->set_compute_seconds(st.seconds);
    if (i < segment_sent_seconds_.size()) t->set_sent_seconds(segment_sent_seconds_[i]);
  }
}

void QueryJob::logStats(LogLine& line) const {
  line.number("segments", uint64_t(result_.segments.size()))
      .number("voxels", voxels_sent_)
      .number("bricks", bricks_sent_)
      .real("MB", value_bytes_ / 1e6, "{:.1f}")
      .seconds("seed_time", seed_seconds_)  // "seeds" is the query's seeds already
      .seconds("compute", result_.seconds)
      .text("enc", query_.encoding == v1::BRICK_ENCODING_FLOAT16 ? "f16" : "f32");
}

void QueryJob::emitChunk(SegmentBricks&& chunk) {
  segment_compute_seconds_ += secondsBetween(segment_started_, Clock::now());
  if (query_.tile) {
    // A tile: bricks move to the whole grid's coordinates; those of the halo (outside `deliver`, whole bricks since
    // both boxes are brick-aligned) are not sent. Order (z, y, x) is kept: the shift is the same for every brick.
    const Coord shift = query_.tile->window.min;
    const Coord window = query_.engineGrid().dims();
    const bool voxel_ids = closestOf(query_.plan) == v1::CLOSEST_FEATURE_VOXEL;  // window indices -> the whole grid's
    size_t kept = 0;
    for (Brick& b : chunk.bricks) {
      b.origin = b.origin + shift;
      if (!query_.tile->deliver.contains(b.origin)) continue;
      if (voxel_ids)
        for (int64_t& id : b.closest)
          if (id >= 0) {
            const Coord c{int(id % window.x), int(id / window.x % window.y), int(id / (int64_t(window.x) * window.y))};
            id = query_.grid.denseIndex(c + shift);
          }
      if (&chunk.bricks[kept] != &b) chunk.bricks[kept] = std::move(b);
      ++kept;
    }
    chunk.bricks.resize(kept);
  }
  const v1::BrickEncoding enc = query_.encoding;
  const v1::ClosestFeature closest = closestOf(query_.plan);
  const size_t n = chunk.bricks.size();
  // Batches: always at least one brick per message; a batch stops before exceeding the byte bound.
  struct Batch {
    size_t begin, end, bytes;
  };
  std::vector<Batch> batches;
  for (size_t i = 0; i < n;) {
    Batch batch{i, i, 32};
    do {
      const Brick& b = chunk.bricks[i];
      const int count = b.mask.count();
      const size_t need = encodedBrickBytes(count, enc, closest);
      if (batch.end > batch.begin && batch.bytes + need > query_.batch_bytes) break;
      batch.bytes += need;
      segment_voxels_ += uint64_t(count);
      value_bytes_ += need - 24;
      ++segment_bricks_so_far_;
      batch.end = ++i;
    } while (i < n);
    batches.push_back(batch);
  }
  // Encoded in parallel on the query's arena (the engine waits for this callback anyway), a wave at a time so a
  // chunk is never held encoded all at once; sent in order.
  const size_t wave = 4 * size_t(std::max(1, tbb::this_task_arena::max_concurrency()));
  std::vector<std::unique_ptr<v1::QueryReply>> messages;
  for (size_t w0 = 0; w0 < batches.size() && !interrupter_->interrupted(); w0 += wave) {
    const size_t w1 = std::min(batches.size(), w0 + wave);
    messages.clear();
    messages.resize(w1 - w0);
    tbb::parallel_for(size_t(w0), w1, [&](size_t k) {
      auto msg = std::make_unique<v1::QueryReply>();
      v1::BrickBatch* batch = msg->mutable_bricks();
      batch->set_segment(uint32_t(chunk.index));
      batch->set_lower(chunk.lower_world);
      batch->set_upper(chunk.upper_world);
      batch->mutable_bricks()->Reserve(int(batches[k].end - batches[k].begin));
      for (size_t i = batches[k].begin; i < batches[k].end; ++i) encodeBrick(chunk.bricks[i], enc, batch->add_bricks(), closest);
      messages[k - w0] = std::move(msg);
    });
    for (size_t k = w0; k < w1; ++k)
      if (!queue_.push(std::move(messages[k - w0]), batches[k].bytes)) return;  // stopped
  }
  chunk.bricks.clear();
  chunk.bricks.shrink_to_fit();
  if (interrupter_->interrupted()) return;
  if (chunk.complete) {
    auto done = std::make_unique<v1::QueryReply>();
    v1::SegmentDone* d = done->mutable_segment_done();
    d->set_segment(uint32_t(chunk.index));
    d->set_lower(chunk.lower_world);
    d->set_upper(chunk.upper_world);
    d->set_voxels(segment_voxels_);
    d->set_bricks(segment_bricks_so_far_);
    d->set_compute_seconds(segment_compute_seconds_);
    d->set_last(chunk.last);
    bricks_sent_ += segment_bricks_so_far_;
    voxels_sent_ += segment_voxels_;
    segment_bricks_.push_back(segment_bricks_so_far_);
    segment_voxels_sent_.push_back(segment_voxels_);
    segment_sent_seconds_.push_back(secondsBetween(started_, Clock::now()));
    segment_voxels_ = segment_bricks_so_far_ = 0;
    segment_compute_seconds_ = 0;
    queue_.push(std::move(done), 64);
  }
  segment_started_ = Clock::now();
}

}  // namespace distband

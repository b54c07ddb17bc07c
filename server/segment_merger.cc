#include "server/segment_merger.h"

#include <algorithm>
#include <utility>

#include <fmt/format.h>

#include "server/memory_budget.h"

namespace distband {
namespace {

uint64_t brickKey(const v1::BrickData& b) {
  return (uint64_t(uint32_t(b.x())) << 42) | (uint64_t(uint32_t(b.y())) << 21) | uint64_t(uint32_t(b.z()));
}

}  // namespace

SegmentMerger::SegmentMerger(Config config, Sink sink)
    : config_(config), sink_(std::move(sink)), tiles_(config.tiles) {}

Status SegmentMerger::onBatch(size_t tile, Message batch) {
  if (stopped_) return Status::Ok();
  TileState& t = tiles_[tile];
  const uint32_t s = batch->bricks().segment();
  if (s < t.completed || s < merging_) return Status::Ok();  // a replay of what was already merged
  if (s == merging_) {
    forward(tile, std::move(batch));
    return Status::Ok();
  }
  const uint64_t bytes = batch->ByteSizeLong();
  if (held_bytes_ + bytes > config_.buffer_bytes) {
    abort();
    return Status::ResourceExhausted(fmt::format(
        "the coordinator would hold more than --tile-buffer-bytes ({}) of later segments while segment {} waits "
        "for slower tiles; use fewer segments (a longer segment_length) or a larger --tile-buffer-bytes",
        humanBytes(config_.buffer_bytes), merging_));
  }
  held_bytes_ += bytes;
  t.held_bytes += bytes;
  t.held[s].push_back({std::move(batch), bytes});
  return Status::Ok();
}

void SegmentMerger::onSegmentDone(size_t tile, const v1::SegmentDone& d) {
  if (stopped_) return;
  TileState& t = tiles_[tile];
  if (d.segment() < t.completed) return;
  t.completed = d.segment() + 1;
  t.segments.resize(t.completed);
  t.segments[d.segment()] = d;
  if (d.last()) {
    t.finished = true;
    t.last = d.segment();
  }
  advance();
}

void SegmentMerger::onSummary(size_t tile, const v1::QuerySummary& summary) {
  if (!stopped_) tiles_[tile].summary = summary;
}

void SegmentMerger::onTileFinished(size_t tile) {
  if (stopped_) return;
  tiles_[tile].finished = true;
  advance();
}

void SegmentMerger::onAttemptFailed(size_t tile) {
  if (stopped_) return;
  // What was merged stays; what was held for later segments comes again with the replay.
  TileState& t = tiles_[tile];
  held_bytes_ -= t.held_bytes;
  t.held.clear();
  t.held_bytes = 0;
  t.finished = false;
  t.completed = std::min(t.completed, merging_ + 1);
  t.segments.resize(t.completed);
  t.replaying = true;
}

void SegmentMerger::abort() {
  stopped_ = true;
  for (TileState& t : tiles_) {
    t.held.clear();
    t.held_bytes = 0;
  }
  held_bytes_ = 0;
}

bool SegmentMerger::sawLastSegment(size_t tile) const { return tiles_[tile].finished; }

bool SegmentMerger::everythingMerged(size_t tile) const {
  return tiles_[tile].finished && tiles_[tile].last <= merging_;
}

void SegmentMerger::forward(size_t tile, Message batch) {
  TileState& t = tiles_[tile];
  auto* bricks = batch->mutable_bricks()->mutable_bricks();
  if (t.replaying) {
    auto keep = std::remove_if(bricks->begin(), bricks->end(),
                               [&](const v1::BrickData& b) { return t.forwarded.count(brickKey(b)) > 0; });
    bricks->erase(keep, bricks->end());
    if (bricks->empty()) return;
  }
  for (const v1::BrickData& b : *bricks) {
    t.forwarded.insert(brickKey(b));
    value_bytes_ += b.values().size() + b.mask().size() + b.closest().size();
  }
  sink_.batch(tile, std::move(batch));
}

void SegmentMerger::advance() {
  while (!complete_ && !stopped_) {
    bool all_finished = true;
    uint32_t last = 0;
    for (const TileState& t : tiles_) {
      if (!(t.completed > merging_ || t.finished)) return;
      all_finished &= t.finished;
      if (t.finished) last = std::max(last, t.last);
    }
    v1::SegmentDone d;
    d.set_segment(merging_);
    bool have_range = false;
    uint64_t voxels = 0, bricks = 0;
    double compute = 0;
    for (const TileState& t : tiles_) {
      if (t.segments.size() <= merging_) continue;
      const v1::SegmentDone& s = t.segments[merging_];
      if (!have_range) {
        d.set_lower(s.lower());
        d.set_upper(s.upper());
        have_range = true;
      }
      voxels += s.voxels();
      bricks += s.bricks();
      compute += s.compute_seconds();
    }
    if (!have_range) {  // no tile had anything to compute: the protocol still ends with an (empty) segment
      const double length = config_.segment_length_world;
      d.set_lower(length > 0 ? merging_ * length : 0);
      d.set_upper(length > 0 ? std::min((merging_ + 1) * length, config_.limit_world) : config_.limit_world);
    }
    d.set_voxels(voxels);
    d.set_bricks(bricks);
    d.set_compute_seconds(compute);
    const bool is_last = all_finished && merging_ >= last;
    d.set_last(is_last);
    v1::SegmentTiming& timing = timings_.emplace_back();
    timing.set_segment(merging_);
    timing.set_lower(d.lower());
    timing.set_upper(d.upper());
    timing.set_voxels(voxels);
    timing.set_bricks(bricks);
    timing.set_compute_seconds(compute);
    timing.set_sent_seconds(std::chrono::duration<double>(Clock::now() - config_.started).count());
    auto done = std::make_unique<v1::QueryReply>();
    *done->mutable_segment_done() = d;
    sink_.segment_done(std::move(done));
    if (is_last) {
      complete_ = true;
      return;
    }
    ++merging_;
    for (size_t i = 0; i < tiles_.size(); ++i) {
      TileState& t = tiles_[i];
      t.forwarded.clear();
      auto it = t.held.find(merging_);
      if (it == t.held.end()) continue;
      for (Held& h : it->second) {
        held_bytes_ -= h.bytes;
        t.held_bytes -= h.bytes;
        forward(i, std::move(h.batch));
      }
      t.held.erase(it);
    }
  }
}

void SegmentMerger::summarize(v1::QuerySummary* s) const {
  uint64_t voxels = 0, bricks = 0, steps = 0;
  double seeds = 0, compute = 0;
  v1::SignShares shares;
  for (const v1::SegmentTiming& t : timings_) {
    voxels += t.voxels();
    bricks += t.bricks();
  }
  for (const TileState& t : tiles_) {
    steps += t.summary.steps();
    seeds += t.summary.seed_seconds();
    compute += t.summary.compute_seconds();
    const v1::SignShares& ts = t.summary.sign_shares();
    shares.set_pseudonormal(shares.pseudonormal() + ts.pseudonormal());
    shares.set_winding_certified(shares.winding_certified() + ts.winding_certified());
    shares.set_winding_per_voxel(shares.winding_per_voxel() + ts.winding_per_voxel());
    shares.set_parity(shares.parity() + ts.parity());
  }
  s->set_voxels(voxels);
  s->set_bricks(bricks);
  s->set_value_bytes(value_bytes_);
  s->set_steps(uint32_t(std::min<uint64_t>(steps, UINT32_MAX)));
  s->set_seed_seconds(seeds);
  s->set_compute_seconds(compute);
  if (shares.pseudonormal() + shares.winding_certified() + shares.winding_per_voxel() + shares.parity() > 0)
    *s->mutable_sign_shares() = shares;
  for (const v1::SegmentTiming& timing : timings_) {
    v1::SegmentTiming* out = s->add_segments();
    *out = timing;
    uint64_t segment_steps = 0;
    for (const TileState& t : tiles_)
      if (t.summary.segments_size() > int(timing.segment())) segment_steps += t.summary.segments(int(timing.segment())).steps();
    out->set_steps(uint32_t(std::min<uint64_t>(segment_steps, UINT32_MAX)));
  }
}

}  // namespace distband

#include "server/tiled_query.h"

#include <fmt/format.h>

namespace distband {
namespace {

void setBox(const VoxelBox& b, v1::VoxelBox* out) {
  out->set_min_x(uint32_t(b.min.x));
  out->set_min_y(uint32_t(b.min.y));
  out->set_min_z(uint32_t(b.min.z));
  out->set_size_x(uint32_t(b.dims.x));
  out->set_size_y(uint32_t(b.dims.y));
  out->set_size_z(uint32_t(b.dims.z));
}

}  // namespace

uint64_t TiledQuery::reservedBytes(const ServerOptions& o) { return o.stream_buffer_bytes + o.tile_buffer_bytes; }

std::vector<TilePlan> TiledQuery::plan(const ResolvedQuery& q, uint64_t tile_voxels) {
  int halo = tileHalo(q.plan.limitVoxels(q.grid));
  // Without a limit every seed can reach every voxel. The separable point EDT is exact for points outside its grid,
  // so a margin suffices there; the band in a window is not (two points outside it can seed the same face voxels and
  // the farther one never enters), and mesh and volume seeds outside a window would be lost: their windows are the
  // whole grid.
  if (halo < 0 && q.seed_kind == ResolvedQuery::SeedKind::kPoints && q.plan.algorithm == FieldAlgorithm::kSeparable)
    halo = 2 * kBrickSize;
  return planTiles(q.grid.dims(), tile_voxels, halo);
}

TiledQuery::TiledQuery(ResolvedQuery query, Config config)
    : query_(std::move(query)), config_(config), queue_(config.options.stream_buffer_bytes),
      dispatcher_(config, *this) {}

TiledQuery::~TiledQuery() {
  if (thread_.joinable()) {
    stop();
    thread_.join();
  }
}

void TiledQuery::start() {
  started_ = Clock::now();
  thread_ = std::thread([this] { run(); });
}

void TiledQuery::stop() {
  // The queue first: a worker blocked pushing into it holds the dispatcher's lock.
  queue_.abort();
  dispatcher_.stop();
}

void TiledQuery::join() {
  if (thread_.joinable()) thread_.join();
}

void TiledQuery::run() {
  replicas_ = config_.pool.replicas().size();
  plans_ = plan(query_, config_.options.tile_voxels);
  shipper_.emplace(query_, config_.options, config_.pool, plans_);
  SegmentMerger::Config merge{plans_.size(), config_.options.tile_buffer_bytes, query_.plan.segment_length_world,
                              query_.plan.limit_world, started_};
  merger_.emplace(merge, SegmentMerger::Sink{
                             [this](size_t tile, Message batch) {
                               shipper_->toQueryPointIds(tile, batch->mutable_bricks());
                               const uint64_t bytes = batch->ByteSizeLong();
                               // Blocks while the client reads slowly (every tile then waits: bounded).
                               queue_.push(std::move(batch), bytes);
                             },
                             [this](Message segment_done) { queue_.push(std::move(segment_done), 64); }});
  Status status;
  if (replicas_ == 0)
    status = Status::Unavailable(fmt::format("--peers {} names no reachable replica", config_.pool.target()));
  if (status.ok()) status = shipper_->ship(dispatcher_);
  if (status.ok()) dispatcher_.run(plans_, replicas_);
  else dispatcher_.fail(status);
  // Every worker has ended: what the merger still holds is freed with the query.
  config_.metrics.mergeBufferChanged(-int64_t(reported_held_bytes_));
  reported_held_bytes_ = 0;
  interrupted_ = config_.interrupter.interrupted();
  stopped_ = Clock::now();
  queue_.close();
}

std::optional<v1::QueryRequest> TiledQuery::request(size_t tile) {
  const ResolvedQuery& q = query_;
  v1::QueryRequest r;
  // The whole grid exactly as resolved here (explicit: replicas decide no default of their own).
  v1::GridSpec* g = r.mutable_grid();
  g->mutable_origin()->set_x(q.grid.origin().x);
  g->mutable_origin()->set_y(q.grid.origin().y);
  g->mutable_origin()->set_z(q.grid.origin().z);
  if (q.grid.cubic()) {
    g->set_voxel_size(q.grid.voxelSize());
  } else {
    g->mutable_spacing()->set_x(q.grid.spacing().x);
    g->mutable_spacing()->set_y(q.grid.spacing().y);
    g->mutable_spacing()->set_z(q.grid.spacing().z);
  }
  *g->mutable_dims() = dimsOf(q.grid.dims());
  // The whole grid's algorithm, so a tile's values are the whole grid's (a separable plan takes no stencil).
  r.set_algorithm(q.plan.algorithm == FieldAlgorithm::kSeparable ? v1::ALGORITHM_SEPARABLE : v1::ALGORITHM_BAND);
  if (q.plan.algorithm == FieldAlgorithm::kBand) r.set_stencil(stencilOf(q.plan));
  r.set_mode(modeOf(q.plan));
  r.set_sign(signOf(q.plan));
  r.set_encoding(q.encoding);
  r.set_segment_length(q.plan.segment_length_world);
  r.set_limit(q.plan.limit_world);
  r.set_max_batch_bytes(q.batch_bytes);
  r.set_closest_feature(q.plan.closest_features);
  // Label volumes: each tile's black border only on the faces it shares with the grid (core's buildFieldInputs).
  r.set_labels(q.plan.labels);
  r.set_black_border(q.plan.labels && q.plan.black_border);
  r.set_nearest_label(q.plan.nearest_label);
  setBox(plans_[tile].window, r.mutable_tile()->mutable_window());
  setBox(plans_[tile].deliver, r.mutable_tile()->mutable_deliver());
  if (!shipper_->addSeeds(tile, &r)) return std::nullopt;
  return r;
}

void TiledQuery::reportHeldBytes() {
  const uint64_t held = merger_->heldBytes();
  config_.metrics.mergeBufferChanged(int64_t(held) - int64_t(reported_held_bytes_));
  reported_held_bytes_ = held;
}

Status TiledQuery::onReply(size_t tile, v1::QueryReply& m) {
  const Status s = merge(tile, m);
  reportHeldBytes();
  return s;
}

Status TiledQuery::merge(size_t tile, v1::QueryReply& m) {
  switch (m.kind_case()) {
    case v1::QueryReply::kHeader: {
      const v1::Dims& d = m.header().dims();
      if (int(d.x()) != query_.grid.dims().x || int(d.y()) != query_.grid.dims().y || int(d.z()) != query_.grid.dims().z)
        return Status::Internal("a replica described a different grid (mixed versions?)");
      return Status::Ok();
    }
    case v1::QueryReply::kBricks: return merger_->onBatch(tile, std::make_unique<v1::QueryReply>(std::move(m)));
    case v1::QueryReply::kSegmentDone: merger_->onSegmentDone(tile, m.segment_done()); return Status::Ok();
    case v1::QueryReply::kSummary: merger_->onSummary(tile, m.summary()); return Status::Ok();
    case v1::QueryReply::KIND_NOT_SET: return Status::Ok();
  }
  return Status::Ok();
}

Status TiledQuery::reship() {
  shipper_->forgetUploads();
  return shipper_->ship(dispatcher_);
}

void TiledQuery::summarize(v1::QuerySummary* s) const {
  if (merger_) merger_->summarize(s);
}

void TiledQuery::logStats(LogLine& line) const {
  v1::QuerySummary s;
  summarize(&s);
  line.number("tiles", uint64_t(plans_.size()))
      .number("replicas", uint64_t(replicas_))
      .number("retries", dispatcher_.retries())
      .number("segments", s.segments_size())
      .number("voxels", s.voxels())
      .number("bricks", s.bricks())
      .real("MB", s.value_bytes() / 1e6, "{:.1f}")
      .seconds("tile_seeds", s.seed_seconds())
      .seconds("tile_compute", s.compute_seconds());
}

}  // namespace distband

#include "server/tiled_query.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "core/mesh/ply_writer.h"
#include "server/asset_parsing.h"
#include "server/grpc_status.h"
#include "server/memory_budget.h"

namespace distband {
namespace {

constexpr size_t kUploadChunkBytes = size_t(1) << 20;
constexpr size_t kMaxTileCallsPerQuery = 128;

uint64_t brickKey(const v1::BrickData& b) {
  return (uint64_t(uint32_t(b.x())) << 42) | (uint64_t(uint32_t(b.y())) << 21) | uint64_t(uint32_t(b.z()));
}

std::string boxKey(const VoxelBox& b) {
  return fmt::format("{},{},{},{},{},{}", b.min.x, b.min.y, b.min.z, b.dims.x, b.dims.y, b.dims.z);
}

void setBox(const VoxelBox& b, v1::VoxelBox* out) {
  out->set_min_x(uint32_t(b.min.x));
  out->set_min_y(uint32_t(b.min.y));
  out->set_min_z(uint32_t(b.min.z));
  out->set_size_x(uint32_t(b.dims.x));
  out->set_size_y(uint32_t(b.dims.y));
  out->set_size_z(uint32_t(b.dims.z));
}

v1::Dims dimsOf(const Coord& c) {
  v1::Dims d;
  d.set_x(uint32_t(c.x));
  d.set_y(uint32_t(c.y));
  d.set_z(uint32_t(c.z));
  return d;
}

/// The window's voxels of a whole-grid mask (x fastest).
std::string cropMask(const std::vector<uint8_t>& mask, const Coord& dims, const VoxelBox& window) {
  std::string out(size_t(window.voxelCount()), '\0');
  size_t o = 0;
  for (int z = window.min.z; z < window.end().z; ++z)
    for (int y = window.min.y; y < window.end().y; ++y) {
      const size_t row = (size_t(z) * dims.y + y) * dims.x + window.min.x;
      std::copy_n(reinterpret_cast<const char*>(mask.data()) + row, window.dims.x, out.data() + o);
      o += size_t(window.dims.x);
    }
  return out;
}

/// Squared index-space distance from p to the box's voxels.
double dist2ToBox(const Vec3d& p, const VoxelBox& b) {
  auto axis = [](double v, int lo, int hi) { return v < lo ? lo - v : (v > hi ? v - hi : 0.0); };
  const double dx = axis(p.x, b.min.x, b.end().x - 1), dy = axis(p.y, b.min.y, b.end().y - 1),
               dz = axis(p.z, b.min.z, b.end().z - 1);
  return dx * dx + dy * dy + dz * dz;
}

bool retriable(Status::Code code) {
  switch (code) {
    case Status::Code::kUnavailable:
    case Status::Code::kResourceExhausted:
    case Status::Code::kDeadlineExceeded:
    case Status::Code::kCancelled:  // a replica shutting down cancels its calls
    case Status::Code::kNotFound:   // the asset was evicted or the replica restarted: uploaded again first
    case Status::Code::kInternal:
      return true;
    default:
      return false;
  }
}

}  // namespace

uint64_t TiledQuery::reservedBytes(const ServerOptions& o) { return o.stream_buffer_bytes + o.tile_buffer_bytes; }

std::vector<TilePlan> TiledQuery::plan(const ResolvedQuery& q, uint64_t tile_voxels) {
  int halo = tileHalo(q.plan.limitVoxels(q.grid));
  // Without a limit every seed can reach every voxel. Point sites outside a window still give exact distances (the
  // engine seeds them at the window's face and is exact for sites outside its grid), so a margin suffices; mesh and
  // volume seeds outside a window would be lost, so their windows are the whole grid.
  if (halo < 0 && q.seed_kind == ResolvedQuery::SeedKind::kPoints) halo = 2 * kBrickSize;
  return planTiles(q.grid.dims(), tile_voxels, halo);
}

TiledQuery::TiledQuery(ResolvedQuery query, Config config)
    : query_(std::move(query)), config_(config), queue_(config.options.stream_buffer_bytes) {}

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
  stop_.store(true);
  queue_.abort();
  std::lock_guard lock(mu_);
  cancelCalls();
}

void TiledQuery::cancelCalls() {
  for (grpc::ClientContext* c : calls_) c->TryCancel();
  cv_.notify_all();
}

TiledQuery::RegisteredCall::RegisteredCall(TiledQuery& query, grpc::ClientContext* context)
    : query_(query), context_(context) {
  std::lock_guard lock(query_.mu_);
  query_.calls_.insert(context_);
}

TiledQuery::RegisteredCall::~RegisteredCall() {
  std::lock_guard lock(query_.mu_);
  query_.calls_.erase(context_);
}

void TiledQuery::join() {
  if (thread_.joinable()) thread_.join();
}

bool TiledQuery::stopping() const { return stop_.load() || config_.interrupter.interrupted(); }

std::chrono::system_clock::time_point TiledQuery::tileDeadline() const {
  const auto own = std::chrono::system_clock::now() +
                   std::chrono::milliseconds(int64_t(config_.options.tile_timeout_seconds * 1000));
  return std::min(own, config_.client_deadline);
}

Status TiledQuery::uploadToReplicas(
    const std::string& id,
    const std::function<Status(v1::DistanceField::Stub&, grpc::ClientContext*)>& upload) {
  const auto replicas = config_.pool.replicas();
  int present = 0;
  std::string last_error = "no replica resolves";
  for (const ReplicaPool::Replica& r : replicas) {
    if (stopping()) return config_.interrupter.interrupted() ? config_.interrupter.status() : Status::Cancelled("stopped");
    {
      std::lock_guard lock(mu_);
      if (uploaded_.count({r.address, id})) {
        ++present;
        continue;
      }
    }
    auto stub = v1::DistanceField::NewStub(r.channel);
    grpc::ClientContext context;
    config_.pool.prepare(&context, tileDeadline());
    Status s;
    {
      RegisteredCall registered(*this, &context);
      s = upload(*stub, &context);
    }
    std::lock_guard lock(mu_);
    if (s.ok()) {
      uploaded_.insert({r.address, id});
      ++present;
    } else {
      last_error = fmt::format("{}: {} {}", r.address, Status::codeName(s.code()), s.message());
      spdlog::warn("coordinator: uploading {} to replica {} failed: {}", id.substr(0, 17), r.address, last_error);
    }
  }
  // A replica that missed it answers NOT_FOUND to a tile, which uploads again and retries.
  if (present > 0) return Status::Ok();
  return Status::Unavailable(fmt::format("could not pass the seeds on to any replica of --peers {} ({})",
                                         config_.pool.target(), last_error));
}

namespace {

template <typename Chunk>
Status streamUpload(std::unique_ptr<grpc::ClientWriter<Chunk>> writer, const std::string& bytes, Chunk first,
                    const v1::UploadReply& reply, const std::string& id) {
  for (size_t off = 0; off == 0 || off < bytes.size(); off += kUploadChunkBytes) {
    Chunk chunk = off == 0 ? first : Chunk();
    chunk.set_data(bytes.substr(off, kUploadChunkBytes));
    if (!writer->Write(chunk)) break;
  }
  writer->WritesDone();
  const grpc::Status s = writer->Finish();
  if (!s.ok()) return fromGrpcStatus(s);
  if (reply.asset_id() != id)
    return Status::Internal(fmt::format("the replica named the upload {} instead of {}", reply.asset_id(), id));
  return Status::Ok();
}

}  // namespace

Status TiledQuery::prepareSeeds() {
  if (query_.seed_kind == ResolvedQuery::SeedKind::kMesh) {
    if (mesh_bytes_.empty()) {
      mesh_bytes_ = encodeBinaryPly(*query_.asset->mesh);
      mesh_id_ = meshAssetId(mesh_bytes_, v1::MESH_FORMAT_PLY);
    }
    return uploadToReplicas(mesh_id_, [&](v1::DistanceField::Stub& stub, grpc::ClientContext* context) {
      v1::UploadReply reply;
      v1::UploadMeshChunk first;
      first.mutable_header()->set_format(v1::MESH_FORMAT_PLY);
      first.mutable_header()->set_total_bytes(mesh_bytes_.size());
      first.mutable_header()->set_name(query_.asset->name.substr(0, 200));
      return streamUpload(stub.UploadMesh(context, &reply), mesh_bytes_, first, reply, mesh_id_);
    });
  }
  if (query_.seed_kind == ResolvedQuery::SeedKind::kVolume) {
    // Crops too large to travel inside a tile's request are uploaded to every replica (without a limit every window
    // is the whole grid: one upload). The ids are settled on the first call, before any worker reads them.
    const uint64_t inline_limit = config_.options.max_message_bytes / 2;
    const bool planning = !volumes_planned_;
    if (planning) {
      for (const Tile& t : tiles_)
        if (uint64_t(t.plan.window.voxelCount()) > inline_limit) volume_ids_[boxKey(t.plan.window)] = {t.plan.window, ""};
      volumes_planned_ = true;
    }
    for (auto& [key, entry] : volume_ids_) {
      const std::string bytes = cropMask(*query_.asset->mask, query_.asset->dims, entry.first);
      const v1::Dims dims = dimsOf(entry.first.dims);
      if (planning) entry.second = volumeAssetId(dims, bytes);
      const std::string& id = entry.second;
      Status s = uploadToReplicas(id, [&](v1::DistanceField::Stub& stub, grpc::ClientContext* context) {
        v1::UploadReply reply;
        v1::UploadVolumeChunk first;
        *first.mutable_header()->mutable_dims() = dims;
        return streamUpload(stub.UploadVolume(context, &reply), bytes, first, reply, id);
      });
      if (!s.ok()) return s;
    }
  }
  return Status::Ok();
}

v1::QueryRequest TiledQuery::tileRequest(const Tile& tile) const {
  const ResolvedQuery& q = query_;
  v1::QueryRequest r;
  // The whole grid exactly as resolved here (explicit: replicas decide no default of their own).
  v1::GridSpec* g = r.mutable_grid();
  g->mutable_origin()->set_x(q.grid.origin().x);
  g->mutable_origin()->set_y(q.grid.origin().y);
  g->mutable_origin()->set_z(q.grid.origin().z);
  g->set_voxel_size(q.grid.voxelSize());
  *g->mutable_dims() = dimsOf(q.grid.dims());
  r.set_stencil(stencilOf(q.plan));
  r.set_mode(modeOf(q.plan));
  r.set_sign(signOf(q.plan));
  r.set_encoding(q.encoding);
  r.set_segment_length(q.plan.segment_length_world);
  r.set_limit(q.plan.limit_world);
  r.set_max_batch_bytes(q.batch_bytes);
  r.set_closest_feature(q.plan.closest_features);
  setBox(tile.plan.window, r.mutable_tile()->mutable_window());
  setBox(tile.plan.deliver, r.mutable_tile()->mutable_deliver());
  switch (q.seed_kind) {
    case ResolvedQuery::SeedKind::kPoints: {
      r.mutable_points();  // set even when no point is within reach (then the tile is not sent)
      for (const uint32_t i : tile.point_index) {
        v1::Vec3* v = r.mutable_points()->add_points();
        v->set_x(q.points[i].x);
        v->set_y(q.points[i].y);
        v->set_z(q.points[i].z);
      }
      break;
    }
    case ResolvedQuery::SeedKind::kMesh: r.set_asset_id(mesh_id_); break;
    case ResolvedQuery::SeedKind::kVolume: {
      const auto id = volume_ids_.find(boxKey(tile.plan.window));
      if (id != volume_ids_.end()) {
        r.set_asset_id(id->second.second);
      } else {
        *r.mutable_volume()->mutable_dims() = dimsOf(tile.plan.window.dims);
        r.mutable_volume()->set_mask(cropMask(*q.asset->mask, q.asset->dims, tile.plan.window));
      }
      break;
    }
  }
  return r;
}

namespace {

// Whether a tile's request has anything to compute (else the tile delivers nothing and is not sent).
bool hasWork(const v1::QueryRequest& r, bool signed_volume) {
  switch (r.seeds_case()) {
    case v1::QueryRequest::kPoints: return r.points().points_size() > 0;
    case v1::QueryRequest::kVolume: {
      const std::string& m = r.volume().mask();
      const bool any_seed = std::any_of(m.begin(), m.end(), [](char c) { return c != 0; });
      const bool any_free = std::any_of(m.begin(), m.end(), [](char c) { return c == 0; });
      return any_seed && (any_free || !signed_volume);
    }
    default: return true;
  }
}

}  // namespace

std::vector<bool> TiledQuery::meshReach() const {
  // With a limit, a tile no triangle comes within the limit of delivers nothing: its call is skipped (a surface in
  // a large grid touches few tiles). Each triangle marks the tiles its box, grown by the limit, overlaps.
  std::vector<bool> reach(tiles_.size(), true);
  const double limit = query_.plan.limitVoxels(query_.grid);
  if (query_.seed_kind != ResolvedQuery::SeedKind::kMesh || !std::isfinite(limit) || tiles_.empty()) return reach;
  std::fill(reach.begin(), reach.end(), false);
  // Tiles form a regular lattice (planTiles): the first tile's size is the step, ordered x fastest.
  const Coord step = tiles_[0].plan.deliver.dims, dims = query_.grid.dims();
  const Coord count{(dims.x + step.x - 1) / step.x, (dims.y + step.y - 1) / step.y, (dims.z + step.z - 1) / step.z};
  const TriangleMesh& mesh = *query_.asset->mesh;
  auto range = [&](double lo, double hi, int s, int n, int* a, int* b) {
    *a = int(std::clamp(std::floor((lo - limit - 1) / s), 0.0, double(n - 1)));
    *b = int(std::clamp(std::floor((hi + limit + 1) / s), 0.0, double(n - 1)));
    return hi + limit + 1 >= 0 && lo - limit - 1 <= double(n) * s;
  };
  for (const auto& t : mesh.triangles) {
    const Vec3d a = query_.grid.indexOf(mesh.vertices[t[0]]), b = query_.grid.indexOf(mesh.vertices[t[1]]),
                c = query_.grid.indexOf(mesh.vertices[t[2]]);
    int x0, x1, y0, y1, z0, z1;
    if (!range(std::min({a.x, b.x, c.x}), std::max({a.x, b.x, c.x}), step.x, count.x, &x0, &x1) ||
        !range(std::min({a.y, b.y, c.y}), std::max({a.y, b.y, c.y}), step.y, count.y, &y0, &y1) ||
        !range(std::min({a.z, b.z, c.z}), std::max({a.z, b.z, c.z}), step.z, count.z, &z0, &z1))
      continue;
    for (int z = z0; z <= z1; ++z)
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) reach[(size_t(z) * count.y + y) * count.x + x] = true;
  }
  return reach;
}

TiledQuery::Attempt TiledQuery::runTile(size_t index) {
  Attempt attempt;
  if (!mesh_reach_[index]) return attempt;  // no triangle within the limit: nothing to deliver
  v1::QueryRequest request = tileRequest(tiles_[index]);
  if (!hasWork(request, query_.plan.inside_negative)) return attempt;  // nothing within the limit
  // First attempts go where round_robin sends them; a retry goes to a replica this tile has not failed on.
  std::shared_ptr<v1::DistanceField::Stub> stub;
  std::set<std::string> avoid;
  int attempts;
  {
    std::lock_guard lock(mu_);
    avoid = tiles_[index].failed_on;
    attempts = tiles_[index].attempts;
  }
  if (!avoid.empty()) {
    std::vector<ReplicaPool::Replica> others;
    for (ReplicaPool::Replica& r : config_.pool.replicas())
      if (!avoid.count(r.address)) others.push_back(std::move(r));
    if (!others.empty()) stub = v1::DistanceField::NewStub(others[(index + size_t(attempts)) % others.size()].channel);
  }
  if (!stub) stub = config_.pool.balanced();
  if (!stub) {
    attempt.status = Status::Unavailable(fmt::format("--peers {} resolves to no replica", config_.pool.target()));
    return attempt;
  }
  grpc::ClientContext context;
  config_.pool.prepare(&context, tileDeadline());
  RegisteredCall registered(*this, &context);
  if (stop_.load()) {  // stop() may have cancelled every call just before this one was registered
    attempt.status = Status::Cancelled("stopped");
    return attempt;
  }
  auto reader = stub->Query(&context, request);
  request.Clear();
  v1::QueryReply message;
  while (reader->Read(&message)) {
    std::lock_guard lock(mu_);
    if (stop_.load() || !status_.ok()) {
      context.TryCancel();
      break;
    }
    onMessage(index, message);
  }
  const grpc::Status s = reader->Finish();
  attempt.peer = context.peer();
  std::lock_guard lock(mu_);
  attempt.status = fromGrpcStatus(s);
  attempt.asset_missing = s.error_code() == grpc::StatusCode::NOT_FOUND;
  if (attempt.status.ok() && !tiles_[index].finished)
    attempt.status = Status::Internal("the replica's stream ended without its last segment");
  return attempt;
}

void TiledQuery::onMessage(size_t index, v1::QueryReply& m) {
  Tile& t = tiles_[index];
  switch (m.kind_case()) {
    case v1::QueryReply::kHeader: {
      const v1::Dims& d = m.header().dims();
      if (int(d.x()) != query_.grid.dims().x || int(d.y()) != query_.grid.dims().y || int(d.z()) != query_.grid.dims().z)
        fail(Status::Internal("a replica described a different grid (mixed versions?)"));
      break;
    }
    case v1::QueryReply::kBricks: {
      const uint32_t s = m.bricks().segment();
      if (s < t.completed || s < merged_) break;  // a retry replaying what was already merged
      auto msg = std::make_unique<v1::QueryReply>(std::move(m));
      if (s == merged_) {
        forward(t, std::move(msg));
      } else {
        const uint64_t bytes = msg->ByteSizeLong();
        if (ahead_bytes_ + bytes > config_.options.tile_buffer_bytes) {
          fail(Status::ResourceExhausted(fmt::format(
              "the coordinator would hold more than --tile-buffer-bytes ({}) of later segments while segment {} waits "
              "for slower tiles; use fewer segments (a longer segment_length) or a larger --tile-buffer-bytes",
              humanBytes(config_.options.tile_buffer_bytes), merged_)));
          break;
        }
        ahead_bytes_ += bytes;
        t.ahead_bytes += bytes;
        t.ahead[s].push_back(std::move(msg));
      }
      break;
    }
    case v1::QueryReply::kSegmentDone: {
      const v1::SegmentDone& d = m.segment_done();
      if (d.segment() < t.completed) break;
      t.completed = d.segment() + 1;
      t.segments.resize(t.completed);
      t.segments[d.segment()] = d;
      if (d.last()) {
        t.finished = true;
        t.last = d.segment();
      }
      advance();
      break;
    }
    case v1::QueryReply::kSummary: t.summary = m.summary(); break;
    case v1::QueryReply::KIND_NOT_SET: break;
  }
}

namespace {

// A replica's point ids index the tile's points; the client's index the request's. An id outside the tile's list
// (a faulty replica) becomes -1, which no client takes for a point.
void remapPointIds(const std::vector<uint32_t>& point_index, v1::BrickData* b) {
  std::string& ids = *b->mutable_closest();
  for (size_t at = 0; at + 4 <= ids.size(); at += 4) {
    int32_t id;
    std::memcpy(&id, ids.data() + at, 4);
    id = id >= 0 && size_t(id) < point_index.size() ? int32_t(point_index[size_t(id)]) : -1;
    std::memcpy(ids.data() + at, &id, 4);
  }
}

}  // namespace

void TiledQuery::forward(Tile& t, Message msg) {
  auto* bricks = msg->mutable_bricks()->mutable_bricks();
  if (t.attempts > 0) {  // a retry: skip what the failed attempt already sent
    auto keep = std::remove_if(bricks->begin(), bricks->end(),
                               [&](const v1::BrickData& b) { return t.forwarded.count(brickKey(b)) > 0; });
    bricks->erase(keep, bricks->end());
    if (bricks->empty()) return;
  }
  const bool point_ids = closestOf(query_.plan) == v1::CLOSEST_FEATURE_POINT;
  for (v1::BrickData& b : *bricks) {
    t.forwarded.insert(brickKey(b));
    value_bytes_ += b.values().size() + b.mask().size() + b.closest().size();
    if (point_ids) remapPointIds(t.point_index, &b);
  }
  const uint64_t bytes = msg->ByteSizeLong();
  queue_.push(std::move(msg), bytes);  // blocks while the client reads slowly (every tile then waits: bounded)
}

void TiledQuery::advance() {
  while (!all_sent_ && status_.ok()) {
    bool all_finished = true;
    uint32_t last = 0;
    for (const Tile& t : tiles_) {
      if (!(t.completed > merged_ || t.finished)) return;
      all_finished &= t.finished;
      if (t.finished) last = std::max(last, t.last);
    }
    v1::SegmentDone d;
    d.set_segment(merged_);
    bool have_range = false;
    uint64_t voxels = 0, bricks = 0;
    double compute = 0;
    for (const Tile& t : tiles_) {
      if (t.segments.size() <= merged_) continue;
      const v1::SegmentDone& s = t.segments[merged_];
      if (!have_range) {
        d.set_lower(s.lower());
        d.set_upper(s.upper());
        have_range = true;
      }
      voxels += s.voxels();
      bricks += s.bricks();
      compute += s.compute_seconds();
    }
    if (!have_range) {  // no tile had anything to compute: the protocol still ends with a (empty) segment
      const double length = query_.plan.segment_length_world;
      d.set_lower(length > 0 ? merged_ * length : 0);
      d.set_upper(length > 0 ? std::min((merged_ + 1) * length, query_.plan.limit_world) : query_.plan.limit_world);
    }
    d.set_voxels(voxels);
    d.set_bricks(bricks);
    d.set_compute_seconds(compute);
    const bool is_last = all_finished && merged_ >= last;
    d.set_last(is_last);
    v1::SegmentTiming timing;
    timing.set_segment(merged_);
    timing.set_lower(d.lower());
    timing.set_upper(d.upper());
    timing.set_voxels(voxels);
    timing.set_bricks(bricks);
    timing.set_compute_seconds(compute);
    timing.set_sent_seconds(std::chrono::duration<double>(Clock::now() - started_).count());
    timings_.push_back(timing);
    auto msg = std::make_unique<v1::QueryReply>();
    *msg->mutable_segment_done() = d;
    queue_.push(std::move(msg), 64);
    if (is_last) {
      all_sent_ = true;
      cv_.notify_all();
      return;
    }
    ++merged_;
    for (Tile& t : tiles_) {
      t.forwarded.clear();
      auto it = t.ahead.find(merged_);
      if (it == t.ahead.end()) continue;
      for (Message& m : it->second) {
        const uint64_t bytes = m->ByteSizeLong();
        ahead_bytes_ -= bytes;
        t.ahead_bytes -= bytes;
        forward(t, std::move(m));
      }
      t.ahead.erase(it);
    }
  }
}

void TiledQuery::fail(Status status) {
  if (status_.ok()) status_ = std::move(status);
  cancelCalls();
}

void TiledQuery::worker() {
  for (;;) {
    size_t index;
    int attempts;
    {
      std::unique_lock lock(mu_);
      cv_.wait(lock, [&] { return stop_.load() || !status_.ok() || !pending_.empty() || running_ == 0; });
      if (stop_.load() || !status_.ok() || pending_.empty()) return;
      index = pending_.front();
      pending_.erase(pending_.begin());
      ++running_;
      attempts = tiles_[index].attempts;
    }
    // Back-off before a retry: gRPC's round_robin needs a moment to see that a replica is gone.
    for (int waited = 0; attempts > 0 && waited < 100 * attempts && !stopping(); waited += 5)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    Attempt a;
    if (stopping()) a.status = Status::Cancelled("stopped");
    else a = runTile(index);
    if (a.asset_missing && !stopping()) {
      {
        std::lock_guard lock(mu_);
        uploaded_.clear();
      }
      if (Status s = prepareSeeds(); !s.ok()) a.status = s;
    }
    std::lock_guard lock(mu_);
    --running_;
    Tile& t = tiles_[index];
    if (a.status.ok() || (t.finished && t.last <= merged_)) {  // done, or everything it had to say was merged
      t.finished = true;
      ++done_tiles_;
      advance();
    } else if (!stop_.load() && status_.ok()) {
      // Keep what was merged; what was held for later segments is computed again by the retry.
      ahead_bytes_ -= t.ahead_bytes;
      t.ahead.clear();
      t.ahead_bytes = 0;
      t.finished = false;
      t.completed = std::min(t.completed, merged_ + 1);
      t.segments.resize(t.completed);
      if (!a.peer.empty()) t.failed_on.insert(a.peer);
      if (retriable(a.status.code()) && t.attempts < config_.options.tile_retries) {
        ++t.attempts;
        ++retries_;
        spdlog::warn("coordinator: tile {} attempt {} failed on {} ({} {}); retrying", index, t.attempts,
                     a.peer.empty() ? "?" : a.peer, Status::codeName(a.status.code()), a.status.message());
        pending_.push_back(index);
      } else {
        const VoxelBox& b = t.plan.deliver;
        const std::string what = fmt::format("tile {} (voxels {},{},{} + {}x{}x{}) failed after {} attempts: {} {}",
                                             index, b.min.x, b.min.y, b.min.z, b.dims.x, b.dims.y, b.dims.z,
                                             t.attempts + 1, Status::codeName(a.status.code()), a.status.message());
        fail(retriable(a.status.code()) ? Status::Unavailable(what) : Status::Internal(what));
      }
    }
    cv_.notify_all();
  }
}

void TiledQuery::run() {
  Status status;
  replicas_ = config_.pool.replicas().size();
  {
    std::lock_guard lock(mu_);
    for (const TilePlan& p : plan(query_, config_.options.tile_voxels)) {
      Tile& t = tiles_.emplace_back();
      t.plan = p;
      if (query_.seed_kind != ResolvedQuery::SeedKind::kPoints) continue;
      // Only points that can reach the tile within the limit, in their original order (ties go to the lower index).
      const double reach = query_.plan.limitVoxels(query_.grid) + 1;
      for (size_t i = 0; i < query_.points.size(); ++i)
        if (!std::isfinite(reach) || dist2ToBox(query_.grid.indexOf(query_.points[i]), p.deliver) <= reach * reach)
          t.point_index.push_back(uint32_t(i));
    }
    for (size_t i = 0; i < tiles_.size(); ++i) pending_.push_back(i);
  }
  mesh_reach_ = meshReach();
  if (replicas_ == 0)
    status = Status::Unavailable(fmt::format("--peers {} names no reachable replica", config_.pool.target()));
  if (status.ok()) status = prepareSeeds();
  if (!status.ok()) {
    std::lock_guard lock(mu_);
    fail(status);
  } else {
    // One thread per tile call in flight (the synchronous client API), capped: a headless Service listing hundreds
    // of pods must not turn one query into hundreds of threads.
    const size_t workers = std::min({tiles_.size(), replicas_ * size_t(config_.options.tiles_in_flight_per_replica),
                                     kMaxTileCallsPerQuery});
    std::vector<std::thread> threads;
    for (size_t i = 0; i < workers; ++i) threads.emplace_back([this] { worker(); });
    {
      std::unique_lock lock(mu_);
      while (!(all_sent_ && done_tiles_ == tiles_.size()) && status_.ok() && !stop_.load()) {
        cv_.wait_for(lock, std::chrono::milliseconds(5));
        if (config_.interrupter.interrupted()) {
          stop_.store(true);
          cancelCalls();
        }
        if (running_ == 0 && pending_.empty() && !all_sent_ && status_.ok() && !stop_.load())
          fail(Status::Internal("every tile ended but the merged stream has not (a replica's stream was incomplete)"));
      }
      if (!all_sent_ || !status_.ok()) stop_.store(true);
      cancelCalls();  // none is left after a complete stream
    }
    for (std::thread& t : threads) t.join();
  }
  interrupted_ = config_.interrupter.interrupted();
  stopped_ = Clock::now();
  queue_.close();
}

void TiledQuery::summarize(v1::QuerySummary* s) const {
  std::lock_guard lock(mu_);
  uint64_t voxels = 0, bricks = 0, steps = 0;
  double seeds = 0, compute = 0;
  for (const v1::SegmentTiming& t : timings_) {
    voxels += t.voxels();
    bricks += t.bricks();
  }
  for (const Tile& t : tiles_) {
    steps += t.summary.steps();
    seeds += t.summary.seed_seconds();
    compute += t.summary.compute_seconds();
  }
  s->set_voxels(voxels);
  s->set_bricks(bricks);
  s->set_value_bytes(value_bytes_);
  s->set_steps(uint32_t(std::min<uint64_t>(steps, UINT32_MAX)));
  s->set_seed_seconds(seeds);
  s->set_compute_seconds(compute);
  for (const v1::SegmentTiming& timing : timings_) {
    v1::SegmentTiming* out = s->add_segments();
    *out = timing;
    uint64_t segment_steps = 0;
    for (const Tile& t : tiles_)
      if (t.summary.segments_size() > int(timing.segment())) segment_steps += t.summary.segments(int(timing.segment())).steps();
    out->set_steps(uint32_t(std::min<uint64_t>(segment_steps, UINT32_MAX)));
  }
}

int TiledQuery::tiles() const {
  std::lock_guard lock(mu_);
  return int(tiles_.size());
}

int TiledQuery::retries() const {
  std::lock_guard lock(mu_);
  return retries_;
}

std::string TiledQuery::logStats() const {
  v1::QuerySummary s;
  summarize(&s);
  std::lock_guard lock(mu_);
  return fmt::format("tiles={} replicas={} retries={} segments={} voxels={} bricks={} MB={:.1f} tile_seeds={:.3f}s "
                     "tile_compute={:.3f}s",
                     tiles_.size(), replicas_, retries_, s.segments_size(), s.voxels(), s.bricks(), value_bytes_ / 1e6,
                     s.seed_seconds(), s.compute_seconds());
}

}  // namespace distband

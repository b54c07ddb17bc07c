#include "server/distance_field_service.h"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <new>
#include <optional>
#include <thread>

#include <fmt/format.h>
#include <grpcpp/grpcpp.h>
#include <spdlog/spdlog.h>

#include "core/band/band_engine.h"
#include "server/asset_parsing.h"
#include "server/grpc_status.h"
#include "server/log_line.h"
#include "server/points_fan_out.h"
#include "server/query_job.h"
#include "server/request_validation.h"
#include "server/tiled_query.h"

namespace distband {
namespace {

using Clock = std::chrono::steady_clock;

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

/// A call's log line, opened with its request id (and, when the client's was refused, a note saying so).
LogLine callLine(std::string_view method, const RequestId& rid, std::string_view id_name = {},
                 std::string_view id = {}) {
  LogLine line(method, id_name, id);
  line.text("request_id", rid.id);
  if (rid.replaced) line.flag("request_id_replaced", true);
  return line;
}

/// A query counted as running (admitted, streaming) for its scope.
class RunningQuery {
 public:
  explicit RunningQuery(Metrics& metrics) : metrics_(metrics) { metrics_.queryRunning(1); }
  ~RunningQuery() { metrics_.queryRunning(-1); }
  RunningQuery(const RunningQuery&) = delete;
  RunningQuery& operator=(const RunningQuery&) = delete;

 private:
  Metrics& metrics_;
};

/// Why an upload that ended with `s` was refused; none for a success or a call the client itself ended.
std::optional<UploadRefusal> refusalOf(const Status& s, bool budget_refused) {
  switch (s.code()) {
    case Status::Code::kUnauthenticated: return UploadRefusal::kAuth;
    case Status::Code::kInvalidArgument: return UploadRefusal::kBadInput;
    case Status::Code::kResourceExhausted: return budget_refused ? UploadRefusal::kBudget : UploadRefusal::kLimits;
    default: return std::nullopt;
  }
}

// Arena: `threads - 1` shared workers, plus one reserved slot per concurrent query for the query's own compute
// thread. A query's thread blocked on a slow client thus holds only its own slot; the workers stay available to
// the other queries, and a single query computes on exactly `threads` threads.
std::unique_ptr<tbb::task_arena> makeArena(const ServerOptions& o) {
  const int q = o.max_concurrent_queries;
  return std::make_unique<tbb::task_arena>(q + o.resolvedComputeThreads() - 1, unsigned(q));
}

}  // namespace

MemoryPlan MemoryPlan::of(const ServerOptions& o) {
  MemoryPlan p;
  p.total = o.resolvedMemoryBudget();
  p.baseline = uint64_t(64) << 20;
  p.cache = o.resolvedCacheBytes();
  p.grpc = std::min<uint64_t>(uint64_t(256) << 20, p.total / 16);
  const uint64_t fixed = p.baseline + p.cache + p.grpc;
  p.requests = p.total > fixed ? p.total - fixed : 0;
  return p;
}

DistanceFieldService::DistanceFieldService(const ServerOptions& options, ServerHooks hooks,
                                           std::unique_ptr<TokenAuth> auth, Metrics& metrics)
    : options_(options),
      hooks_(std::move(hooks)),
      auth_(std::move(auth)),
      plan_(MemoryPlan::of(options)),
      metrics_(metrics),
      arena_(makeArena(options)),
      cache_(plan_.cache),
      budget_(plan_.requests),
      slots_(options.max_concurrent_queries),
      calls_(options.max_streams, std::chrono::milliseconds(int64_t(options.idle_timeout_seconds * 1000))) {
  // Read when Prometheus scrapes; the pool (set by connectPeers() before serving) only on a coordinator.
  Metrics::Sources sources;
  sources.streams_open = [this] { return double(calls_.active()); };
  sources.budget_reserved_bytes = [this] { return double(budget_.used()); };
  sources.budget_bytes = [this] { return double(budget_.capacity()); };
  sources.cache_bytes = [this] { return double(cache_.usedBytes()); };
  sources.cache_capacity_bytes = [this] { return double(cache_.capacityBytes()); };
  sources.cache_entries = [this] { return double(cache_.size()); };
  const double threads = options_.resolvedComputeThreads();
  sources.compute_threads = [threads] { return threads; };
  if (!options_.peers.empty()) {
    sources.replicas_known = [this] { return pool_ ? double(pool_->lastReplicaCount()) : 0.0; };
    sources.replicas_healthy = [this] { return pool_ ? double(pool_->healthyReplicas()) : 0.0; };
  }
  metrics_.watch(std::move(sources));
}

DistanceFieldService::~DistanceFieldService() = default;

Status DistanceFieldService::connectPeers() {
  if (options_.peers.empty()) return Status::Ok();
  if (Status s = ReplicaPool::create(options_, &pool_); !s.ok()) return s;
  if (metrics_.on()) {
    pool_->onResolved([this](const std::vector<std::string>& addresses) { metrics_.replicasResolved(addresses); });
    pool_->watchHealth(std::chrono::seconds(2));
  }
  return Status::Ok();
}

void DistanceFieldService::uploadEnded(Rpc rpc, const Status& status, const ActiveCalls::Call* call, uint64_t bytes,
                                       double seconds) {
  if (!metrics_.on()) return;
  metrics_.uploadReceived(rpc, bytes);
  if (auto reason = refusalOf(status, call && call->budgetRefused())) metrics_.uploadRefused(rpc, *reason);
  metrics_.callEnded(rpc, toGrpcCode(status.code()), seconds);
}

Status DistanceFieldService::admitCall(grpc::ServerContext* context, const char* method,
                                       std::unique_ptr<ActiveCalls::Call>* call) {
  if (shutting_down_.load()) return Status::Unavailable("the server is shutting down and accepts no new calls");
  if (auth_)
    if (Status s = auth_->check(*context); !s.ok()) return s;
  return calls_.enter(context, method, call);
}

Status DistanceFieldService::admitWork(grpc::ServerContext* context, ActiveCalls::Call& call, uint64_t bytes,
                                       const std::string& what, MemoryBudget::Reservation* reservation,
                                       ComputeSlot* slot) {
  const auto t0 = Clock::now();
  auto abandon = [&] { return context->IsCancelled() || call.interrupter().interrupted() || shutting_down_.load(); };
  const auto wait = std::chrono::milliseconds(options_.queue_wait_ms);
  if (Status s = budget_.reserve(bytes, what, wait, abandon, reservation); !s.ok()) {
    if (s.code() == Status::Code::kCancelled && call.interrupter().interrupted()) return call.interrupter().status();
    if (s.code() == Status::Code::kResourceExhausted) call.markBudgetRefusal();
    return s;
  }
  const auto left = std::max(std::chrono::milliseconds(0),
                             wait - std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - t0));
  if (!slots_.acquire(left, abandon)) {
    reservation->release();
    if (call.interrupter().interrupted()) return call.interrupter().status();
    if (context->IsCancelled()) return Status::Cancelled("the client cancelled while the call waited for a compute slot");
    if (shutting_down_.load()) return Status::Unavailable("the server is shutting down");
    call.markBudgetRefusal();
    return Status::ResourceExhausted(
        fmt::format("{}: all {} compute slots (--max-queries, concurrent computations) stayed busy for {} ms; retry later", what,
                    options_.max_concurrent_queries, options_.queue_wait_ms));
  }
  slot->slots = &slots_;
  return Status::Ok();
}

Status DistanceFieldService::runCompute(grpc::ServerContext* context, ActiveCalls::Call& call,
                                        const std::function<Status()>& work) {
  std::mutex mu;
  std::condition_variable done_cv;
  bool done = false;
  Status result;
  std::thread compute([&] {
    Status s;
    try {
      arena_->execute([&] { s = work(); });
    } catch (const std::bad_alloc&) {
      s = Status::ResourceExhausted("the server ran out of memory for this request");
    } catch (const std::exception& e) {
      s = Status::Internal(fmt::format("unexpected failure: {}", e.what()));
    }
    std::lock_guard lock(mu);
    result = std::move(s);
    done = true;
    done_cv.notify_all();
  });
  {
    std::unique_lock lock(mu);
    while (!done_cv.wait_for(lock, std::chrono::milliseconds(5), [&] { return done; }))
      if (context->IsCancelled()) call.interrupter().cancel(Status::Code::kCancelled, "the client cancelled the call");
  }
  compute.join();
  if (!result.ok() && call.interrupter().interrupted()) return call.interrupter().status();
  return result;
}

template <typename Chunk>
Status DistanceFieldService::readUpload(grpc::ServerContext* context, grpc::ServerReader<Chunk>* reader,
                                        ActiveCalls::Call& call, const char* what,
                                        const std::function<Status(const Chunk&, uint64_t*)>& on_header,
                                        std::string* data, Chunk* first, MemoryBudget::Reservation* reservation) {
  Chunk chunk;
  bool have_first = false;
  uint64_t expected_bytes = 0;
  auto read = [&] {
    call.waitingForClient(true);
    const bool ok = reader->Read(&chunk);
    call.waitingForClient(false);
    return ok;
  };
  while (read()) {
    if (call.interrupter().interrupted()) return call.interrupter().status();
    if (!have_first) {
      if (!chunk.has_header())
        return Status::InvalidArgument(fmt::format("{}: the first chunk must carry `header`", what));
      *first = chunk;
      first->clear_data();
      have_first = true;
      if (first->header().name().size() > 256)
        return Status::InvalidArgument(fmt::format("{}.header.name must be at most 256 bytes", what));
      if (Status s = on_header(*first, &expected_bytes); !s.ok()) return s;
        } else if (chunk.has_header()) {
      return Status::InvalidArgument(fmt::format("{}: only the first chunk may carry `header`", what));
    }
    const uint64_t size = data->size() + chunk.data().size();
    if (size > options_.max_upload_bytes)
      return Status::ResourceExhausted(
          fmt::format("{}.data: the upload exceeds the server's limit of {} bytes", what, options_.max_upload_bytes));
    if (expected_bytes > 0 && size > expected_bytes)
      return Status::InvalidArgument(
          fmt::format("{}.data: more data arrived ({}+ bytes) than the header declared ({})", what, size, expected_bytes));
    if (size > data->capacity()) {
      // Memory is reserved as bytes arrive, not when they are announced: a client that stalls holds only what it
      // has sent. The buffer grows by half (to the declared size at most); old and new buffers coexist while the
      // bytes move.
      const uint64_t cap = data->capacity();
      const uint64_t bound = expected_bytes > 0 ? expected_bytes : options_.max_upload_bytes;
      const uint64_t grown = std::min<uint64_t>(bound, std::max<uint64_t>(size, cap + cap / 2 + (64 << 10)));
      if (!reservation->held()) budget_.tryReserve(0, reservation);
      if (!reservation->tryGrow(cap + grown - std::min<uint64_t>(reservation->bytes(), cap + grown))) {
        call.markBudgetRefusal();
        return Status::ResourceExhausted(fmt::format(
            "{}.data: the upload has reached {} and needs {} more, but only {} of the server's memory budget is free",
            what, humanBytes(data->size()), humanBytes(grown - cap), humanBytes(budget_.available())));
      }
      data->reserve(grown);
      reservation->shrinkTo(data->capacity());
    }
    data->append(chunk.data());
    chunk.clear_data();
  }
  if (call.interrupter().interrupted()) return call.interrupter().status();
  if (context->IsCancelled()) return Status::Cancelled("the client cancelled the upload");
  if (!have_first) return Status::InvalidArgument(fmt::format("{}: the stream carried no chunk", what));
  return Status::Ok();
}

Status DistanceFieldService::computeAdmitted(grpc::ServerContext* context, ActiveCalls::Call& call, uint64_t bytes,
                                             const std::string& what, const std::function<Status()>& work) {
  MemoryBudget::Reservation memory;
  ComputeSlot slot;
  if (Status s = admitWork(context, call, bytes, what, &memory, &slot); !s.ok()) return s;
  return runCompute(context, call, work);
}

Status DistanceFieldService::parseMeshAdmitted(grpc::ServerContext* context, ActiveCalls::Call& call,
                                               std::string_view bytes, v1::MeshFormat format, const std::string& name,
                                               std::string_view field, std::shared_ptr<const Asset>* asset,
                                               double* parse_seconds) {
  const MeshLimits limits{options_.max_vertices, options_.max_triangles};
  return computeAdmitted(context, call, meshParsePeakBytes(bytes.size()),
                         fmt::format("parsing the mesh ({} bytes)", bytes.size()), [&] {
                           const auto t0 = Clock::now();
                           Status s = parseMeshAsset(bytes, format, name, field, limits, &call.interrupter(), asset);
                           if (parse_seconds) *parse_seconds = since(t0);
                           return s;
                         });
}

Status DistanceFieldService::cacheUpload(const std::shared_ptr<const Asset>& asset, std::string_view field,
                                         std::string_view what) {
  if (cache_.insert(asset)) return Status::Ok();
  return Status::ResourceExhausted(fmt::format("{}: {} needs {} bytes, more than the whole asset cache ({} bytes)",
                                               field, what, asset->memoryBytes(), cache_.capacityBytes()));
}

grpc::Status DistanceFieldService::UploadMesh(grpc::ServerContext* context,
                                              grpc::ServerReader<v1::UploadMeshChunk>* reader,
                                              v1::UploadReply* reply) {
  const auto t0 = Clock::now();
  const RequestId rid = takeRequestId(context);
  const std::string peer = context->peer();
  std::unique_ptr<ActiveCalls::Call> call;
  std::string data;
  v1::UploadMeshChunk first;
  double parse_seconds = -1;
  MemoryBudget::Reservation buffer;
  std::shared_ptr<const Asset> asset;
  bool cached = false;
  Status status = admitCall(context, "UploadMesh", &call);
  const std::function<Status(const v1::UploadMeshChunk&, uint64_t*)> check_header =
      [&](const v1::UploadMeshChunk& c, uint64_t* expected) {
        const v1::UploadMeshHeader& h = c.header();
        if (meshFormatExtension(h.format()).empty())
          return Status::InvalidArgument(fmt::format(
              "UploadMeshChunk.header.format must be MESH_FORMAT_OBJ, _OFF, _PLY or _STL (got {})", int(h.format())));
        if (h.total_bytes() > options_.max_upload_bytes)
          return Status::ResourceExhausted(
              fmt::format("UploadMeshChunk.header.total_bytes: {} bytes exceed the server's upload limit of {}",
                          h.total_bytes(), options_.max_upload_bytes));
        *expected = h.total_bytes();
        return Status::Ok();
      };
  if (status.ok()) status = readUpload(context, reader, *call, "UploadMeshChunk", check_header, &data, &first, &buffer);
  const v1::UploadMeshHeader& h = first.header();
  if (status.ok() && h.total_bytes() != 0 && h.total_bytes() != data.size())
    status = Status::InvalidArgument(fmt::format("UploadMeshChunk.header.total_bytes is {} but {} data bytes arrived",
                                                 h.total_bytes(), data.size()));
  if (status.ok() && data.empty()) status = Status::InvalidArgument("UploadMeshChunk.data: the mesh data is empty");
  if (status.ok()) {
    if ((asset = cache_.find(meshAssetId(data, h.format())))) {
      cached = true;
    } else {
      status = parseMeshAdmitted(context, *call, data, h.format(), h.name(), "UploadMeshChunk.data", &asset,
                                 &parse_seconds);
      if (parse_seconds >= 0) metrics_.uploadParsed(Rpc::kUploadMesh, parse_seconds);
      if (status.ok()) status = cacheUpload(asset, "UploadMeshChunk.data", "the parsed mesh");
    }
  }
  if (status.ok()) {
    reply->set_asset_id(asset->id);
    reply->set_bytes(data.size());
    reply->set_already_cached(cached);
    const MeshReport& r = asset->mesh_report;
    v1::MeshStats* m = reply->mutable_mesh();
    m->set_vertices(uint64_t(r.vertices));
    m->set_triangles(uint64_t(r.triangles));
    m->set_degenerate_triangles(uint64_t(r.degenerate));
    m->set_boundary_edges(uint64_t(r.boundary_edges));
    m->set_reoriented_faces(uint64_t(r.reoriented_faces));
    for (auto [dst, src] : {std::pair{m->mutable_bounds()->mutable_min(), r.bbox_min},
                            std::pair{m->mutable_bounds()->mutable_max(), r.bbox_max}}) {
      dst->set_x(src.x);
      dst->set_y(src.y);
      dst->set_z(src.z);
    }
  }
  const double seconds = since(t0);
  callLine("UploadMesh", rid)
      .text("peer", peer)
      .quoted("name", logSafe(h.name()))
      .number("bytes", uint64_t(data.size()))
      .text("id", asset ? asset->id.substr(0, 17) : "-")
      .flag("cached", cached)
      .text("mesh", "[" + (asset ? asset->mesh_report.summary() : std::string()) + "]")
      .seconds("time", seconds)
      .status(status)
      .write();
  uploadEnded(Rpc::kUploadMesh, status, call.get(), data.size(), seconds);
  return toGrpcStatus(status);
}

grpc::Status DistanceFieldService::UploadVolume(grpc::ServerContext* context,
                                                grpc::ServerReader<v1::UploadVolumeChunk>* reader,
                                                v1::UploadReply* reply) {
  const auto t0 = Clock::now();
  const RequestId rid = takeRequestId(context);
  const std::string peer = context->peer();
  std::unique_ptr<ActiveCalls::Call> call;
  std::string data;
  uint64_t received = 0;  // `data` moves into the parse
  v1::UploadVolumeChunk first;
  MemoryBudget::Reservation buffer;
  std::shared_ptr<const Asset> asset;
  bool cached = false;
  Status status = admitCall(context, "UploadVolume", &call);
  // A volume's size follows from its dims: they are checked on the first chunk, before anything is buffered.
  const std::function<Status(const v1::UploadVolumeChunk&, uint64_t*)> check_header =
      [&](const v1::UploadVolumeChunk& c, uint64_t* expected) {
        const v1::UploadVolumeHeader& h = c.header();
        if (!h.has_dims()) return Status::InvalidArgument("UploadVolumeChunk.header.dims must be set");
        if (Status s = checkDims(h.dims(), "UploadVolumeChunk.header.dims"); !s.ok()) return s;
        VoxelType type;
        if (!voxelTypeOf(h.element_type(), &type))
          return Status::InvalidArgument(fmt::format(
              "UploadVolumeChunk.header.element_type must be a VoxelType value 0..3 (got {})", int(h.element_type())));
        const uint64_t voxels = uint64_t(h.dims().x()) * h.dims().y() * h.dims().z();
        const uint64_t limit = std::min(options_.max_voxels_per_query, options_.max_upload_bytes);
        if (voxels > limit)
          return Status::ResourceExhausted(fmt::format(
              "UploadVolumeChunk.header.dims: {}x{}x{} = {} voxels exceeds the server's limit of {} (--max-voxels, "
              "--max-upload-bytes)",
              h.dims().x(), h.dims().y(), h.dims().z(), voxels, limit));
        *expected = voxels * voxelTypeBytes(type);
        return Status::Ok();
      };
  if (status.ok())
    status = readUpload(context, reader, *call, "UploadVolumeChunk", check_header, &data, &first, &buffer);
  const v1::UploadVolumeHeader& h = first.header();
  received = data.size();
  if (status.ok()) {
    VoxelType type = VoxelType::kUint8;
    voxelTypeOf(h.element_type(), &type);  // checked with the header
    if ((asset = cache_.find(volumeAssetId(h.dims(), type, data)))) {
      cached = true;
    } else {
      double parse_seconds = -1;
      status = computeAdmitted(context, *call, volumeParsePeakBytes(data.size()),
                               fmt::format("analysing the volume ({} voxels)", data.size()), [&] {
                                 const auto p0 = Clock::now();
                                 Status s = parseVolumeAsset(h.dims(), h.element_type(), std::move(data), h.name(),
                                                             "UploadVolumeChunk.header", options_.max_voxels_per_query,
                                                             &call->interrupter(), &asset);
                                 parse_seconds = since(p0);
                                 return s;
                               });
      if (parse_seconds >= 0) metrics_.uploadParsed(Rpc::kUploadVolume, parse_seconds);
      if (status.ok()) status = cacheUpload(asset, "UploadVolumeChunk.data", "the volume");
    }
  }
  if (status.ok()) {
    reply->set_asset_id(asset->id);
    reply->set_bytes(asset->volume.bytes().size());
    reply->set_already_cached(cached);
    reply->mutable_volume_dims()->set_x(uint32_t(asset->volume.dims().x));
    reply->mutable_volume_dims()->set_y(uint32_t(asset->volume.dims().y));
    reply->mutable_volume_dims()->set_z(uint32_t(asset->volume.dims().z));
  }
  const double seconds = since(t0);
  callLine("UploadVolume", rid)
      .text("peer", peer)
      .quoted("name", logSafe(h.name()))
      .text("dims", fmt::format("{}x{}x{}", h.dims().x(), h.dims().y(), h.dims().z()))
      .text("id", asset ? asset->id.substr(0, 19) : "-")
      .flag("cached", cached)
      .seconds("time", seconds)
      .status(status)
      .write();
  uploadEnded(Rpc::kUploadVolume, status, call.get(), received, seconds);
  return toGrpcStatus(status);
}

grpc::Status DistanceFieldService::GetInfo(grpc::ServerContext* context, const v1::GetInfoRequest*,
                                           v1::ServerInfo* r) {
  const auto t0 = Clock::now();
  const RequestId rid = takeRequestId(context);
  std::unique_ptr<ActiveCalls::Call> call;
  if (Status s = admitCall(context, "GetInfo", &call); !s.ok()) {
    callLine("GetInfo", rid).text("peer", context->peer()).status(s).write();
    metrics_.callEnded(Rpc::kGetInfo, toGrpcCode(s.code()), since(t0));
    return toGrpcStatus(s);
  }
  r->set_version(DISTBAND_VERSION);
  r->set_compute_threads(uint32_t(options_.resolvedComputeThreads()));
  r->set_max_concurrent_queries(uint32_t(options_.max_concurrent_queries));
  r->set_max_voxels_per_query(options_.max_voxels_per_query);
  r->set_max_upload_bytes(options_.max_upload_bytes);
  r->set_cache_bytes(cache_.capacityBytes());
  r->set_cache_used_bytes(cache_.usedBytes());
  r->set_max_message_bytes(options_.max_message_bytes);
  for (const char* s : {"cubic6", "cubic18", "cubic26", "fcc12"}) r->add_stencils(s);
  for (const char* s : {"paper", "exact"}) r->add_modes(s);
  for (const char* s : {"auto", "unsigned", "pseudonormal", "winding", "parity", "mask_inside"}) r->add_sign_modes(s);
  for (const char* s : {"obj", "off", "ply", "stl"}) r->add_mesh_formats(s);
  for (const char* s : {"float32", "float16"}) r->add_encodings(s);
  r->set_active_queries(uint32_t(slots_.active()));
  r->set_mesh_support(true);
  r->set_memory_budget_bytes(budget_.capacity());
  r->set_memory_available_bytes(budget_.available());
  r->set_max_streams(uint32_t(options_.max_streams));
  r->set_max_chunk_points(uint32_t(kMaxChunkPoints));
  r->set_idle_timeout_seconds(options_.idle_timeout_seconds);
  r->set_max_triangles(options_.max_triangles);
  r->set_max_vertices(options_.max_vertices);
  r->set_auth_required(auth_ != nullptr);
  if (pool_) {
    r->set_replicas(uint32_t(pool_->replicas().size()));
    r->set_tile_voxels(options_.tile_voxels);
  }
  callLine("GetInfo", rid).text("peer", context->peer()).status(Status::Ok()).write();
  metrics_.callEnded(Rpc::kGetInfo, grpc::StatusCode::OK, since(t0));
  return grpc::Status::OK;
}

grpc::Status DistanceFieldService::Query(grpc::ServerContext* context, const v1::QueryRequest* request,
                                         grpc::ServerWriter<v1::QueryReply>* writer) {
  QueryRecord record;
  record.received = Clock::now();
  record.id = fmt::format("q{}", next_query_.fetch_add(1));
  const RequestId rid = takeRequestId(context);
  record.request_id = rid.id;
  std::unique_ptr<ActiveCalls::Call> call;
  Status status = admitCall(context, "Query", &call);
  if (status.ok()) {
    status = runQuery(context, *call, *request, writer, rid, &record);
  } else {
    callLine("Query", rid, "query", record.id).text("peer", context->peer()).status(status).write();
  }
  record.code = toGrpcCode(status.code());
  record.message = status.message();
  record.finished = Clock::now();
  metrics_.callEnded(Rpc::kQuery, record.code,
                     std::chrono::duration<double>(record.finished - record.received).count());
  if (hooks_.on_query_end) hooks_.on_query_end(record);
  return toGrpcStatus(status);
}

Status DistanceFieldService::runQuery(grpc::ServerContext* context, ActiveCalls::Call& call,
                                      const v1::QueryRequest& request, grpc::ServerWriter<v1::QueryReply>* writer,
                                      const RequestId& rid, QueryRecord* record) {
  const auto t0 = record->received;
  const std::string peer = context->peer();
  Interrupter& interrupter = call.interrupter();
  ResolvedQuery q;
  // What the log line shows (copied: `q` moves into the job).
  std::string label = "-";
  Grid grid;
  double limit = 0, segment = 0;
  std::string window;  // a tile's
  auto log = [&](const Status& s, const std::function<void(LogLine&)>& extra) {
    LogLine line = callLine("Query", rid, "query", record->id);
    line.text("peer", peer).text("seeds", label);
    if (!window.empty()) line.text("tile_window", window);
    line.text("grid", fmt::format("{}x{}x{}", grid.dims().x, grid.dims().y, grid.dims().z))
        .real("h", grid.voxelSize())
        .real("limit", limit)
        .real("segment", segment);
    if (extra) extra(line);
    line.seconds("time", since(t0)).status(s).write();
    return s;
  };

  // Validation (and, for an inline mesh, its parse under admission) before any other work.
  std::shared_ptr<const Asset> inline_mesh;
  if (pool_ && request.has_tile())
    return log(Status::InvalidArgument("tile: this server is a coordinator and makes its own tiles; send tiles to a "
                                       "replica, or the whole query here"),
               {});
  if (Status s = checkInlineMesh(request, options_); !s.ok()) return log(s, {});
  if (request.seeds_case() == v1::QueryRequest::kMesh)
    if (Status s = parseMeshAdmitted(context, call, request.mesh().data(), request.mesh().format(), "inline mesh",
                                     "mesh", &inline_mesh, nullptr);
        !s.ok())
      return log(s, {});
  if (Status s = resolveQuery(request, options_, cache_, std::move(inline_mesh), &q); !s.ok()) return log(s, {});
  label = q.seeds_label;
  if (q.tile)
    window = fmt::format("{}x{}x{}@{},{},{}", q.tile->window.dims.x, q.tile->window.dims.y, q.tile->window.dims.z,
                         q.tile->window.min.x, q.tile->window.min.y, q.tile->window.min.z);
  grid = q.grid;
  limit = q.plan.limit_world;
  segment = q.plan.segment_length_world;

  // Admission: the estimated peak (seeds, engine, one output chunk, the stream buffer) and a compute slot.
  // A coordinator computes nothing itself: it holds its stream buffer and the later segments it may buffer.
  const uint64_t peak =
      pool_ ? TiledQuery::reservedBytes(options_) : q.memory.total() + options_.stream_buffer_bytes;
  MemoryBudget::Reservation memory;
  ComputeSlot slot;
  const std::string what = fmt::format("the query ({}x{}x{} voxels, at most {} within the limit; {})", grid.dims().x,
                                       grid.dims().y, grid.dims().z, q.touched_voxels_bound, q.memory.summary());
  const auto admission_began = Clock::now();
  metrics_.queryQueued(1);
  Status admitted = admitWork(context, call, peak, what, &memory, &slot);
  metrics_.queryQueued(-1);
  metrics_.queryAdmitted(since(admission_began));
  if (!admitted.ok()) return log(admitted, {});
  const RunningQuery running(metrics_);
  record->reserved_bytes = memory.bytes();
  const double queue_seconds = since(t0);

  bool sent_bricks = false;
  auto write = [&](const v1::QueryReply& m) {
    call.waitingForClient(true);
    const bool ok = writer->Write(m);
    call.waitingForClient(false);
    if (ok && metrics_.on()) {
      metrics_.querySentBytes(uint64_t(m.GetCachedSize()));  // sized when gRPC serialized it
      if (!sent_bricks && m.has_bricks()) {
        sent_bricks = true;
        metrics_.queryFirstBrick(since(t0));
      }
    }
    return ok;
  };
  {
    v1::QueryReply header;
    fillQueryHeader(q, record->id, header.mutable_header());
    if (!write(header))
      return log(interrupter.interrupted() ? interrupter.status() : Status::Cancelled("the client went away"), {});
  }
  std::unique_ptr<QueryStream> job;
  if (pool_) {
    TiledQuery::Config config{options_, *pool_, call.interrupter(), context->deadline(), metrics_, rid.id};
    job = std::make_unique<TiledQuery>(std::move(q), config);
  } else {
    job = std::make_unique<QueryJob>(std::move(q), arena_.get(), options_.stream_buffer_bytes, &interrupter);
  }
  job->start();
  record->engine_ran = true;
  uint64_t messages = 1;
  QueryStream::Message msg;
  for (;;) {
    const auto r = job->queue().pop(&msg, std::chrono::milliseconds(5));
    if (r == BoundedQueue<QueryStream::Message>::PopResult::kClosed) break;
    if (r == BoundedQueue<QueryStream::Message>::PopResult::kItem) {
      if (write(*msg)) ++messages;
      else interrupter.cancel(Status::Code::kCancelled, "the client went away");
      msg.reset();
    }
    if (!interrupter.interrupted() && context->IsCancelled())
      interrupter.cancel(Status::Code::kCancelled, "the client cancelled the query");
    if (interrupter.interrupted()) {
      record->cancel_seen = Clock::now();
      job->stop();
      break;
    }
  }
  job->join();
  v1::QueryReply reply;
  v1::QuerySummary* s = reply.mutable_summary();
  job->summarize(s);
  record->engine_stopped = job->stopped();
  record->interrupted = job->interrupted() || interrupter.interrupted();
  record->voxels = s->voxels();
  record->bricks = s->bricks();
  record->messages = messages;
  record->bytes = s->value_bytes();
  record->segments = s->segments_size();
  record->tiles = job->tiles();
  record->tile_retries = job->retries();
  metrics_.querySentVoxels(s->voxels());
  const auto stats = [&](LogLine& line) {
    job->logStats(line);
    line.number("messages", messages).text("reserved", humanBytes(memory.bytes()));
  };
  if (interrupter.interrupted()) {
    if (record->cancel_seen == Clock::time_point{}) record->cancel_seen = Clock::now();
    const double stop_ms =
        std::chrono::duration<double, std::milli>(record->engine_stopped - record->cancel_seen).count();
    return log(interrupter.status(), [&](LogLine& line) {
      stats(line);
      line.real("engine_stop_after_cancel", stop_ms, "{:.1f}ms");
    });
  }
  if (!job->status().ok()) return log(job->status(), stats);
  if (!pool_) metrics_.queryComputed(s->seed_seconds(), s->compute_seconds());

  s->set_messages(messages + 1);
  s->set_queue_seconds(queue_seconds);
  s->set_total_seconds(since(t0));
  if (!write(reply))
    return log(interrupter.interrupted() ? interrupter.status() : Status::Cancelled("the client went away"), stats);
  return log(Status::Ok(), stats);
}

grpc::Status DistanceFieldService::QueryPoints(grpc::ServerContext* context,
                                               grpc::ServerReaderWriter<v1::PointsReply, v1::PointsRequest>* stream) {
  const auto t0 = Clock::now();
  const std::string id = fmt::format("p{}", next_query_.fetch_add(1));
  const RequestId rid = takeRequestId(context);
  std::unique_ptr<ActiveCalls::Call> call;
  Status status = admitCall(context, "QueryPoints", &call);
  if (status.ok()) {
    status = runPoints(context, *call, stream, rid, id);
  } else {
    callLine("QueryPoints", rid, "query", id).text("peer", context->peer()).status(status).write();
  }
  metrics_.callEnded(Rpc::kQueryPoints, toGrpcCode(status.code()), since(t0));
  return toGrpcStatus(status);
}

Status DistanceFieldService::runPoints(grpc::ServerContext* context, ActiveCalls::Call& call,
                                       grpc::ServerReaderWriter<v1::PointsReply, v1::PointsRequest>* stream,
                                       const RequestId& rid, const std::string& id) {
  const auto t0 = Clock::now();
  Interrupter& interrupter = call.interrupter();
  std::string label = "-";
  std::string_view search_state = "-";  // "built" or "cached" once the search is ready
  uint64_t points = 0, chunks = 0, beyond = 0;
  std::optional<uint64_t> replicas;  // a coordinator's: the replica streams the chunks went to
  auto log = [&](const Status& s) {
    LogLine line = callLine("QueryPoints", rid, "query", id);
    line.text("peer", context->peer()).text("seeds", label).number("points", points).number("chunks", chunks);
    if (replicas)
      line.number("replicas", *replicas);
    else
      line.text("search", search_state);
    line.seconds("time", since(t0)).status(s).write();
    return s;
  };
  auto gone = [&] {
    if (interrupter.interrupted()) return interrupter.status();
    if (context->IsCancelled()) return Status::Cancelled("the client cancelled the call");
    return Status::Cancelled("the client went away");
  };
  v1::PointsRequest request;
  auto read = [&] {
    call.waitingForClient(true);
    const bool ok = stream->Read(&request);
    call.waitingForClient(false);
    return ok;
  };
  auto write = [&](const v1::PointsReply& m) {
    call.waitingForClient(true);
    const bool ok = stream->Write(m);
    call.waitingForClient(false);
    return ok;
  };

  // The header, validated (an inline mesh parsed under admission) before any other work.
  if (!read()) return log(gone());
  if (request.kind_case() != v1::PointsRequest::kHeader)
    return log(Status::InvalidArgument("header: the first message of a QueryPoints stream must be a header"));
  const v1::PointsHeader header = request.header();
  std::shared_ptr<const Asset> inline_mesh;
  if (Status s = checkInlineMesh(header, options_); !s.ok()) return log(s.withPrefix("header"));
  if (header.seeds_case() == v1::PointsHeader::kMesh)
    if (Status s = parseMeshAdmitted(context, call, header.mesh().data(), header.mesh().format(), "inline mesh",
                                     "header.mesh", &inline_mesh, nullptr);
        !s.ok())
      return log(s);
  ResolvedPoints p;
  if (Status s = resolvePointsHeader(header, options_, cache_, std::move(inline_mesh), &p); !s.ok())
    return log(s.code() == Status::Code::kInvalidArgument ? s.withPrefix("header") : s);
  label = p.seeds_label;
  if (pool_) {
    // A coordinator: the chunks fan out to the replicas (server/points_fan_out.h), admitted with what it holds of
    // their results.
    const size_t streams = PointsFanOut::streamsFor(pool_->replicas().size());
    MemoryBudget::Reservation memory;
    ComputeSlot slot;
    if (Status s =
            admitWork(context, call, PointsFanOut::reservedBytes(p, streams),
                      fmt::format("the point query on {} over {} replicas", p.seeds_label, streams), &memory, &slot);
        !s.ok())
      return log(s);
    const double queue_seconds = since(t0);
    PointsFanOut fan_out(p, {options_, *pool_, interrupter, *context, *stream,
                             [&call](bool waiting) { call.waitingForClient(waiting); }, rid.id});
    v1::PointsReply reply;
    fillPointsHeader(p, id, reply.mutable_header());
    Status s = fan_out.open(reply.header());
    if (s.ok()) s = fan_out.serve();
    points = fan_out.points();
    chunks = fan_out.chunks();
    replicas = fan_out.streams();
    if (!s.ok()) return log(s);
    reply.Clear();
    v1::PointsSummary* summary = reply.mutable_summary();
    fan_out.summarize(summary);
    summary->set_queue_seconds(queue_seconds + summary->queue_seconds());
    summary->set_total_seconds(since(t0));
    if (!write(reply)) return log(gone());
    return log(Status::Ok());
  }

  // Admission: the search's peak bytes and one chunk's buffers (the points, the results, the packed reply).
  const uint64_t chunk_bytes = uint64_t(kMaxChunkPoints) * (24 + 8 + 24 + 8 + 24) * 2;
  // The search: the parts a cached asset keeps, completed with what this plan still needs (then kept for the next).
  PointSearch search = p.cached ? p.asset->search_parts->forPlan(p.plan) : PointSearch{};
  const uint64_t peak = pointSearchBytes(p.plan, p.counts, search) + chunk_bytes + options_.stream_buffer_bytes;
  MemoryBudget::Reservation memory;
  ComputeSlot slot;
  if (Status s = admitWork(context, call, peak, fmt::format("the point query on {}", p.seeds_label), &memory, &slot);
      !s.ok())
    return log(s);
  const double queue_seconds = since(t0);
  const auto t_search = Clock::now();
  PointSeedSource source;
  if (p.seed_kind == SeedKind::kMesh) {
    source.mesh = p.asset->mesh.get();
  } else if (p.seed_kind == SeedKind::kVolume) {
    source.mask = p.asset->volume.seedMask();
    source.lattice = p.lattice;
  } else {
    source.points = &p.points;
  }
  const PointSearch kept = search;
  if (Status s = runCompute(context, call, [&] { return completePointSearch(p.plan, source, &interrupter, &search); });
      !s.ok())
    return log(s);
  const double search_seconds = since(t_search);
  const bool search_cached = search.mesh == kept.mesh && search.sign == kept.sign && search.far_sign == kept.far_sign &&
                             search.points == kept.points && search.volume == kept.volume;
  if (p.cached && !search_cached) cache_.keepSearchParts(p.asset, search);
  search_state = search_cached ? "cached" : "built";
  {
    v1::PointsReply reply;
    fillPointsHeader(p, id, reply.mutable_header());
    if (!write(reply)) return log(gone());
  }

  // The chunks, one at a time: read, decoded, computed, answered.
  const v1::ValueType type = p.packing.doubles ? v1::VALUE_TYPE_FLOAT64 : v1::VALUE_TYPE_FLOAT32;
  std::vector<Vec3d> at;
  PointResultBuffer results;
  double compute_seconds = 0;
  v1::PointsReply reply;
  while (read()) {
    if (request.kind_case() != v1::PointsRequest::kChunk)
      return log(Status::InvalidArgument(fmt::format("chunk {}: only the first message may be a header", chunks)));
    if (Status s = decodePointsChunk(request.chunk(), type, chunks, points, &at); !s.ok()) return log(s);
    results.resize(at.size(), p.outputs);
    const auto t_chunk = Clock::now();
    if (Status s = runCompute(context, call,
                              [&] {
                                return queryPoints(search, at.data(), at.size(), p.plan.queryOptions(&interrupter),
                                                   results.results());
                              });
        !s.ok())
      return log(s);
    compute_seconds += since(t_chunk);
    const double* d = results.results().distance;
    for (size_t i = 0; i < at.size(); ++i) beyond += std::abs(d[i]) >= p.plan.limit_world;
    v1::PointsResults* r = reply.mutable_results();
    r->set_chunk(chunks);
    r->set_first_point(points);
    r->set_points(uint32_t(at.size()));
    results.packDistance(p.packing, r->mutable_distance());
    results.packClosestPoints(p.packing, r->mutable_closest_points());
    results.packFeatures(p.packing, r->mutable_closest_feature());
    results.packGradients(p.packing, r->mutable_gradient());
    if (!write(reply)) return log(gone());
    ++chunks;
    points += at.size();
  }
  if (interrupter.interrupted() || context->IsCancelled()) return log(gone());
  reply.Clear();
  v1::PointsSummary* s = reply.mutable_summary();
  s->set_points(points);
  s->set_chunks(chunks);
  s->set_beyond_limit(beyond);
  s->set_search_cached(search_cached);
  s->set_search_seconds(search_seconds);
  s->set_compute_seconds(compute_seconds);
  s->set_queue_seconds(queue_seconds);
  s->set_total_seconds(since(t0));
  if (!write(reply)) return log(gone());
  return log(Status::Ok());
}

}  // namespace distband

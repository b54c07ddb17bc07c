#include "server/distance_field_service.h"

#include <chrono>

#include <fmt/format.h>
#include <grpcpp/grpcpp.h>
#include <spdlog/spdlog.h>

#include "core/engine.h"
#include "server/asset_parsing.h"
#include "server/query_job.h"
#include "server/request_validation.h"

namespace distband {
namespace {

using Clock = std::chrono::steady_clock;

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

const char* codeName(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK: return "OK";
    case grpc::StatusCode::CANCELLED: return "CANCELLED";
    case grpc::StatusCode::INVALID_ARGUMENT: return "INVALID_ARGUMENT";
    case grpc::StatusCode::DEADLINE_EXCEEDED: return "DEADLINE_EXCEEDED";
    case grpc::StatusCode::NOT_FOUND: return "NOT_FOUND";
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return "RESOURCE_EXHAUSTED";
    case grpc::StatusCode::UNAVAILABLE: return "UNAVAILABLE";
    case grpc::StatusCode::INTERNAL: return "INTERNAL";
    default: return "ERROR";
  }
}

std::string statusText(const grpc::Status& s) {
  return s.ok() ? "OK" : fmt::format("{} \"{}\"", codeName(s.error_code()), s.error_message());
}

// Arena: `threads - 1` shared workers, plus one reserved slot per concurrent query for the query's own compute
// thread. A query's thread blocked on a slow client thus holds only its own slot; the workers stay available to
// the other queries, and a single query computes on exactly `threads` threads.
std::unique_ptr<tbb::task_arena> makeArena(const ServerOptions& o) {
  const int q = o.max_concurrent_queries;
  return std::make_unique<tbb::task_arena>(q + o.resolvedComputeThreads() - 1, unsigned(q));
}

}  // namespace

DistanceFieldService::DistanceFieldService(const ServerOptions& options, ServerHooks hooks)
    : options_(options),
      hooks_(std::move(hooks)),
      arena_(makeArena(options)),
      cache_(options.cache_bytes),
      slots_(options.max_concurrent_queries) {}

DistanceFieldService::~DistanceFieldService() = default;

template <typename Chunk>
grpc::Status DistanceFieldService::readUpload(grpc::ServerContext* context, grpc::ServerReader<Chunk>* reader,
                                              std::string* data, Chunk* first, const char* what) {
  if (shutting_down_.load()) return {grpc::StatusCode::UNAVAILABLE, "the server is shutting down"};
  Chunk chunk;
  bool have_first = false;
  while (reader->Read(&chunk)) {
    if (!have_first) {
      if (!chunk.has_header())
        return {grpc::StatusCode::INVALID_ARGUMENT, fmt::format("{}: the first chunk must carry `header`", what)};
      *first = chunk;
      first->clear_data();
      have_first = true;
    } else if (chunk.has_header()) {
      return {grpc::StatusCode::INVALID_ARGUMENT,
              fmt::format("{}: only the first chunk may carry `header`", what)};
    }
    if (data->size() + chunk.data().size() > options_.max_upload_bytes)
      return {grpc::StatusCode::RESOURCE_EXHAUSTED,
              fmt::format("{}.data: the upload exceeds the server's limit of {} bytes", what,
                          options_.max_upload_bytes)};
    data->append(chunk.data());
  }
  if (context->IsCancelled()) return {grpc::StatusCode::CANCELLED, "the client cancelled the upload"};
  if (!have_first)
    return {grpc::StatusCode::INVALID_ARGUMENT, fmt::format("{}: the stream carried no chunk", what)};
  if (first->header().name().size() > 256)
    return {grpc::StatusCode::INVALID_ARGUMENT, fmt::format("{}.header.name must be at most 256 bytes", what)};
  return grpc::Status::OK;
}

grpc::Status DistanceFieldService::UploadMesh(grpc::ServerContext* context,
                                              grpc::ServerReader<v1::UploadMeshChunk>* reader,
                                              v1::UploadReply* reply) {
  const auto t0 = Clock::now();
  std::string data;
  v1::UploadMeshChunk first;
  grpc::Status status = readUpload(context, reader, &data, &first, "UploadMeshChunk");
  std::shared_ptr<const Asset> asset;
  bool cached = false;
  if (status.ok() && first.header().total_bytes() != 0 && first.header().total_bytes() != data.size())
    status = {grpc::StatusCode::INVALID_ARGUMENT,
              fmt::format("UploadMeshChunk.header.total_bytes is {} but {} data bytes arrived",
                          first.header().total_bytes(), data.size())};
  if (status.ok()) {
    if (meshFormatExtension(first.header().format()).empty()) {
      status = {grpc::StatusCode::INVALID_ARGUMENT,
                fmt::format("UploadMeshChunk.header.format must be MESH_FORMAT_OBJ, _OFF, _PLY or _STL (got {})",
                            int(first.header().format()))};
    } else if ((asset = cache_.find(meshAssetId(data, first.header().format())))) {
      cached = true;
    } else {
      status = parseMeshAsset(data, first.header().format(), first.header().name(), "UploadMeshChunk.data", &asset);
      if (status.ok() && !cache_.insert(asset))
        status = {grpc::StatusCode::RESOURCE_EXHAUSTED,
                  fmt::format("UploadMeshChunk.data: the parsed mesh needs {} bytes, more than the whole asset "
                              "cache ({} bytes)", asset->memoryBytes(), cache_.capacityBytes())};
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
    for (auto [dst, src] : {std::pair{m->mutable_bounds()->mutable_min(), r.bbox_min},
                            std::pair{m->mutable_bounds()->mutable_max(), r.bbox_max}}) {
      dst->set_x(src.x);
      dst->set_y(src.y);
      dst->set_z(src.z);
    }
  }
  spdlog::info("UploadMesh peer={} name='{}' bytes={} id={} cached={} mesh=[{}] time={:.3f}s status={}",
               context->peer(), first.header().name(), data.size(), asset ? asset->id.substr(0, 17) : "-", cached,
               asset ? asset->mesh_report.summary() : "", since(t0), statusText(status));
  return status;
}

grpc::Status DistanceFieldService::UploadVolume(grpc::ServerContext* context,
                                                grpc::ServerReader<v1::UploadVolumeChunk>* reader,
                                                v1::UploadReply* reply) {
  const auto t0 = Clock::now();
  std::string data;
  v1::UploadVolumeChunk first;
  grpc::Status status = readUpload(context, reader, &data, &first, "UploadVolumeChunk");
  std::shared_ptr<const Asset> asset;
  bool cached = false;
  if (status.ok()) {
    if (!first.header().has_dims()) {
      status = {grpc::StatusCode::INVALID_ARGUMENT, "UploadVolumeChunk.header.dims must be set"};
    } else if ((asset = cache_.find(volumeAssetId(first.header().dims(), data)))) {
      cached = true;
    } else {
      status = parseVolumeAsset(first.header().dims(), std::move(data), first.header().name(),
                                "UploadVolumeChunk.header", options_.max_voxels_per_query, &asset);
      if (status.ok() && !cache_.insert(asset))
        status = {grpc::StatusCode::RESOURCE_EXHAUSTED,
                  fmt::format("UploadVolumeChunk.data: the volume needs {} bytes, more than the whole asset cache "
                              "({} bytes)", asset->memoryBytes(), cache_.capacityBytes())};
    }
  }
  if (status.ok()) {
    reply->set_asset_id(asset->id);
    reply->set_bytes(asset->mask->size());
    reply->set_already_cached(cached);
    reply->mutable_volume_dims()->set_x(uint32_t(asset->dims.x));
    reply->mutable_volume_dims()->set_y(uint32_t(asset->dims.y));
    reply->mutable_volume_dims()->set_z(uint32_t(asset->dims.z));
  }
  spdlog::info("UploadVolume peer={} name='{}' dims={}x{}x{} id={} cached={} time={:.3f}s status={}",
               context->peer(), first.header().name(), first.header().dims().x(), first.header().dims().y(),
               first.header().dims().z(), asset ? asset->id.substr(0, 19) : "-", cached, since(t0),
               statusText(status));
  return status;
}

grpc::Status DistanceFieldService::GetInfo(grpc::ServerContext* context, const v1::GetInfoRequest*,
                                           v1::ServerInfo* r) {
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
  for (const char* s : {"unsigned", "pseudonormal", "winding", "parity", "mask_inside"}) r->add_sign_modes(s);
  for (const char* s : {"obj", "off", "ply", "stl"}) r->add_mesh_formats(s);
  for (const char* s : {"float32", "float16"}) r->add_encodings(s);
  r->set_active_queries(uint32_t(slots_.active()));
  r->set_mesh_support(true);
  spdlog::info("GetInfo peer={} status=OK", context->peer());
  return grpc::Status::OK;
}

grpc::Status DistanceFieldService::Query(grpc::ServerContext* context, const v1::QueryRequest* request,
                                         grpc::ServerWriter<v1::QueryReply>* writer) {
  QueryRecord record;
  record.received = Clock::now();
  record.id = fmt::format("q{}", next_query_.fetch_add(1));
  grpc::Status status = runQuery(context, *request, writer, &record);
  record.code = status.error_code();
  record.message = status.error_message();
  record.finished = Clock::now();
  if (hooks_.on_query_end) hooks_.on_query_end(record);
  return status;
}

grpc::Status DistanceFieldService::runQuery(grpc::ServerContext* context, const v1::QueryRequest& request,
                                            grpc::ServerWriter<v1::QueryReply>* writer, QueryRecord* record) {
  const auto t0 = record->received;
  ResolvedQuery q;
  // What the log line shows (copied: `q` moves into the job).
  std::string label = "-";
  Grid grid;
  double limit = 0, segment = 0;
  auto log = [&](const grpc::Status& s, const std::string& extra) {
    spdlog::info("Query {} peer={} seeds={} grid={}x{}x{} h={:g} limit={:g} segment={:g} {} time={:.3f}s status={}",
                 record->id, context->peer(), label, grid.dims().x, grid.dims().y, grid.dims().z, grid.voxelSize(),
                 limit, segment, extra, since(t0), statusText(s));
    return s;
  };
  if (shutting_down_.load())
    return log({grpc::StatusCode::UNAVAILABLE, "the server is shutting down and accepts no new queries"}, "");
  if (grpc::Status s = resolveQuery(request, options_, cache_, &q); !s.ok()) return log(s, "");
  label = q.seeds_label;
  grid = q.grid;
  limit = q.engine.limit_world;
  segment = q.engine.segment_length_world;

  const bool got_slot = slots_.acquire(std::chrono::milliseconds(options_.queue_wait_ms),
                                       [&] { return context->IsCancelled() || shutting_down_.load(); });
  const double queue_seconds = since(t0);
  if (!got_slot) {
    if (context->IsCancelled()) return log({grpc::StatusCode::CANCELLED, "cancelled while queued"}, "");
    if (shutting_down_.load())
      return log({grpc::StatusCode::UNAVAILABLE, "the server is shutting down and accepts no new queries"}, "");
    return log({grpc::StatusCode::RESOURCE_EXHAUSTED,
                fmt::format("max concurrent queries: all {} compute slots stayed busy for {} ms; retry later",
                            options_.max_concurrent_queries, options_.queue_wait_ms)},
               "");
  }
  struct SlotGuard {
    QuerySlots& slots;
    ~SlotGuard() { slots.release(); }
  } slot_guard{slots_};

  {
    v1::QueryReply header;
    fillQueryHeader(q, record->id, header.mutable_header());
    if (!writer->Write(header)) return log({grpc::StatusCode::CANCELLED, "the client went away"}, "");
  }
  const int encoding = q.encoding;
  QueryJob job(std::move(q), arena_.get(), options_.stream_buffer_bytes);
  job.start();
  record->engine_ran = true;
  uint64_t messages = 1;
  bool client_gone = false;
  QueryJob::Message msg;
  for (;;) {
    const auto r = job.queue().pop(&msg, std::chrono::milliseconds(5));
    if (r == BoundedQueue<QueryJob::Message>::PopResult::kClosed) break;
    if (r == BoundedQueue<QueryJob::Message>::PopResult::kItem) {
      if (!writer->Write(*msg)) {
        client_gone = true;
      } else {
        ++messages;
      }
      msg.reset();
    }
    if (!client_gone && context->IsCancelled()) client_gone = true;
    if (client_gone) {
      record->cancel_seen = Clock::now();
      job.cancel();
      break;
    }
  }
  job.join();
  const EngineResult& res = job.result();
  record->engine_stopped = job.engineStopped();
  record->interrupted = res.interrupted;
  record->voxels = uint64_t(res.voxels);
  record->bricks = job.bricksSent();
  record->messages = messages;
  record->bytes = job.valueBytes();
  record->segments = int(res.segments.size());
  const std::string stats =
      fmt::format("segments={} voxels={} bricks={} messages={} MB={:.1f} seeds={:.3f}s compute={:.3f}s enc={}",
                  res.segments.size(), res.voxels, job.bricksSent(), messages, job.valueBytes() / 1e6,
                  job.seedSeconds(), res.seconds, encoding == v1::BRICK_ENCODING_FLOAT16 ? "f16" : "f32");
  if (client_gone) {
    const double stop_ms =
        std::chrono::duration<double, std::milli>(record->engine_stopped - record->cancel_seen).count();
    return log({grpc::StatusCode::CANCELLED, "the client cancelled or went away"},
               fmt::format("{} engine_stop_after_cancel={:.1f}ms", stats, stop_ms));
  }
  if (!job.error().empty())
    return log({job.outOfMemory() ? grpc::StatusCode::RESOURCE_EXHAUSTED : grpc::StatusCode::INVALID_ARGUMENT,
                job.error()},
               stats);
  if (res.interrupted) return log({grpc::StatusCode::CANCELLED, "the query was interrupted"}, stats);

  v1::QueryReply reply;
  v1::QuerySummary* s = reply.mutable_summary();
  s->set_voxels(uint64_t(res.voxels));
  s->set_bricks(job.bricksSent());
  s->set_messages(messages + 1);
  s->set_value_bytes(job.valueBytes());
  s->set_steps(uint32_t(res.steps));
  s->set_seed_seconds(job.seedSeconds());
  s->set_compute_seconds(res.seconds);
  s->set_queue_seconds(queue_seconds);
  for (size_t i = 0; i < res.segments.size(); ++i) {
    const SegmentStats& st = res.segments[i];
    v1::SegmentTiming* t = s->add_segments();
    t->set_segment(uint32_t(st.index));
    t->set_lower(st.lower_world);
    t->set_upper(st.upper_world);
    t->set_voxels(uint64_t(st.voxels));
    t->set_bricks(i < job.segmentBricks().size() ? job.segmentBricks()[i] : uint64_t(st.bricks));
    t->set_steps(uint32_t(st.steps));
    t->set_compute_seconds(st.seconds);
    if (i < job.segmentSentSeconds().size()) t->set_sent_seconds(job.segmentSentSeconds()[i]);
  }
  s->set_total_seconds(since(t0));
  if (!writer->Write(reply)) return log({grpc::StatusCode::CANCELLED, "the client went away"}, stats);
  return log(grpc::Status::OK, stats);
}

}  // namespace distband

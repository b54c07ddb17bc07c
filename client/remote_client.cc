#include "client/remote_client.h"

#include <algorithm>
#include <atomic>
#include <deque>
#include <mutex>
#include <thread>
#include <cctype>
#include <iterator>

#include <fmt/format.h>
#include <grpcpp/grpcpp.h>

#include "core/io/input_file.h"
#include "core/mesh/triangle_mesh.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "proto/brick_codec.h"

namespace distband {

using Clock = std::chrono::steady_clock;

void QueryCanceller::cancel() {
  std::lock_guard lock(mu_);
  if (!cancelled_) cancel_time_ = Clock::now();
  cancelled_ = true;
  if (context_) context_->TryCancel();
}

std::chrono::steady_clock::time_point QueryCanceller::cancelTime() const {
  std::lock_guard lock(mu_);
  return cancel_time_;
}

bool QueryCanceller::cancelled() const {
  std::lock_guard lock(mu_);
  return cancelled_;
}

void QueryCanceller::attach(grpc::ClientContext* context) {
  std::lock_guard lock(mu_);
  context_ = context;
  if (cancelled_) context_->TryCancel();
}

void QueryCanceller::detach() {
  std::lock_guard lock(mu_);
  context_ = nullptr;
}

v1::MeshFormat meshFormatFromPath(const std::string& path) {
  const size_t dot = path.find_last_of('.');
  if (dot == std::string::npos) return v1::MESH_FORMAT_UNSPECIFIED;
  std::string ext = path.substr(dot + 1);
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext == "obj") return v1::MESH_FORMAT_OBJ;
  if (ext == "off") return v1::MESH_FORMAT_OFF;
  if (ext == "ply") return v1::MESH_FORMAT_PLY;
  if (ext == "stl") return v1::MESH_FORMAT_STL;
  return v1::MESH_FORMAT_UNSPECIFIED;
}

Grid gridFromHeader(const v1::QueryHeader& h) {
  const Vec3d origin{h.origin().x(), h.origin().y(), h.origin().z()};
  const Coord dims{int32_t(h.dims().x()), int32_t(h.dims().y()), int32_t(h.dims().z())};
  // A server before anisotropic grids sends no spacing: voxel_size on every axis.
  if (h.has_spacing()) return Grid(origin, {h.spacing().x(), h.spacing().y(), h.spacing().z()}, dims);
  return Grid(origin, h.voxel_size(), dims);
}

RemoteClient::RemoteClient(const std::string& target, RemoteClientOptions options) : options_(options) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(int(options_.max_message_bytes));
  args.SetMaxSendMessageSize(int(options_.max_message_bytes));
  std::shared_ptr<grpc::ChannelCredentials> credentials = grpc::InsecureChannelCredentials();
  if (options_.tls) {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = options_.tls_root_ca_pem;
    ssl.pem_cert_chain = options_.tls_client_cert_pem;
    ssl.pem_private_key = options_.tls_client_key_pem;
    credentials = grpc::SslCredentials(ssl);
    if (!options_.tls_server_name.empty()) args.SetSslTargetNameOverride(options_.tls_server_name);
  }
  channel_ = grpc::CreateCustomChannel(target, credentials, args);
  stub_ = v1::DistanceField::NewStub(channel_);
}

void RemoteClient::authorize(grpc::ClientContext* context) const {
  if (!options_.bearer_token.empty()) context->AddMetadata("authorization", "Bearer " + options_.bearer_token);
}

namespace {
template <typename Chunk, typename FillHeader>
grpc::Status uploadChunks(grpc::ClientWriter<Chunk>* writer, grpc::ClientContext& ctx, const char* data,
                          size_t size, size_t chunk_bytes, FillHeader fill_header) {
  size_t offset = 0;
  bool first = true;
  while (first || offset < size) {
    Chunk chunk;
    if (first) fill_header(chunk.mutable_header());
    const size_t n = std::min(chunk_bytes, size - offset);
    chunk.set_data(data + offset, n);
    offset += n;
    first = false;
    if (!writer->Write(chunk)) break;  // the server ended the call early; Finish() says why
  }
  writer->WritesDone();
  return writer->Finish();
}
}  // namespace

grpc::Status RemoteClient::uploadMesh(const std::string& bytes, v1::MeshFormat format, const std::string& name,
                                      v1::UploadReply* reply) {
  grpc::ClientContext ctx;
  authorize(&ctx);
  auto writer = stub_->UploadMesh(&ctx, reply);
  return uploadChunks(writer.get(), ctx, bytes.data(), bytes.size(), options_.upload_chunk_bytes,
                      [&](v1::UploadMeshHeader* h) {
                        h->set_format(format);
                        h->set_total_bytes(bytes.size());
                        h->set_name(name.substr(0, 256));
                      });
}

grpc::Status RemoteClient::uploadMeshFile(const std::string& path, v1::UploadReply* reply) {
  const v1::MeshFormat format = meshFormatFromPath(path);
  if (format == v1::MESH_FORMAT_UNSPECIFIED)
    return {grpc::StatusCode::INVALID_ARGUMENT,
            fmt::format("{}: unsupported mesh format (expected .obj, .off, .ply or .stl)", path)};
  std::string bytes;
  if (Status s = readWholeFile(path, kMaxMeshFileBytes, "a mesh", &bytes); !s.ok())
    return {grpc::StatusCode::INVALID_ARGUMENT, s.message()};
  const size_t slash = path.find_last_of('/');
  return uploadMesh(bytes, format, slash == std::string::npos ? path : path.substr(slash + 1), reply);
}

grpc::Status RemoteClient::uploadVolume(const LabelVolume& volume, const std::string& name, v1::UploadReply* reply) {
  const v1::VoxelType type = volume.type() == VoxelType::kUint16   ? v1::VOXEL_TYPE_UINT16
                             : volume.type() == VoxelType::kUint32 ? v1::VOXEL_TYPE_UINT32
                                                                   : v1::VOXEL_TYPE_UINT8;
  return uploadVolumeBytes(volume.dims(), type, volume.bytes(), name, reply);
}

grpc::Status RemoteClient::uploadVolumeBytes(const Coord& dims, v1::VoxelType type, const std::vector<uint8_t>& bytes,
                                             const std::string& name, v1::UploadReply* reply) {
  grpc::ClientContext ctx;
  authorize(&ctx);
  auto writer = stub_->UploadVolume(&ctx, reply);
  return uploadChunks(writer.get(), ctx, reinterpret_cast<const char*>(bytes.data()), bytes.size(),
                      options_.upload_chunk_bytes, [&](v1::UploadVolumeHeader* h) {
                        h->mutable_dims()->set_x(uint32_t(dims.x));
                        h->mutable_dims()->set_y(uint32_t(dims.y));
                        h->mutable_dims()->set_z(uint32_t(dims.z));
                        h->set_element_type(type);
                        h->set_name(name.substr(0, 256));
                      });
}

RemoteQueryResult RemoteClient::query(const v1::QueryRequest& request, const RemoteQueryCallbacks& cb,
                                      const RemoteQueryOptions& options) {
  RemoteQueryResult result;
  const auto t0 = Clock::now();
  auto seconds = [&] { return std::chrono::duration<double>(Clock::now() - t0).count(); };
  grpc::ClientContext ctx;
  authorize(&ctx);
  if (options.deadline.count() > 0) ctx.set_deadline(std::chrono::system_clock::now() + options.deadline);
  if (options.canceller) options.canceller->attach(&ctx);
  auto reader = stub_->Query(&ctx, request);

  std::string protocol_error;
  auto stop = [&] {
    result.cancelled_by_client = true;
    result.cancel_time = Clock::now();
    ctx.TryCancel();
  };
  v1::QueryReply reply;
  v1::BrickEncoding encoding = v1::BRICK_ENCODING_FLOAT32;
  v1::ClosestFeature closest = v1::CLOSEST_FEATURE_NONE;
  int expected_segment = 0;
  while (reader->Read(&reply)) {
    ++result.messages;
    bool go_on = true;
    switch (reply.kind_case()) {
      case v1::QueryReply::kHeader:
        if (result.have_header) {
          protocol_error = "a second header arrived";
          break;
        }
        result.have_header = true;
        result.header = reply.header();
        result.grid = gridFromHeader(reply.header());
        encoding = reply.header().encoding();
        closest = reply.header().closest_feature();
        if (Status s = result.grid.validate(); !s.ok()) protocol_error = "header grid: " + s.message();
        else if (!v1::ClosestFeature_IsValid(closest))
          protocol_error = fmt::format("header closest_feature {} is not a ClosestFeature value", int(closest));
        else if (cb.on_header) go_on = cb.on_header(result.grid, result.header);
        break;
      case v1::QueryReply::kBricks: {
        const v1::BrickBatch& b = reply.bricks();
        if (!result.have_header) {
          protocol_error = "bricks arrived before the header";
          break;
        }
        if (int(b.segment()) != expected_segment) {
          protocol_error = fmt::format("bricks of segment {} arrived while segment {} was open", b.segment(),
                                       expected_segment);
          break;
        }
        if (result.first_bricks_seconds < 0) result.first_bricks_seconds = seconds();
        SegmentBricks batch;
        batch.index = int(b.segment());
        batch.lower_world = b.lower();
        batch.upper_world = b.upper();
        batch.bricks.resize(size_t(b.bricks_size()));
        uint64_t bytes = 0;
        for (int i = 0; i < b.bricks_size() && protocol_error.empty(); ++i) {
          protocol_error = decodeBrick(b.bricks(i), encoding, &batch.bricks[size_t(i)], closest).message();
          bytes += b.bricks(i).values().size() + b.bricks(i).mask().size() + b.bricks(i).closest().size();
        }
        result.wire_bytes += bytes;
        if (protocol_error.empty() && cb.on_bricks) go_on = cb.on_bricks(std::move(batch), bytes);
        break;
      }
      case v1::QueryReply::kSegmentDone:
        if (int(reply.segment_done().segment()) != expected_segment) {
          protocol_error = fmt::format("segment_done for segment {} while segment {} was open",
                                       reply.segment_done().segment(), expected_segment);
          break;
        }
        ++expected_segment;
        if (result.first_segment_done_seconds < 0) result.first_segment_done_seconds = seconds();
        if (cb.on_segment_done) go_on = cb.on_segment_done(reply.segment_done());
        break;
      case v1::QueryReply::kSummary:
        result.have_summary = true;
        result.summary = reply.summary();
        break;
      case v1::QueryReply::KIND_NOT_SET:
        protocol_error = "a reply with no content arrived";
        break;
    }
    if (!protocol_error.empty()) {
      ctx.TryCancel();
      break;
    }
    if (!go_on) {
      stop();
      break;
    }
  }
  // Drain after a cancel so Finish() does not wait on unread messages.
  if (result.cancelled_by_client || !protocol_error.empty())
    while (reader->Read(&reply)) {
    }
  result.status = reader->Finish();
  if (options.canceller) {
    if (options.canceller->cancelled() && !result.cancelled_by_client) {
      result.cancelled_by_client = true;
      result.cancel_time = options.canceller->cancelTime();
    }
    options.canceller->detach();
  }
  if (!protocol_error.empty())
    result.status = {grpc::StatusCode::INTERNAL, "malformed server stream: " + protocol_error};
  else if (result.status.ok() && !result.have_summary)
    result.status = {grpc::StatusCode::INTERNAL, "the stream ended without a summary"};
  result.total_seconds = seconds();
  return result;
}

RemotePointsResult RemoteClient::queryPoints(const v1::PointsHeader& header, const RemotePointsCallbacks& cb,
                                             const RemoteQueryOptions& options) {
  RemotePointsResult result;
  const auto t0 = Clock::now();
  grpc::ClientContext ctx;
  authorize(&ctx);
  if (options.deadline.count() > 0) ctx.set_deadline(std::chrono::system_clock::now() + options.deadline);
  if (options.canceller) options.canceller->attach(&ctx);
  auto stream = stub_->QueryPoints(&ctx);

  // The writer: the header, then each chunk; the sizes sent let the reader check each result's point count.
  std::mutex mu;
  std::deque<uint64_t> sent_points;  // per chunk not yet answered
  const size_t record = header.coordinates() == v1::VALUE_TYPE_FLOAT64 ? 24 : 12;
  std::atomic<bool> stop_writing{false};
  std::thread writer([&] {
    v1::PointsRequest m;
    *m.mutable_header() = header;
    if (!stream->Write(m)) return;
    for (;;) {
      if (stop_writing.load()) return;
      m.Clear();
      std::string* xyz = m.mutable_chunk()->mutable_xyz();
      if (!cb.next_chunk || !cb.next_chunk(xyz)) break;
      {
        std::lock_guard lock(mu);
        sent_points.push_back(xyz->size() / record);
      }
      if (!stream->Write(m)) return;
    }
    stream->WritesDone();
  });

  std::string protocol_error;
  bool go_on = true;
  v1::PointsReply reply;
  while (go_on && protocol_error.empty() && stream->Read(&reply)) {
    switch (reply.kind_case()) {
      case v1::PointsReply::kHeader:
        if (result.have_header)
          protocol_error = "a second header arrived";
        else {
          result.have_header = true;
          result.header = reply.header();
          if (cb.on_header) go_on = cb.on_header(result.header);
        }
        break;
      case v1::PointsReply::kResults: {
        const v1::PointsResults& r = reply.results();
        uint64_t expected = 0;
        {
          std::lock_guard lock(mu);
          if (!sent_points.empty()) {
            expected = sent_points.front();
            sent_points.pop_front();
          }
        }
        if (!result.have_header)
          protocol_error = "results arrived before the header";
        else if (r.chunk() != result.chunks || r.first_point() != result.points || r.points() != expected)
          protocol_error = fmt::format(
              "results of chunk {} (first point {}, {} points) arrived where chunk {} "
              "(first point {}, {} points) was due",
              r.chunk(), r.first_point(), r.points(), result.chunks, result.points, expected);
        else {
          ++result.chunks;
          result.points += r.points();
          if (cb.on_results) go_on = cb.on_results(r);
        }
        break;
      }
      case v1::PointsReply::kSummary:
        result.have_summary = true;
        result.summary = reply.summary();
        break;
      case v1::PointsReply::KIND_NOT_SET:
        protocol_error = "a reply with no content arrived";
        break;
    }
  }
  if (!go_on || !protocol_error.empty()) {
    result.cancelled_by_client = go_on ? false : true;
    stop_writing.store(true);
    ctx.TryCancel();
    while (stream->Read(&reply)) {
    }
  }
  writer.join();
  result.status = stream->Finish();
  if (options.canceller) {
    if (options.canceller->cancelled()) result.cancelled_by_client = true;
    options.canceller->detach();
  }
  if (!protocol_error.empty())
    result.status = {grpc::StatusCode::INTERNAL, "malformed server stream: " + protocol_error};
  else if (result.status.ok() && !result.have_summary)
    result.status = {grpc::StatusCode::INTERNAL, "the stream ended without a summary"};
  result.total_seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return result;
}

grpc::Status RemoteClient::info(v1::ServerInfo* info, std::chrono::milliseconds deadline) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + deadline);
  authorize(&ctx);
  return stub_->GetInfo(&ctx, v1::GetInfoRequest(), info);
}

grpc::Status RemoteClient::health(const std::string& service, bool* serving, std::string* status_name,
                                  std::chrono::milliseconds deadline) {
  auto stub = grpc::health::v1::Health::NewStub(channel_);
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + deadline);
  grpc::health::v1::HealthCheckRequest req;
  req.set_service(service);
  grpc::health::v1::HealthCheckResponse resp;
  grpc::Status s = stub->Check(&ctx, req, &resp);
  if (serving) *serving = s.ok() && resp.status() == grpc::health::v1::HealthCheckResponse::SERVING;
  if (status_name)
    *status_name = s.ok() ? grpc::health::v1::HealthCheckResponse::ServingStatus_Name(resp.status()) : "";
  return s;
}

}  // namespace distband

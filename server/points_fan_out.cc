#include "server/points_fan_out.h"

#include <grpc/grpc.h>

#include <algorithm>
#include <atomic>
#include <string_view>
#include <utility>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "core/points/point_results.h"
#include "server/asset_parsing.h"
#include "server/grpc_status.h"
#include "server/log_line.h"
#include "server/request_id.h"

namespace distband {
namespace {

constexpr auto kPoll = std::chrono::milliseconds(5);

/// Refusals of a stream's header that leave the replica out of the call (down, busy, lost the upload) rather than
/// fail it.
bool leftOutFor(Status::Code code) {
  switch (code) {
    case Status::Code::kUnavailable:
    case Status::Code::kResourceExhausted:
    case Status::Code::kNotFound:
    case Status::Code::kDeadlineExceeded:
    case Status::Code::kCancelled:
    case Status::Code::kInternal:
      return true;
    default:
      return false;
  }
}

std::string described(const Status& s) { return fmt::format("{} {}", Status::codeName(s.code()), s.message()); }

}  // namespace

struct PointsFanOut::Stream {
  std::string address;
  std::unique_ptr<v1::DistanceField::Stub> stub;
  grpc::ClientContext context;
  std::unique_ptr<grpc::ClientReaderWriter<v1::PointsRequest, v1::PointsReply>> stream;
  std::mutex write_mu;    ///< the handler's Write/WritesDone against the reader's Finish
  bool finished = false;  ///< under write_mu: Finish() returned
  std::thread reader;
  // Under the fan-out's mu_:
  bool in_use = false;
  bool ended = false;  ///< its reader has finished; `status` is the stream's
  Status status;
  std::optional<v1::PointsReplyHeader> header;
  std::deque<v1::PointsResults> results;  ///< arrived, not yet forwarded (at most kWindow)
  uint64_t sent = 0, sent_points = 0, answered = 0, forwarded = 0;
  Clock::time_point owed_since{};  ///< when it last answered, or began to owe something again
  std::optional<v1::PointsSummary> summary;
};

size_t PointsFanOut::streamsFor(size_t replicas) { return std::clamp<size_t>(replicas, 1, kMaxStreams); }

uint64_t PointsFanOut::reservedBytes(const ResolvedPoints& p, size_t streams) {
  const uint64_t value = p.packing.doubles ? 8 : 4, id = p.packing.wide_ids ? 8 : 4;
  const uint64_t per_point =
      value * (1 + (p.outputs.closest_points ? 3 : 0) + (p.outputs.gradients ? 3 : 0)) + (p.outputs.features ? id : 0);
  const uint64_t result = uint64_t(kMaxChunkPoints) * per_point + 1024;
  const uint64_t chunk = uint64_t(kMaxChunkPoints) * (3 * value + sizeof(Vec3d));  // as received, and decoded
  uint64_t ply = 0;
  if (p.header.seeds_case() == v1::PointsHeader::kAssetId && p.seed_kind == SeedKind::kMesh)
    ply = uint64_t(p.asset->mesh->vertices.size()) * 24 + uint64_t(p.asset->mesh->triangles.size()) * 13 + 512;
  return uint64_t(streams) * kWindow * result + chunk + ply;
}

PointsFanOut::PointsFanOut(const ResolvedPoints& points, Config config)
    : points_(points), config_(std::move(config)), uploads_(config_.pool) {}

PointsFanOut::~PointsFanOut() {
  {
    std::lock_guard lock(mu_);
    failLocked(Status::Cancelled("the call ended"));  // no-op after an earlier error; stops the merge thread
    for (auto& s : streams_) s->context.TryCancel();  // streams that ended ignore it
  }
  if (merger_.joinable()) merger_.join();
  for (auto& s : streams_)
    if (s->reader.joinable()) s->reader.join();
}

PointsFanOut::Clock::duration PointsFanOut::tileTimeout() const {
  return std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(config_.options.tile_timeout_seconds));
}

Status PointsFanOut::stopReason() const {
  std::lock_guard lock(mu_);
  if (!failure_.ok()) return failure_;
  return config_.interrupter.status();
}

void PointsFanOut::enroll(grpc::ClientContext* context) {
  const auto own =
      std::chrono::system_clock::now() + std::chrono::duration_cast<std::chrono::system_clock::duration>(
                                             std::chrono::duration<double>(config_.options.tile_timeout_seconds));
  config_.pool.prepare(context, std::min(own, config_.client_context.deadline()));
  if (!config_.request_id.empty()) context->AddMetadata(kRequestIdHeader, config_.request_id);
  std::lock_guard lock(mu_);
  uploads_in_flight_.insert(context);
  if (!failure_.ok()) context->TryCancel();
}

void PointsFanOut::withdraw(grpc::ClientContext* context) {
  std::lock_guard lock(mu_);
  uploads_in_flight_.erase(context);
}

void PointsFanOut::failLocked(Status status) {
  if (!failure_.ok()) return;
  failure_ = std::move(status);
  for (auto& s : streams_) s->context.TryCancel();
  for (grpc::ClientContext* c : uploads_in_flight_) c->TryCancel();
  // A handler blocked reading its client cannot return a status, and a client that waits for results before it sends
  // again would wait for ever: its call ends with the status now (ServerContext::TryCancel does the same with
  // CANCELLED). The handler then returns the same status.
  if (reading_ && !config_.client_context.IsCancelled())
    grpc_call_cancel_with_status(config_.client_context.c_call(), grpc_status_code(toGrpcCode(failure_.code())),
                                 failure_.message().c_str(), nullptr);
  cv_.notify_all();
}

Status PointsFanOut::fail(Status status) {
  std::lock_guard lock(mu_);
  failLocked(std::move(status));
  return failure_;
}

Status PointsFanOut::clientGone() const {
  if (config_.interrupter.interrupted()) return config_.interrupter.status();
  if (config_.client_context.IsCancelled()) return Status::Cancelled("the client cancelled the call");
  return Status::Cancelled("the client went away");
}

Status PointsFanOut::replicaFailure(const Stream& s, const Status& status) const {
  const std::string what =
      fmt::format("replica {}: its point stream failed after it answered {} of the {} chunks sent to it: {}", s.address,
                  s.answered, s.sent, described(status));
  // A replica refusing a chunk's content would be the client's fault; anything else is the replica's.
  return status.code() == Status::Code::kInvalidArgument ? Status::InvalidArgument(what) : Status::Unavailable(what);
}

void PointsFanOut::updateWaitingLocked() {
  const bool waiting = writing_ || (reading_ && outstanding_.empty());
  if (waiting == waiting_) return;
  waiting_ = waiting;
  if (config_.waiting) config_.waiting(waiting);
}

bool PointsFanOut::allEndedLocked() const {
  return std::all_of(in_use_.begin(), in_use_.end(), [&](size_t i) { return streams_[i]->ended; });
}

Status PointsFanOut::shipSeeds(std::vector<ReplicaPool::Replica>* replicas, v1::PointsHeader* header) {
  if (points_.header.seeds_case() != v1::PointsHeader::kAssetId) return Status::Ok();  // inline: as the client sent it
  std::string id;
  Status s;
  if (points_.seed_kind == SeedKind::kMesh) {
    const ShippedMesh mesh = canonicalMesh(*points_.asset);
    id = mesh.id;
    s = uploads_.uploadMesh(mesh, *replicas, *this);
  } else {
    const LabelVolume& volume = points_.asset->volume;
    const std::string_view bytes(reinterpret_cast<const char*>(volume.bytes().data()), volume.bytes().size());
    const v1::Dims dims = dimsOf(volume.dims());
    id = volumeAssetId(dims, volume.type(), bytes);
    s = uploads_.uploadVolume(dims, volume.type(), bytes, id, *replicas, *this);
  }
  if (!s.ok()) return s;
  header->set_asset_id(id);
  std::erase_if(*replicas, [&](const ReplicaPool::Replica& r) { return !uploads_.holds(r.address, id); });
  return Status::Ok();
}

void PointsFanOut::openStream(const ReplicaPool::Replica& replica, const v1::PointsRequest& header) {
  auto owned = std::make_unique<Stream>();
  Stream& s = *owned;
  s.address = replica.address;
  s.stub = v1::DistanceField::NewStub(replica.channel);
  // The stream lasts as long as the client's call: the client's deadline, not --tile-timeout (stalls are watched).
  config_.pool.prepare(&s.context, config_.client_context.deadline());
  if (!config_.request_id.empty()) s.context.AddMetadata(kRequestIdHeader, config_.request_id);
  {
    std::lock_guard lock(mu_);
    streams_.push_back(std::move(owned));
    if (!failure_.ok()) s.context.TryCancel();  // a cancelled context cancels its call as it starts
  }
  s.stream = s.stub->QueryPoints(&s.context);
  {
    std::lock_guard write(s.write_mu);
    s.stream->Write(header);  // a refused write shows in the stream's status
  }
  s.reader = std::thread([this, &s] { readReplies(s); });
}

Status PointsFanOut::agreementLocked(const Stream& s) const {
  const v1::PointsReplyHeader& h = *s.header;
  std::string differs;
  if (h.sign() != header_.sign())
    differs = fmt::format("sign {} instead of {}", v1::SignMode_Name(h.sign()), v1::SignMode_Name(header_.sign()));
  else if (h.signed_() != header_.signed_())
    differs = fmt::format("signed {} instead of {}", h.signed_(), header_.signed_());
  else if (!(h.limit() == header_.limit()))
    differs = fmt::format("limit {} instead of {}", h.limit(), header_.limit());
  else if (h.closest_feature() != header_.closest_feature())
    differs = fmt::format("closest feature {} instead of {}", v1::ClosestFeature_Name(h.closest_feature()),
                          v1::ClosestFeature_Name(header_.closest_feature()));
  else if (h.values() != header_.values())
    differs =
        fmt::format("values {} instead of {}", v1::ValueType_Name(h.values()), v1::ValueType_Name(header_.values()));
  else if (h.max_chunk_points() < header_.max_chunk_points())
    differs = fmt::format("max_chunk_points {}, fewer than {}", h.max_chunk_points(), header_.max_chunk_points());
  if (differs.empty()) return Status::Ok();
  return Status::Internal(fmt::format(
      "replica {} describes the point query otherwise than this coordinator ({}): are they different versions?",
      s.address, differs));
}

Status PointsFanOut::open(const v1::PointsReplyHeader& header) {
  header_ = header;
  merger_ = std::thread([this] { merge(); });  // watches the client and the Interrupter from now on
  std::vector<ReplicaPool::Replica> replicas = config_.pool.replicas();
  if (replicas.empty())
    return fail(Status::Unavailable(fmt::format("--peers {} names no reachable replica", config_.pool.target())));
  // Calls take turns at which replica comes first, so that capped calls spread over a large pool.
  static std::atomic<size_t> next_first{0};
  std::rotate(replicas.begin(), replicas.begin() + long(next_first.fetch_add(1) % replicas.size()), replicas.end());
  replicas.resize(streamsFor(replicas.size()));
  v1::PointsRequest request;
  *request.mutable_header() = points_.header;
  if (Status s = shipSeeds(&replicas, request.mutable_header()); !s.ok()) return fail(s);
  for (const ReplicaPool::Replica& r : replicas) openStream(r, request);

  // Each stream's first reply is its header, within --tile-timeout.
  std::unique_lock lock(mu_);
  cv_.wait_until(lock, Clock::now() + tileTimeout(), [&] {
    return !failure_.ok() || std::all_of(streams_.begin(), streams_.end(),
                                         [](const auto& s) { return s->header.has_value() || s->ended; });
  });
  if (!failure_.ok()) return failure_;
  std::string last_refusal;
  for (size_t i = 0; i < streams_.size(); ++i) {
    Stream& s = *streams_[i];
    if (s.header && !s.ended) {
      if (Status agreed = agreementLocked(s); !agreed.ok()) {
        failLocked(agreed);
        return failure_;
      }
      s.in_use = true;
      in_use_.push_back(i);
      continue;
    }
    Status why = s.status;
    if (!s.ended)
      why = Status::DeadlineExceeded(
          fmt::format("no header within --tile-timeout ({:g} s)", config_.options.tile_timeout_seconds));
    else if (why.ok())
      why = Status::Internal("the stream ended without results");
    if (!leftOutFor(why.code())) {
      const std::string what = fmt::format("replica {} refused the point query: {}", s.address, described(why));
      failLocked(why.code() == Status::Code::kInvalidArgument ? Status::InvalidArgument(what) : Status::Internal(what));
      return failure_;
    }
    s.context.TryCancel();
    last_refusal = fmt::format("{}: {}", s.address, described(why));
    LogLine("PointsReplicaLeftOut")
        .text("request_id", config_.request_id)
        .text("replica", s.address)
        .status(why)
        .write(spdlog::level::warn);
  }
  if (in_use_.empty())
    failLocked(Status::Unavailable(
        fmt::format("no replica of --peers {} opened the point stream ({})", config_.pool.target(), last_refusal)));
  return failure_;
}

void PointsFanOut::readReplies(Stream& s) {
  v1::PointsReply reply;
  while (s.stream->Read(&reply)) {
    std::lock_guard lock(mu_);
    std::string broken;
    switch (reply.kind_case()) {
      case v1::PointsReply::kHeader:
        if (s.header)
          broken = "a second header";
        else
          s.header = std::move(*reply.mutable_header());
        break;
      case v1::PointsReply::kResults:
        if (!s.header || s.answered >= s.sent) {
          broken = "results of a chunk it was not sent";
        } else {
          s.results.push_back(std::move(*reply.mutable_results()));
          ++s.answered;
          s.owed_since = Clock::now();
        }
        break;
      case v1::PointsReply::kSummary:
        if (s.summary || !input_done_ || s.answered != s.sent)
          broken = "a summary before its last chunk's results";
        else
          s.summary = std::move(*reply.mutable_summary());
        break;
      case v1::PointsReply::KIND_NOT_SET:
        broken = "an empty reply";
        break;
    }
    cv_.notify_all();
    if (!broken.empty()) {
      failLocked(Status::Internal(fmt::format("replica {} broke the QueryPoints protocol: {}", s.address, broken)));
      break;
    }
  }
  Status status;
  {
    std::lock_guard write(s.write_mu);
    status = fromGrpcStatus(s.stream->Finish());
    s.finished = true;
  }
  std::lock_guard lock(mu_);
  s.ended = true;
  s.status = status;
  if (s.in_use) {
    if (!status.ok())
      failLocked(replicaFailure(s, status));
    else if (!s.summary)
      failLocked(Status::Unavailable(
          fmt::format("replica {} ended its point stream without a summary after it answered {} of the {} chunks "
                      "sent to it",
                      s.address, s.answered, s.sent)));
  }
  cv_.notify_all();
}

void PointsFanOut::checkStopLocked() {
  if (!failure_.ok()) return;
  if (!config_.interrupter.interrupted() && config_.client_context.IsCancelled())
    config_.interrupter.cancel(Status::Code::kCancelled, "the client cancelled the call");
  if (config_.interrupter.interrupted()) return failLocked(config_.interrupter.status());
  // A replica that owes results (or, after the client's half-close, its summary) and says nothing for --tile-timeout
  // is stalled: the call must not wait for it until the client's deadline.
  const auto now = Clock::now();
  for (const size_t i : in_use_) {
    const Stream& s = *streams_[i];
    const bool owes = s.answered < s.sent || (input_done_ && !input_failed_ && !s.ended);
    if (owes && now - s.owed_since > tileTimeout())
      return failLocked(Status::Unavailable(fmt::format(
          "replica {} answered nothing for {:g} s (--tile-timeout) while it owed {} chunks' results{}", s.address,
          config_.options.tile_timeout_seconds, s.sent - s.answered, s.answered == s.sent ? " and its summary" : "")));
  }
}

void PointsFanOut::merge() {
  std::unique_lock lock(mu_);
  for (;;) {
    checkStopLocked();
    if (!failure_.ok()) return;
    if (!outstanding_.empty()) {
      const Outstanding next = outstanding_.front();
      Stream& s = *streams_[next.stream];
      if (!s.results.empty()) {
        v1::PointsReply reply;
        v1::PointsResults& r = *reply.mutable_results();
        r = std::move(s.results.front());
        s.results.pop_front();
        if (r.chunk() != s.forwarded || r.points() != next.points)
          return failLocked(Status::Internal(
              fmt::format("replica {} answered its chunk {} ({} points) with the results of chunk {} ({} points)",
                          s.address, s.forwarded, next.points, r.chunk(), r.points())));
        r.set_chunk(next.chunk);
        r.set_first_point(next.first_point);
        writing_ = true;
        updateWaitingLocked();
        lock.unlock();
        const bool written = config_.client.Write(reply);
        lock.lock();
        writing_ = false;
        if (!written) return failLocked(clientGone());
        outstanding_.pop_front();
        ++s.forwarded;
        ++chunks_;
        points_forwarded_ += next.points;
        updateWaitingLocked();
        cv_.notify_all();
        continue;
      }
    } else if (input_done_ && (input_failed_ || allEndedLocked())) {
      return;
    }
    cv_.wait_for(lock, kPoll);
  }
}

bool PointsFanOut::writeClient(const v1::PointsReply& reply) {
  {
    std::lock_guard lock(mu_);
    writing_ = true;
    updateWaitingLocked();
  }
  const bool written = config_.client.Write(reply);
  std::lock_guard lock(mu_);
  writing_ = false;
  updateWaitingLocked();
  return written;
}

bool PointsFanOut::sendChunk(const v1::PointsRequest& request, uint64_t chunk, uint64_t first_point, uint32_t points) {
  Stream* s;
  {
    std::unique_lock lock(mu_);
    const size_t index = in_use_[chunk % in_use_.size()];
    s = streams_[index].get();
    // The merge thread frees a slot as it forwards the stream's oldest result (and wakes this on any failure).
    while (failure_.ok() && s->sent - s->forwarded >= kWindow) cv_.wait_for(lock, kPoll);
    if (!failure_.ok()) return false;
    if (s->answered == s->sent) s->owed_since = Clock::now();
    outstanding_.push_back({index, chunk, first_point, points});
    ++s->sent;
    s->sent_points += points;
    updateWaitingLocked();
  }
  std::lock_guard write(s->write_mu);
  if (!s->finished) s->stream->Write(request);  // a stream that ended says why through its reader
  return true;
}

void PointsFanOut::halfCloseStreams() {
  std::vector<Stream*> streams;
  {
    std::lock_guard lock(mu_);
    for (const size_t i : in_use_) streams.push_back(streams_[i].get());
  }
  for (Stream* s : streams) {
    std::lock_guard write(s->write_mu);
    if (!s->finished) s->stream->WritesDone();
  }
}

Status PointsFanOut::serve() {
  {
    v1::PointsReply reply;
    *reply.mutable_header() = header_;
    if (!writeClient(reply)) return fail(clientGone());
  }
  const v1::ValueType type = points_.packing.doubles ? v1::VALUE_TYPE_FLOAT64 : v1::VALUE_TYPE_FLOAT32;
  v1::PointsRequest request;
  std::vector<Vec3d> decoded;
  uint64_t chunk = 0, first_point = 0;
  Status input;  // a malformed message from the client ends its input early
  bool input_ended = false;
  for (;;) {
    {
      std::lock_guard lock(mu_);
      if (!failure_.ok()) break;
      reading_ = true;
      updateWaitingLocked();
    }
    const bool got = config_.client.Read(&request);
    {
      std::lock_guard lock(mu_);
      reading_ = false;
      updateWaitingLocked();
      if (!failure_.ok()) break;
    }
    if (!got) {
      input_ended = true;
      break;
    }
    if (request.kind_case() != v1::PointsRequest::kChunk) {
      input = Status::InvalidArgument(fmt::format("chunk {}: only the first message may be a header", chunk));
      break;
    }
    if (input = decodePointsChunk(request.chunk(), type, chunk, first_point, &decoded); !input.ok()) break;
    const auto points = uint32_t(decoded.size());
    if (!sendChunk(request, chunk, first_point, points)) break;
    ++chunk;
    first_point += points;
  }
  {
    std::lock_guard lock(mu_);
    // Read() ends with the client's half-close, and also with its cancel or the deadline.
    if (input_ended && (config_.client_context.IsCancelled() || config_.interrupter.interrupted()))
      failLocked(clientGone());
    if (failure_.ok() && (input_ended || !input.ok())) {
      input_done_ = true;
      input_failed_ = !input.ok();
      for (const size_t i : in_use_)
        if (streams_[i]->answered == streams_[i]->sent) streams_[i]->owed_since = Clock::now();  // now its summary
      cv_.notify_all();
    }
  }
  if (input_ended) halfCloseStreams();
  // The merge thread ends on the first error, or once every result is forwarded (and, after a half-close, every
  // replica summarized).
  merger_.join();
  std::lock_guard lock(mu_);
  // A malformed chunk: the results of the chunks before it are the client's; the replicas stop now.
  if (!input.ok()) failLocked(input);
  if (!failure_.ok()) return failure_;
  for (const size_t i : in_use_) {
    const Stream& s = *streams_[i];
    if (s.summary->chunks() != s.sent || s.summary->points() != s.sent_points)
      failLocked(
          Status::Internal(fmt::format("replica {} summarized {} chunks and {} points, but was sent {} and {}",
                                       s.address, s.summary->chunks(), s.summary->points(), s.sent, s.sent_points)));
  }
  return failure_;
}

void PointsFanOut::summarize(v1::PointsSummary* out) const {
  std::lock_guard lock(mu_);
  out->set_points(points_forwarded_);
  out->set_chunks(chunks_);
  uint64_t beyond = 0;
  bool cached = !in_use_.empty();
  double search = 0, compute = 0, queue = 0;
  for (const size_t i : in_use_) {
    if (!streams_[i]->summary) continue;
    const v1::PointsSummary& s = *streams_[i]->summary;
    beyond += s.beyond_limit();
    cached = cached && s.search_cached();
    search = std::max(search, s.search_seconds());  // built in parallel: the client waited for the slowest
    compute += s.compute_seconds();                 // the work done, over every replica
    queue = std::max(queue, s.queue_seconds());
  }
  out->set_beyond_limit(beyond);
  out->set_search_cached(cached);
  out->set_search_seconds(search);
  out->set_compute_seconds(compute);
  out->set_queue_seconds(queue);
}

uint64_t PointsFanOut::chunks() const {
  std::lock_guard lock(mu_);
  return chunks_;
}

uint64_t PointsFanOut::points() const {
  std::lock_guard lock(mu_);
  return points_forwarded_;
}

size_t PointsFanOut::streams() const {
  std::lock_guard lock(mu_);
  return in_use_.size();
}

}  // namespace distband

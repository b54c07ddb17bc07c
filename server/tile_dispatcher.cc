#include "server/tile_dispatcher.h"

#include <algorithm>
#include <memory>
#include <thread>
#include <utility>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "server/grpc_status.h"
#include "server/log_line.h"
#include "server/request_id.h"

namespace distband {
namespace {

constexpr size_t kMaxTileCallsPerQuery = 128;

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

TileDispatcher::TileDispatcher(Config config, Tiles& tiles) : config_(config), tiles_(tiles) {}

void TileDispatcher::enroll(grpc::ClientContext* context) {
  config_.pool.prepare(context, tileDeadline());
  if (!config_.request_id.empty()) context->AddMetadata(kRequestIdHeader, config_.request_id);
  std::lock_guard lock(mu_);
  calls_.insert(context);
}

void TileDispatcher::withdraw(grpc::ClientContext* context) {
  std::lock_guard lock(mu_);
  calls_.erase(context);
}

void TileDispatcher::stop() {
  stop_.store(true);
  std::lock_guard lock(mu_);
  cancelCalls();
}

void TileDispatcher::cancelCalls() {
  for (grpc::ClientContext* c : calls_) c->TryCancel();
  cv_.notify_all();
}

void TileDispatcher::fail(Status status) {
  std::lock_guard lock(mu_);
  failLocked(std::move(status));
}

void TileDispatcher::failLocked(Status status) {
  if (status_.ok()) status_ = std::move(status);
  cancelCalls();
}

bool TileDispatcher::stopping() const { return stop_.load() || config_.interrupter.interrupted(); }

Status TileDispatcher::stopReason() const {
  if (!stopping()) return Status::Ok();
  return config_.interrupter.interrupted() ? config_.interrupter.status() : Status::Cancelled("stopped");
}

int TileDispatcher::retries() const {
  std::lock_guard lock(mu_);
  return retries_;
}

std::chrono::system_clock::time_point TileDispatcher::tileDeadline() const {
  const auto own = std::chrono::system_clock::now() +
                   std::chrono::milliseconds(int64_t(config_.options.tile_timeout_seconds * 1000));
  return std::min(own, config_.client_deadline);
}

TileDispatcher::Attempt TileDispatcher::runTile(size_t index) {
  Attempt attempt;
  std::optional<v1::QueryRequest> request = tiles_.request(index);
  if (!request) return attempt;  // nothing within the limit: nothing to deliver
  // First attempts go where round_robin sends them; a retry goes to a replica this tile has not failed on.
  std::shared_ptr<v1::DistanceField::Stub> stub;
  std::set<std::string> avoid;
  int attempts;
  {
    std::lock_guard lock(mu_);
    avoid = attempts_[index].failed_on;
    attempts = attempts_[index].attempts;
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
  Call call(*this, &context);
  if (stop_.load()) {  // stop() may have cancelled every call just before this one was registered
    attempt.status = Status::Cancelled("stopped");
    return attempt;
  }
  auto reader = stub->Query(&context, *request);
  attempt.called = true;
  request.reset();
  v1::QueryReply message;
  while (reader->Read(&message)) {
    std::lock_guard lock(mu_);
    if (stop_.load() || !status_.ok()) {
      context.TryCancel();
      break;
    }
    if (Status s = tiles_.onReply(index, message); !s.ok()) failLocked(std::move(s));
  }
  const grpc::Status s = reader->Finish();
  attempt.peer = context.peer();
  std::lock_guard lock(mu_);
  attempt.status = fromGrpcStatus(s);
  attempt.asset_missing = s.error_code() == grpc::StatusCode::NOT_FOUND;
  if (attempt.status.ok() && status_.ok() && !tiles_.sawLastSegment(index))
    attempt.status = Status::Internal("the replica's stream ended without its last segment");
  return attempt;
}

void TileDispatcher::worker(const std::vector<TilePlan>& plans) {
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
      attempts = attempts_[index].attempts;
    }
    // Back-off before a retry: gRPC's round_robin needs a moment to see that a replica is gone.
    for (int waited = 0; attempts > 0 && waited < 100 * attempts && !stopping(); waited += 5)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    Attempt a;
    if (stopping()) a.status = Status::Cancelled("stopped");
    else a = runTile(index);
    if (a.asset_missing && !stopping())
      if (Status s = tiles_.reship(); !s.ok()) a.status = s;
    if (a.called) config_.metrics.tileDispatched(a.peer);
    std::lock_guard lock(mu_);
    --running_;
    if (!status_.ok()) {
      // The query failed: nothing more is merged.
    } else if (a.status.ok() || tiles_.everythingMerged(index)) {
      tiles_.onTileDone(index);
      ++done_tiles_;
    } else if (!stop_.load()) {
      TileAttempts& t = attempts_[index];
      tiles_.onAttemptFailed(index);
      if (!a.peer.empty()) t.failed_on.insert(a.peer);
      const bool retry = retriable(a.status.code()) && t.attempts < config_.options.tile_retries;
      if (a.called) config_.metrics.tileFailed(a.peer, retry);
      if (retry) {
        ++t.attempts;
        ++retries_;
        LogLine("TileRetry")
            .text("request_id", config_.request_id)
            .number("tile", uint64_t(index))
            .number("attempt", t.attempts)
            .text("replica", a.peer.empty() ? "?" : a.peer)
            .status(a.status)
            .write(spdlog::level::warn);
        pending_.push_back(index);
      } else {
        const VoxelBox& b = plans[index].deliver;
        const std::string what = fmt::format("tile {} (voxels {},{},{} + {}x{}x{}) failed after {} attempts: {} {}",
                                             index, b.min.x, b.min.y, b.min.z, b.dims.x, b.dims.y, b.dims.z,
                                             t.attempts + 1, Status::codeName(a.status.code()), a.status.message());
        failLocked(retriable(a.status.code()) ? Status::Unavailable(what) : Status::Internal(what));
      }
    }
    cv_.notify_all();
  }
}

void TileDispatcher::run(const std::vector<TilePlan>& plans, size_t replicas) {
  {
    std::lock_guard lock(mu_);
    attempts_.assign(plans.size(), TileAttempts{});
    for (size_t i = 0; i < plans.size(); ++i) pending_.push_back(i);
  }
  const size_t workers = std::min({plans.size(), replicas * size_t(config_.options.tiles_in_flight_per_replica),
                                   kMaxTileCallsPerQuery});
  // One thread per tile call in flight (the synchronous client API), capped: a headless Service listing hundreds of
  // pods must not turn one query into hundreds of threads.
  std::vector<std::thread> threads;
  for (size_t i = 0; i < workers; ++i) threads.emplace_back([this, &plans] { worker(plans); });
  {
    std::unique_lock lock(mu_);
    while (status_.ok() && !stop_.load() && !(tiles_.complete() && done_tiles_ == plans.size())) {
      cv_.wait_for(lock, std::chrono::milliseconds(5));
      if (config_.interrupter.interrupted()) {
        stop_.store(true);
        cancelCalls();
      }
      if (running_ == 0 && pending_.empty() && status_.ok() && !stop_.load() && !tiles_.complete())
        failLocked(Status::Internal("every tile ended but the merged stream has not (a replica's stream was incomplete)"));
    }
    if (!status_.ok() || !tiles_.complete()) stop_.store(true);
    cancelCalls();  // none is left after a complete stream
  }
  for (std::thread& t : threads) t.join();
}

}  // namespace distband

#include "server/active_calls.h"

#include <fmt/format.h>

namespace distband {
namespace {

int64_t nowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(ActiveCalls::Clock::now().time_since_epoch()).count();
}

// gRPC deadlines are system-clock time points; the Interrupter runs on the steady clock.
bool steadyDeadline(const grpc::ServerContext* context, ActiveCalls::Clock::time_point* out) {
  const auto deadline = context->deadline();
  if (deadline >= std::chrono::system_clock::time_point::max() - std::chrono::hours(24 * 365)) return false;
  *out = ActiveCalls::Clock::now() +
         std::chrono::duration_cast<ActiveCalls::Clock::duration>(deadline - std::chrono::system_clock::now());
  return true;
}

}  // namespace

ActiveCalls::Call::Call(ActiveCalls* owner, grpc::ServerContext* context, const char* method)
    : owner_(owner), context_(context), method_(method) {
  Clock::time_point deadline;
  if (context && steadyDeadline(context, &deadline)) interrupter_.setDeadline(deadline);
}

ActiveCalls::Call::~Call() { owner_->leave(this); }

void ActiveCalls::Call::waitingForClient(bool waiting) {
  waiting_since_ns_.store(waiting ? std::max<int64_t>(1, nowNs()) : 0, std::memory_order_relaxed);
}

ActiveCalls::ActiveCalls(int max_streams, std::chrono::milliseconds idle_timeout)
    : max_streams_(max_streams), idle_timeout_(idle_timeout), watchdog_([this] { watch(); }) {}

ActiveCalls::~ActiveCalls() {
  {
    std::lock_guard lock(mu_);
    stopping_ = true;
  }
  wake_.notify_all();
  watchdog_.join();
}

Status ActiveCalls::enter(grpc::ServerContext* context, const char* method, std::unique_ptr<Call>* out) {
  std::lock_guard lock(mu_);
  if (int(calls_.size()) >= max_streams_)
    return Status::ResourceExhausted(fmt::format(
        "{}: the server is at its limit of {} concurrent calls (--max-streams); retry later", method, max_streams_));
  std::unique_ptr<Call> call(new Call(this, context, method));
  calls_.push_front(call.get());
  call->position_ = calls_.begin();
  peak_ = std::max(peak_, int(calls_.size()));
  *out = std::move(call);
  return Status::Ok();
}

void ActiveCalls::leave(Call* call) {
  std::lock_guard lock(mu_);
  calls_.erase(call->position_);
}

void ActiveCalls::stopAll(const Status& reason) {
  std::lock_guard lock(mu_);
  for (Call* c : calls_) {
    c->interrupter_.cancel(reason.code(), reason.message());
    // A handler computing sees its Interrupter and answers with `reason`; one blocked on its client can only be
    // woken by cancelling the call.
    if (c->context_ && c->waiting_since_ns_.load(std::memory_order_relaxed) != 0) c->context_->TryCancel();
  }
}

int ActiveCalls::active() const {
  std::lock_guard lock(mu_);
  return int(calls_.size());
}

int ActiveCalls::peakActive() const {
  std::lock_guard lock(mu_);
  return peak_;
}

void ActiveCalls::watch() {
  const int64_t limit_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(idle_timeout_).count();
  std::unique_lock lock(mu_);
  while (!stopping_) {
    wake_.wait_for(lock, std::chrono::milliseconds(50));
    const int64_t now = nowNs();
    for (Call* c : calls_) {
      const int64_t since = c->waiting_since_ns_.load(std::memory_order_relaxed);
      if (since == 0 || now - since < limit_ns || c->idle_expired_.load()) continue;
      c->idle_expired_.store(true);
      idle_cancels_.fetch_add(1);
      c->interrupter_.cancel(Status::Code::kCancelled,
                             fmt::format("{}: the client was idle for {:g} s (--idle-timeout); the call was cancelled",
                                         c->method_, idle_timeout_.count() / 1000.0));
      if (c->context_) c->context_->TryCancel();
    }
  }
}

}  // namespace distband

// ActiveCalls: every DistanceField call in flight. It enforces --max-streams, owns each call's Interrupter (with the
// client's deadline), runs the idle watchdog and stops every call at shutdown.
// Contract:
//   * enter() admits a call or answers RESOURCE_EXHAUSTED at once when --max-streams calls are in flight (no
//     waiting: a flood must not pile up threads). The returned Call unregisters itself when destroyed.
//   * A handler brackets every wait on its client with waitingForClient(true/false): reading an upload chunk,
//     writing a reply. When one such wait lasts longer than the idle timeout, the watchdog cancels the call: its
//     Interrupter trips (kCancelled, "idle for N s") and the gRPC context is cancelled, which ends the blocked
//     Read/Write. Compute time never counts as idle.
//   * stopAll() trips every call's Interrupter (the end of the shutdown grace period); calls blocked on their client
//     are also cancelled, since nothing else wakes them.
//   * The watchdog is one thread that wakes every 50 ms; it only calls thread-safe ServerContext::TryCancel.
// Thread-safe.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include <grpcpp/server_context.h>

#include "core/interrupter.h"
#include "core/status.h"

namespace distband {

class ActiveCalls {
 public:
  using Clock = std::chrono::steady_clock;

  class Call {
   public:
    ~Call();
    Interrupter& interrupter() { return interrupter_; }
    /// The handler starts (true) or stops (false) waiting on its client.
    void waitingForClient(bool waiting);
    /// True when the watchdog cancelled this call for idleness.
    bool idleExpired() const { return idle_expired_.load(); }
    const char* method() const { return method_; }
    /// The call's work was refused for the memory budget or the compute slots (not for a limit); the metrics tell
    /// the two RESOURCE_EXHAUSTED reasons apart by it. The handler's thread only.
    void markBudgetRefusal() { budget_refused_ = true; }
    bool budgetRefused() const { return budget_refused_; }

   private:
    friend class ActiveCalls;
    Call(ActiveCalls* owner, grpc::ServerContext* context, const char* method);
    ActiveCalls* owner_;
    grpc::ServerContext* context_;
    const char* method_;
    Interrupter interrupter_;
    std::atomic<int64_t> waiting_since_ns_{0};  ///< steady-clock ns when the current wait began; 0 = not waiting
    std::atomic<bool> idle_expired_{false};
    bool budget_refused_ = false;
    std::list<Call*>::iterator position_;
  };

  ActiveCalls(int max_streams, std::chrono::milliseconds idle_timeout);
  ~ActiveCalls();

  /// Admits a call of `method` (a string literal, for logs).
  Status enter(grpc::ServerContext* context, const char* method, std::unique_ptr<Call>* out);
  /// Trips every call's Interrupter with `reason` and cancels its context.
  void stopAll(const Status& reason);
  int active() const;
  int peakActive() const;
  uint64_t idleCancels() const { return idle_cancels_.load(); }

 private:
  void leave(Call* call);
  void watch();

  const int max_streams_;
  const std::chrono::milliseconds idle_timeout_;
  mutable std::mutex mu_;
  std::condition_variable wake_;
  std::list<Call*> calls_;
  int peak_ = 0;
  bool stopping_ = false;
  std::atomic<uint64_t> idle_cancels_{0};
  std::thread watchdog_;
};

}  // namespace distband

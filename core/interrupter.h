// Interrupter: the one stop signal of a request, handed from the RPC (or the CLI) to parsing, seed building, the
// engine and emission (OpenVDB's util::NullInterrupter is the model).
// Contract:
//   * cancel() (any thread, any number of times) stops the request; the first reason wins. A deadline, when set,
//     stops it once the steady clock passes it (noticed by the next poll, no timer thread).
//   * interrupted() is cheap (one relaxed atomic load; with a deadline also one steady-clock read) and safe from
//     any thread. Every loop in core that can run longer than ~10 ms polls it at least every ~10 ms of work, so a
//     stopped request stops using CPU within 100 ms in every phase. After a true answer it stays true.
//   * status() is OK while running, then kCancelled / kDeadlineExceeded / the code given to cancel(), with a
//     message saying why. A null `const Interrupter*` means "never interrupted" (see isInterrupted()).
// Thread-safe. Not copyable (share it by pointer; it must outlive every phase that polls it).
#pragma once

#include <atomic>
#include <chrono>
#include <mutex>
#include <string>

#include "core/status.h"

namespace distband {

class Interrupter {
 public:
  using Clock = std::chrono::steady_clock;

  Interrupter() = default;
  explicit Interrupter(Clock::time_point deadline) : deadline_(deadline), has_deadline_(true) {}
  Interrupter(const Interrupter&) = delete;
  Interrupter& operator=(const Interrupter&) = delete;

  /// Sets or moves the deadline. Call before handing the interrupter to other threads.
  void setDeadline(Clock::time_point deadline) {
    deadline_ = deadline;
    has_deadline_ = true;
  }
  bool hasDeadline() const { return has_deadline_; }
  Clock::time_point deadline() const { return deadline_; }

  /// Stops the request. `code` says why (kCancelled, kDeadlineExceeded, kUnavailable for shutdown,
  /// kResourceExhausted for an idle timeout, ...); the first call wins.
  void cancel(Status::Code code = Status::Code::kCancelled, std::string message = "the request was cancelled") {
    std::lock_guard lock(mu_);
    if (state_.load(std::memory_order_relaxed) != 0) return;
    reason_ = Status(code == Status::Code::kOk ? Status::Code::kCancelled : code, std::move(message));
    state_.store(1, std::memory_order_release);
  }

  bool interrupted() const {
    if (state_.load(std::memory_order_relaxed) != 0) return true;
    if (has_deadline_ && Clock::now() >= deadline_) {
      const_cast<Interrupter*>(this)->cancel(Status::Code::kDeadlineExceeded, "the request's deadline passed");
      return true;
    }
    return false;
  }

  Status status() const {
    if (!interrupted()) return Status::Ok();
    std::lock_guard lock(mu_);
    return reason_;
  }

 private:
  std::atomic<int> state_{0};
  Clock::time_point deadline_{};
  bool has_deadline_ = false;
  mutable std::mutex mu_;
  Status reason_;
};

/// Null-safe poll: a null interrupter is never interrupted.
inline bool isInterrupted(const Interrupter* interrupter) { return interrupter && interrupter->interrupted(); }

/// What a phase that stopped because `interrupter` tripped returns: its status (kCancelled, kDeadlineExceeded, ...),
/// or kCancelled when there is no interrupter (a phase stopped by other means, e.g. a cancelled TBB context).
inline Status interruptedStatus(const Interrupter* interrupter) {
  if (interrupter && interrupter->interrupted()) return interrupter->status();
  return Status::Cancelled("the work was cancelled");
}

}  // namespace distband

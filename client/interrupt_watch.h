// InterruptWatch: bridges a "stop was asked" predicate (the CLI's SIGINT flag, which a signal handler sets and which
// therefore cannot do more) and a command's deadline (--deadline) to core's Interrupter, which the engine and the
// seed builders poll.
// Contract: the constructor sets the interrupter's deadline, if any, and asks `requested` once itself (a stop asked
// before the command began is seen whatever the scheduler does: a short command could otherwise finish before the
// thread's first poll and ignore it); then, while the watch lives, a thread polls `requested` and the deadline every
// 10 ms and cancels interrupter() the first time either says stop (kCancelled for the user, kDeadlineExceeded for
// the deadline: interrupter().status() tells which). `on_stop`, when given, runs once when it trips, on the thread
// that noticed (the constructor's or the watch's): a command whose work is not polling the interrupter (a remote
// call) stops it there. An empty predicate never trips by itself. The destructor wakes and stops the thread at once
// (it does not wait out a poll period: a finished command exits without that delay). Not copyable.
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <optional>
#include <thread>

#include "core/interrupter.h"

namespace distband {

class InterruptWatch {
 public:
  explicit InterruptWatch(std::function<bool()> requested,
                          std::optional<Interrupter::Clock::time_point> deadline = std::nullopt,
                          std::function<void()> on_stop = {})
      : requested_(std::move(requested)), on_stop_(std::move(on_stop)) {
    if (deadline) interrupter_.setDeadline(*deadline);
    if ((!requested_ && !deadline) || tripped()) return;
    thread_ = std::thread([this] {
      std::unique_lock<std::mutex> lock(mutex_);
      while (!done_ && !tripped()) wake_.wait_for(lock, std::chrono::milliseconds(10));
    });
  }
  InterruptWatch(const InterruptWatch&) = delete;
  InterruptWatch& operator=(const InterruptWatch&) = delete;
  ~InterruptWatch() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      done_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
  }
  Interrupter& interrupter() { return interrupter_; }
  /// Whether it tripped because the deadline passed (rather than because the user asked).
  bool deadlinePassed() const { return interrupter_.status().code() == Status::Code::kDeadlineExceeded; }

 private:
  /// Asks the predicate and the deadline; cancels the interrupter and runs on_stop when either says stop.
  bool tripped() {
    if (requested_ && requested_()) interrupter_.cancel(Status::Code::kCancelled, "interrupted by the user");
    if (!interrupter_.interrupted()) return false;
    if (on_stop_) on_stop_();
    return true;
  }

  std::function<bool()> requested_;
  std::function<void()> on_stop_;
  Interrupter interrupter_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool done_ = false;  // guarded by mutex_
  std::thread thread_;
};

}  // namespace distband

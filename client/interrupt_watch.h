// InterruptWatch: bridges a "stop was asked" predicate (the CLI's SIGINT flag, which a signal handler sets and which
// therefore cannot do more) to core's Interrupter, which the engine and the seed builders poll.
// Contract: the constructor asks `requested` once itself (a stop asked before the command began is seen whatever the
// scheduler does; before, a short command could finish before the thread's first poll and ignore it); then, while
// the watch lives, a thread polls `requested` every 10 ms and cancels interrupter() the first time it returns true.
// An empty predicate never trips. The destructor wakes and stops the thread at once (it does not wait out a poll
// period: a finished command exits without that delay). Not copyable.
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <thread>

#include "core/interrupter.h"

namespace distband {

class InterruptWatch {
 public:
  explicit InterruptWatch(std::function<bool()> requested) : requested_(std::move(requested)) {
    if (!requested_ || tripped()) return;
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

 private:
  /// Asks the predicate; cancels the interrupter when it says stop.
  bool tripped() {
    if (!requested_()) return false;
    interrupter_.cancel(Status::Code::kCancelled, "interrupted by the user");
    return true;
  }

  std::function<bool()> requested_;
  Interrupter interrupter_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool done_ = false;  // guarded by mutex_
  std::thread thread_;
};

}  // namespace distband

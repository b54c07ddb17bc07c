// InterruptWatch: bridges a "stop was asked" predicate (the CLI's SIGINT flag, which a signal handler sets and which
// therefore cannot do more) to core's Interrupter, which the engine and the seed builders poll.
// Contract: while the watch lives, a thread polls `requested` every 10 ms and cancels interrupter() the first time it
// returns true. An empty predicate never trips. The destructor stops the thread. Not copyable.
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <thread>

#include "core/interrupter.h"

namespace distband {

class InterruptWatch {
 public:
  explicit InterruptWatch(std::function<bool()> requested) : requested_(std::move(requested)) {
    if (requested_)
      thread_ = std::thread([this] {
        while (!done_.load()) {
          if (requested_()) {
            interrupter_.cancel(Status::Code::kCancelled, "interrupted by the user");
            return;
          }
          std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
      });
  }
  InterruptWatch(const InterruptWatch&) = delete;
  InterruptWatch& operator=(const InterruptWatch&) = delete;
  ~InterruptWatch() {
    done_.store(true);
    if (thread_.joinable()) thread_.join();
  }
  Interrupter& interrupter() { return interrupter_; }

 private:
  std::function<bool()> requested_;
  Interrupter interrupter_;
  std::atomic<bool> done_{false};
  std::thread thread_;
};

}  // namespace distband

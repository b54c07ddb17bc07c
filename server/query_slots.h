// QuerySlots: admission control for queries — at most N compute at once; the others wait a short while.
// Contract: acquire() waits until a slot is free, the wait budget is spent, or `abandon()` returns true (client
// gone, server shutting down), polling it every 10 ms; it returns whether a slot was taken. Each successful
// acquire() must be matched by one release(). Thread-safe.
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>

namespace distband {

class QuerySlots {
 public:
  explicit QuerySlots(int slots) : free_(slots) {}

  bool acquire(std::chrono::milliseconds wait, const std::function<bool()>& abandon) {
    const auto deadline = std::chrono::steady_clock::now() + wait;
    std::unique_lock lock(mu_);
    while (free_ == 0) {
      if (abandon && abandon()) return false;
      const auto now = std::chrono::steady_clock::now();
      if (now >= deadline) return false;
      cv_.wait_until(lock, std::min(deadline, now + std::chrono::milliseconds(10)));
    }
    --free_;
    ++active_;
    return true;
  }

  void release() {
    {
      std::lock_guard lock(mu_);
      ++free_;
      --active_;
    }
    cv_.notify_one();
  }

  int active() const {
    std::lock_guard lock(mu_);
    return active_;
  }

 private:
  mutable std::mutex mu_;
  std::condition_variable cv_;
  int free_;
  int active_ = 0;
};

}  // namespace distband

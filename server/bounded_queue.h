// BoundedQueue: the hand-off between a query's compute thread and its gRPC writer, bounded in bytes so that a
// slow client pauses compute instead of growing memory.
// Contract: push() blocks while the item would take the queue beyond its capacity in bytes (an item is always
// admitted into an empty queue, whatever its size) and returns false once the queue is closed. pop() waits up to a
// timeout. close() wakes every waiter; after it, push() refuses and pop() drains what is left, then reports kClosed.
// Thread-safe for any number of producers and consumers.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <utility>

namespace distband {

template <typename T>
class BoundedQueue {
 public:
  enum class PopResult { kItem, kTimeout, kClosed };

  explicit BoundedQueue(uint64_t capacity_bytes) : capacity_(capacity_bytes) {}

  bool push(T item, uint64_t bytes) {
    std::unique_lock lock(mu_);
    not_full_.wait(lock, [&] { return closed_ || used_ == 0 || used_ + bytes <= capacity_; });
    if (closed_) return false;
    used_ += bytes;
    items_.emplace_back(std::move(item), bytes);
    not_empty_.notify_one();
    return true;
  }

  PopResult pop(T* out, std::chrono::milliseconds timeout) {
    std::unique_lock lock(mu_);
    if (!not_empty_.wait_for(lock, timeout, [&] { return closed_ || !items_.empty(); }))
      return PopResult::kTimeout;
    if (items_.empty()) return PopResult::kClosed;
    *out = std::move(items_.front().first);
    used_ -= items_.front().second;
    items_.pop_front();
    not_full_.notify_all();
    return PopResult::kItem;
  }

  /// Producer is done: consumers drain the rest, then see kClosed. Also used by the consumer to abort.
  void close() {
    std::lock_guard lock(mu_);
    closed_ = true;
    not_full_.notify_all();
    not_empty_.notify_all();
  }

  /// Consumer gives up: drop queued items (freeing their memory now) and refuse further pushes.
  void abort() {
    std::lock_guard lock(mu_);
    closed_ = true;
    items_.clear();
    used_ = 0;
    not_full_.notify_all();
    not_empty_.notify_all();
  }

 private:
  std::mutex mu_;
  std::condition_variable not_full_, not_empty_;
  std::deque<std::pair<T, uint64_t>> items_;
  uint64_t used_ = 0;
  const uint64_t capacity_;
  bool closed_ = false;
};

}  // namespace distband

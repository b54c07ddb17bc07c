// MemoryBudget: the bytes this server lets requests use at once (--memory-budget). Every upload and query is
// admitted by an estimate of its peak bytes before it allocates anything big; what does not fit waits a while, then
// gets RESOURCE_EXHAUSTED with a message saying what was asked and what is free.
// Contract:
//   * A Reservation holds bytes of the budget until it is released or destroyed (RAII, move-only). It may grow
//     without waiting (tryGrow: an upload whose size was not declared grows chunk by chunk) and shrink.
//   * reserve() waits up to `wait` for room, polling `abandon` (client gone, shutdown) every 10 ms; an ask larger
//     than the whole budget fails at once. Waiters are served in no particular order.
//   * The asset cache's capacity and gRPC's own buffer quota are carved out of --memory-budget by the server
//     before the rest is handed to this class (server/distance_field_service.cc).
// Thread-safe.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <string_view>

#include "core/status.h"

namespace distband {

/// "512 B", "3.2 MiB", "1.50 GiB": for messages and logs.
std::string humanBytes(uint64_t bytes);

class MemoryBudget {
 public:
  class Reservation {
   public:
    Reservation() = default;
    Reservation(Reservation&& o) noexcept : budget_(o.budget_), bytes_(o.bytes_) { o.budget_ = nullptr, o.bytes_ = 0; }
    Reservation& operator=(Reservation&& o) noexcept;
    Reservation(const Reservation&) = delete;
    Reservation& operator=(const Reservation&) = delete;
    ~Reservation() { release(); }

    uint64_t bytes() const { return bytes_; }
    bool held() const { return budget_ != nullptr; }
    /// Adds `more` bytes if they fit now; false (and no change) otherwise.
    bool tryGrow(uint64_t more);
    /// Gives back everything above `bytes`.
    void shrinkTo(uint64_t bytes);
    void release();

   private:
    friend class MemoryBudget;
    MemoryBudget* budget_ = nullptr;
    uint64_t bytes_ = 0;
  };

  explicit MemoryBudget(uint64_t capacity_bytes) : capacity_(capacity_bytes) {}

  /// Takes `bytes` now if they fit (replacing whatever `out` held).
  bool tryReserve(uint64_t bytes, Reservation* out);
  /// Takes `bytes`, waiting up to `wait` for room. `what` names the request in the RESOURCE_EXHAUSTED message
  /// ("the query (1024x1024x1024 voxels, exact mode)"). kCancelled when `abandon` turned true while waiting.
  Status reserve(uint64_t bytes, std::string_view what, std::chrono::milliseconds wait,
                 const std::function<bool()>& abandon, Reservation* out);

  uint64_t capacity() const { return capacity_; }
  uint64_t used() const;
  uint64_t peakUsed() const;
  uint64_t available() const;

 private:
  void give(uint64_t bytes);
  mutable std::mutex mu_;
  std::condition_variable freed_;
  const uint64_t capacity_;
  uint64_t used_ = 0, peak_ = 0;
};

}  // namespace distband

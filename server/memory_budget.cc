#include "server/memory_budget.h"

#include <algorithm>

#include <fmt/format.h>

namespace distband {

std::string humanBytes(uint64_t b) {
  if (b < 1024) return fmt::format("{} B", b);
  if (b < (uint64_t(1) << 20)) return fmt::format("{:.1f} KiB", b / 1024.0);
  if (b < (uint64_t(1) << 30)) return fmt::format("{:.1f} MiB", b / 1048576.0);
  return fmt::format("{:.2f} GiB", b / 1073741824.0);
}

MemoryBudget::Reservation& MemoryBudget::Reservation::operator=(Reservation&& o) noexcept {
  if (this != &o) {
    release();
    budget_ = o.budget_, bytes_ = o.bytes_;
    o.budget_ = nullptr, o.bytes_ = 0;
  }
  return *this;
}

bool MemoryBudget::Reservation::tryGrow(uint64_t more) {
  if (!budget_ || more == 0) return budget_ != nullptr;
  std::lock_guard lock(budget_->mu_);
  if (budget_->used_ + more > budget_->capacity_) return false;
  budget_->used_ += more;
  budget_->peak_ = std::max(budget_->peak_, budget_->used_);
  bytes_ += more;
  return true;
}

void MemoryBudget::Reservation::shrinkTo(uint64_t bytes) {
  if (!budget_ || bytes >= bytes_) return;
  budget_->give(bytes_ - bytes);
  bytes_ = bytes;
}

void MemoryBudget::Reservation::release() {
  if (!budget_) return;
  budget_->give(bytes_);
  budget_ = nullptr;
  bytes_ = 0;
}

void MemoryBudget::give(uint64_t bytes) {
  {
    std::lock_guard lock(mu_);
    used_ -= std::min(used_, bytes);
  }
  freed_.notify_all();
}

bool MemoryBudget::tryReserve(uint64_t bytes, Reservation* out) {
  out->release();
  std::lock_guard lock(mu_);
  if (used_ + bytes > capacity_) return false;
  used_ += bytes;
  peak_ = std::max(peak_, used_);
  out->budget_ = this;
  out->bytes_ = bytes;
  return true;
}

Status MemoryBudget::reserve(uint64_t bytes, std::string_view what, std::chrono::milliseconds wait,
                             const std::function<bool()>& abandon, Reservation* out) {
  out->release();
  if (bytes > capacity_)
    return Status::ResourceExhausted(fmt::format(
        "{} needs an estimated {} of memory, more than the server's whole memory budget ({}); ask for fewer voxels "
        "(a smaller grid, a distance limit) or a smaller input",
        what, humanBytes(bytes), humanBytes(capacity_)));
  const auto deadline = std::chrono::steady_clock::now() + wait;
  std::unique_lock lock(mu_);
  while (used_ + bytes > capacity_) {
    if (abandon && abandon()) return Status::Cancelled(fmt::format("{}: given up while waiting for memory", what));
    const auto now = std::chrono::steady_clock::now();
    if (now >= deadline)
      return Status::ResourceExhausted(fmt::format(
          "{} needs an estimated {} of memory but only {} of the server's {} budget was free for {} ms; retry later",
          what, humanBytes(bytes), humanBytes(capacity_ - std::min(capacity_, used_)), humanBytes(capacity_),
          wait.count()));
    freed_.wait_until(lock, std::min(deadline, now + std::chrono::milliseconds(10)));
  }
  used_ += bytes;
  peak_ = std::max(peak_, used_);
  out->budget_ = this;
  out->bytes_ = bytes;
  return Status::Ok();
}

uint64_t MemoryBudget::used() const {
  std::lock_guard lock(mu_);
  return used_;
}

uint64_t MemoryBudget::peakUsed() const {
  std::lock_guard lock(mu_);
  return peak_;
}

uint64_t MemoryBudget::available() const {
  std::lock_guard lock(mu_);
  return capacity_ - std::min(capacity_, used_);
}

}  // namespace distband

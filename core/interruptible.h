// runInterruptible: runs work that uses TBB algorithms without polls of its own (parallel_sort, a library's
// parallel build) so that an Interrupter can still stop it.
// Contract: `work` runs in a task group whose context a watcher thread cancels (every TBB task it started, nested
// algorithms included, stops at its next task boundary) within ~2 ms of `interrupter` tripping. Returns false when
// the work was interrupted (its results are then unspecified and must be discarded). With a null interrupter the
// work simply runs. The watcher is one short-lived thread: use it for work of more than a few milliseconds.
#pragma once

#include <atomic>
#include <chrono>
#include <thread>

#include <tbb/task_group.h>

#include "core/interrupter.h"

namespace distband {

template <typename Work>
bool runInterruptible(const Interrupter* interrupter, Work&& work) {
  if (!interrupter) {
    work();
    return true;
  }
  if (interrupter->interrupted()) return false;
  tbb::task_group_context context;
  tbb::task_group group(context);
  std::atomic<bool> done{false};
  std::thread watcher([&] {
    while (!done.load(std::memory_order_acquire)) {
      if (interrupter->interrupted()) {
        context.cancel_group_execution();
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  });
  group.run_and_wait([&] { work(); });
  done.store(true, std::memory_order_release);
  watcher.join();
  return !interrupter->interrupted();
}

}  // namespace distband

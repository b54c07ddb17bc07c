// runInterruptible: runs work that uses TBB algorithms without polls of its own (parallel_sort, a library's
// parallel build) so that an Interrupter can still stop it.
// Contract: `work` runs in a task group whose context a watcher thread cancels (every TBB task it started, nested
// algorithms included, stops at its next task boundary) within ~2 ms of `interrupter` tripping. Returns false when
// the work was interrupted (its results are then unspecified and must be discarded). With a null interrupter the
// work simply runs. The watcher is one short-lived thread, woken when the work ends (the caller never waits out a
// poll period): use it for work of more than a few milliseconds.
#pragma once

#include <chrono>
#include <condition_variable>
#include <mutex>
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
  std::mutex mutex;
  std::condition_variable wake;
  bool done = false;  // guarded by mutex
  std::thread watcher([&] {
    std::unique_lock<std::mutex> lock(mutex);
    while (!done) {
      if (interrupter->interrupted()) {
        context.cancel_group_execution();
        return;
      }
      wake.wait_for(lock, std::chrono::milliseconds(2));
    }
  });
  group.run_and_wait([&] { work(); });
  {
    std::lock_guard<std::mutex> lock(mutex);
    done = true;
  }
  wake.notify_all();
  watcher.join();
  return !interrupter->interrupted();
}

}  // namespace distband

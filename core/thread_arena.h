// runWithThreads: the thread-count rule of the compute entry points (BandOptions::threads) in one place — a
// positive count runs `body` in a TBB task_arena of that many workers, anything else in the caller's arena.
#pragma once

#include <utility>

#include <tbb/task_arena.h>

namespace distband {

template <typename Body>
void runWithThreads(int threads, Body&& body) {
  if (threads > 0) {
    tbb::task_arena arena(threads);
    arena.execute(std::forward<Body>(body));
  } else {
    body();
  }
}

}  // namespace distband
